"""Speciation: species as slots, representatives as tensors.

Each run has ``S`` species slots (``S`` grows by doubling when a run needs more; a dead
species' slot is reused). A genome joins the compatible species whose representative is
closest ([NP]'s rule); genomes compatible with none found new species one at a time, as
in [NEAT02] (a loop over new species, not over genomes). Each species then takes a random
member as its representative for the next generation ([NEAT02]). With
``NEATConfig.speciate_neatc``, NEAT C++ 1.2.1's rule: a genome joins the first compatible
species in founding order, and the representatives are the species' champions of the
parents' generation (set by ``reproduce``).
"""

from __future__ import annotations

from dataclasses import replace

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.distance import distance, gene_stats
from evolution.kernels import breed as breed_kernel
from evolution.kernels import select as select_kernel
from evolution.population import Genomes
from evolution.rng import RunRNG
from evolution.species_state import SpeciesState, empty_species

__all__ = ["SpeciesState", "empty_species", "speciate", "distance_view"]


FOUNDER_BATCH = 16


def _free_slot(species: Tensor, sp: SpeciesState, need: Tensor) -> tuple[Tensor, SpeciesState]:
    """The lowest species slot per run holding no species with members this generation
    and not founded this generation; grows the slots when a run in ``need`` has none."""
    while True:
        # Counted, not scattered: a scatter of flags would let an unassigned genome's False
        # (its -1 clamped to slot 0) overwrite a member's True, and reuse slot 0 while taken.
        members = torch.zeros(sp.alive.shape, dtype=torch.long, device=species.device)
        taken = members.scatter_add_(1, species.clamp_min(0), (species >= 0).long()) > 0
        slot, has_slot = _first_true(~taken)
        if not bool((need & ~has_slot).any()):
            return slot, sp
        sp = sp.grow(2 * sp.capacity)


def _first_true(mask: Tensor) -> tuple[Tensor, Tensor]:
    """Index of the first True along the last dim, and whether there is one."""
    n = mask.shape[-1]
    idx = torch.arange(n, device=mask.device)
    first = torch.where(mask, idx, n).amin(-1)
    return first.clamp_max(n - 1), first < n


def speciate(g: Genomes, sp: SpeciesState, cfg: NEATConfig, rng: RunRNG, generation: int, *,
             fused: bool | None = None, runs: Tensor | None = None,
             genes: breed_kernel.GeneBits | None = None) -> tuple[Tensor, SpeciesState]:
    """Assign every genome a species slot; returns ``(species [R, P] long, new state)``.

    ``fused``: assign by the C kernels (``evolution.kernels.breed.assign_species``, the same
    rule, distances agreeing to about 1e-15; ``evolution.kernels.select`` for the
    representatives) or by the tensor reference below; by default the kernels wherever they
    can run. ``runs``: the genomes are those runs of ``g`` (a larger population; the kernels
    read them in place) and ``sp`` describes those runs. ``genes``: the genomes' gene bitsets
    as ``breed_kernel.breed`` returned them with these genomes (the kernels then skip
    computing them, and take the closest representatives breeding found if it saw these
    representatives and alive flags; ignored by the tensor reference)."""
    use_kernels = breed_kernel.wanted(g, fused)
    g = distance_view(g)
    if runs is not None and not use_kernels:
        g, runs = g.select_runs(runs), None
    # Pure: never edit the input (the representatives are only read, so they are not copied).
    sp = SpeciesState(**{k: v if k.startswith("rep_") else v.clone() for k, v in sp.tensors().items()})
    if use_kernels:
        species, sp = _assign_by_kernel(g, sp, cfg, generation, runs, genes)
    else:
        species, sp = _assign_by_tensors(g, sp, cfg, generation)
    # Species without members die; each survivor takes a random member as representative.
    if use_kernels:
        alive, rep_conn, rep_weight, rep_sigma = select_kernel.choose_representatives(g, species, sp.capacity, rng,
                                                                                      runs)
    else:
        alive, rep_conn, rep_weight, rep_sigma = _choose_representatives(g, species, sp.capacity, rng)
    # A mark of obliteration ends with its species (a slot founded anew starts unmarked).
    obliterated = sp.obliterated & alive & (sp.created != generation)
    return species, SpeciesState(alive=alive, rep_conn=rep_conn, rep_weight=rep_weight, rep_sigma=rep_sigma,
                                 best_fitness=torch.where(alive, sp.best_fitness, -torch.inf),
                                 last_improved=sp.last_improved, created=sp.created, ident=sp.ident,
                                 next_id=sp.next_id, obliterated=obliterated, run_best=sp.run_best,
                                 run_stale=sp.run_stale)


def distance_view(g: Genomes) -> Genomes:
    """The genomes as the compatibility distance reads them: ``weight`` is ``mutation_num`` where
    it is carried ([NEATC], ``NEATConfig.compat_mutation_num``), so representatives record it too."""
    return g if g.mutation_num is None else replace(g, weight=g.mutation_num, mutation_num=None)


def _choose_representatives(g: Genomes, species: Tensor, capacity: int, rng: RunRNG
                            ) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """The reference choice (``select_kernel.choose_representatives`` in C): per species slot,
    the member with the highest score, its rows copied; ``(alive, rep_conn, rep_weight, rep_sigma)``."""
    R, P, S = g.num_runs, g.pop_size, capacity
    counts = torch.zeros(R, S, dtype=torch.long, device=g.device)
    counts.scatter_add_(1, species, torch.ones_like(species))
    alive = counts > 0
    score = rng.rand(P, dtype=torch.float64)
    best_score = torch.full((R, S), -1.0, dtype=torch.float64, device=g.device).scatter_reduce(1, species, score, "amax")
    is_rep = score == torch.gather(best_score, 1, species)
    rep_index = _scatter_index(species, is_rep, S)
    # Whole genome rows copied at once; slots without a species emptied.
    flat = (rep_index + torch.arange(R, device=g.device).unsqueeze(1) * P).flatten()
    reps = {k: getattr(g, k).flatten(0, 1).index_select(0, flat) for k in ("conn", "weight", "sigma")}
    dead = torch.nonzero(~alive.flatten()).squeeze(1)
    for k in ("conn", "weight", "sigma"):
        reps[k][dead] = 0
    return (alive, reps["conn"].view(R, S, *g.conn.shape[2:]), reps["weight"].view(R, S, *g.weight.shape[2:]),
            reps["sigma"].view(R, S))


def _assign_by_tensors(g: Genomes, sp: SpeciesState, cfg: NEATConfig, generation: int) -> tuple[Tensor, SpeciesState]:
    """The reference assignment; ``sp`` is edited in place (the caller's copy)."""
    R, P = g.num_runs, g.pop_size
    dev = g.device
    thr = cfg.compatibility_threshold
    runs = torch.arange(R, device=dev)
    species = torch.full((R, P), -1, dtype=torch.long, device=dev)
    stats = gene_stats(g.conn, g.weight, g.sigma)
    n_alive = int(sp.alive.sum(1).max())
    if n_alive > 0:
        # Compare against living representatives only: their slots, packed to the front
        # (in slot order, so ties still go to the lowest slot; [NEATC]: oldest species first).
        order = torch.where(sp.alive, sp.ident, torch.iinfo(torch.long).max) if cfg.speciate_neatc \
            else (~sp.alive).to(torch.int8)
        live = torch.argsort(order, dim=1, stable=True)[:, :n_alive]
        idx = live[..., None, None].expand(-1, -1, *sp.rep_conn.shape[2:])
        rep_stats = gene_stats(sp.rep_conn.gather(1, idx), sp.rep_weight.gather(1, idx), sp.rep_sigma.gather(1, live))
        d = distance(stats, rep_stats, cfg)
        d = torch.where(torch.gather(sp.alive, 1, live).unsqueeze(1), d, torch.full_like(d, torch.inf))
        if cfg.speciate_neatc:  # [NEATC]: the first species within the threshold
            best_k, found = _first_true(d < thr)
            species = torch.where(found, torch.gather(live, 1, best_k), species)
        else:
            best_d, best_k = d.min(-1)
            species = torch.where(best_d < thr, torch.gather(live, 1, best_k), species)
    # Genomes compatible with no species found new ones, in genome order as in [NEAT02]:
    # the first unassigned genome founds a species, every unassigned genome within the
    # threshold of it joins, and so on. Distances to the next FOUNDER_BATCH candidates are
    # computed in one call; the sequential rule is then resolved candidate by candidate.
    k_max = min(FOUNDER_BATCH, P)
    while True:
        unassigned = species < 0
        need = torch.nonzero(unassigned.any(1)).squeeze(1)
        if need.numel() == 0:
            break
        # Pack each run's unassigned genomes (in genome order) to the front: only they can
        # found or join a new species, and they are usually few.
        n_unassigned = unassigned[need].sum(1)
        U = int(n_unassigned.max())
        packed = torch.argsort((~unassigned[need]).to(torch.int8), dim=1, stable=True)[:, :U]  # genome indices
        valid = torch.arange(U, device=dev) < n_unassigned.unsqueeze(1)
        k = min(k_max, U)
        ustats = stats.select(need, packed)
        d_cand = distance(ustats, ustats.take(torch.arange(k, device=dev).expand(need.numel(), k)), cfg)
        for c in range(k):
            current = species[need.unsqueeze(1), packed]  # [R', U]
            has_sub = valid[:, c] & (current[:, c] < 0)
            if not bool(has_sub.any()):
                continue
            has = torch.zeros(R, dtype=torch.bool, device=dev)
            has[need] = has_sub
            slot, sp = _free_slot(species, sp, has)
            join = has_sub.unsqueeze(1) & valid & (current < 0) & (d_cand[..., c] < thr)
            join[:, c] |= has_sub  # the founder always joins its own species
            species[need.unsqueeze(1), packed] = torch.where(join, slot[need].unsqueeze(1), current)
            s_idx = (runs, slot)
            sp.alive[s_idx] = sp.alive[s_idx] | has
            sp.best_fitness[s_idx] = torch.where(has, -torch.inf, sp.best_fitness[s_idx])
            sp.last_improved[s_idx] = torch.where(has, generation, sp.last_improved[s_idx])
            sp.created[s_idx] = torch.where(has, generation, sp.created[s_idx])
            sp.ident[s_idx] = torch.where(has, sp.next_id, sp.ident[s_idx])
            sp.next_id = sp.next_id + has.long()
    return species, sp


def _assign_by_kernel(g: Genomes, sp: SpeciesState, cfg: NEATConfig, generation: int,
                      runs: Tensor | None = None, genes: breed_kernel.GeneBits | None = None
                      ) -> tuple[Tensor, SpeciesState]:
    """The same assignment by the C kernel, then the new species' bookkeeping as tensors."""
    rows = g.num_runs * g.pop_size if runs is None else len(runs) * g.pop_size
    if genes is None:
        genes = breed_kernel.GeneBits(g.conn, g.weight, g.sigma, runs)
    elif genes.rows != rows or genes.nn != g.num_nodes ** 2 or genes.weight.data_ptr() != g.weight.data_ptr():
        raise ValueError(f"genes describe {genes.rows} genomes of {genes.nn} slots, not these "
                         f"{rows} genomes of {g.num_nodes ** 2}: pass the GeneBits breeding returned with them")
    near = genes.nearest_to
    if genes.nearest is not None and near[1] is sp.rep_conn and torch.equal(near[2], sp.alive):
        # breeding already found each genome's closest representative, of these ones
        species, founded, n_founded = breed_kernel.assign_species(genes, near[0], sp.alive, cfg, genes.nearest,
                                                                  ident=sp.ident)
    else:
        reps = breed_kernel.GeneBits(sp.rep_conn, sp.rep_weight, sp.rep_sigma)
        species, founded, n_founded = breed_kernel.assign_species(genes, reps, sp.alive, cfg, ident=sp.ident)
    capacity = sp.capacity
    while capacity <= int(species.max()):  # grown by doubling, as _free_slot grows
        capacity *= 2
    if capacity > sp.capacity:
        sp = sp.grow(capacity)
    # sp's tensors are speciate's own copies (or grown ones): recorded in place
    breed_kernel.found_species(founded, n_founded, generation, sp.alive, sp.best_fitness, sp.last_improved,
                               sp.created, sp.ident, sp.next_id)
    return species, sp


def _scatter_index(species: Tensor, is_rep: Tensor, capacity: int) -> Tensor:
    """For each species slot, the genome index flagged ``is_rep`` (0 where none)."""
    R, P = species.shape
    out = torch.zeros(R, capacity + 1, dtype=torch.long, device=species.device)
    target = torch.where(is_rep, species, capacity)
    out.scatter_(1, target, torch.arange(P, device=species.device).expand(R, P))
    return out[:, :capacity]
