"""One generation of reproduction, as tensor operations over ``[R, P]``.

[Qiu19]: a (P, P) evolution strategy plus species elitism. Per species: stagnation check
([NEAT02], top ``species_elitism`` species protected), explicit fitness sharing (offspring
in proportion to the species' mean fitness above the run's minimum, rounded by largest
remainder so the population stays exactly P), the champion copied unchanged when the species
has more than 5 members (``elitism`` best members, ``elitism_min_species_size``), the best
20 % as parents, crossover or cloning, then mutation.
Parents are discarded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch
from torch import Tensor

from evolution import breed_kernel, select_kernel
from evolution.config import NEATConfig
from evolution.crossover import crossover
from evolution.mutate import (
    mutate_add_connection,
    mutate_add_node,
    mutate_sigma,
    mutate_toggle_enabled,
    mutate_weights,
)
from evolution.population import Genomes
from evolution.rng import RunRNG
from evolution.speciate import SpeciesState

__all__ = ["ReproductionInfo", "allocate_offspring", "share_scale", "reproduce", "select_parents", "update_stagnation"]


@dataclass
class ReproductionInfo:
    """What one reproduction step did, per run bred (``[R']`` tensors: the runs still evolving, in
    run order; ``NEAT.active_runs`` says which)."""

    extinct: Tensor  # bool: every species of the run was removed
    stagnant_removed: Tensor  # long: species removed for stagnation
    split_refused: Tensor  # long: add-node mutations refused for want of a free slot
    offspring: Tensor  # [R, S] long: offspring allocated per species slot
    # The children's gene bitsets when the C kernel bred them (for ``speciate``'s ``genes``).
    child_genes: breed_kernel.GeneBits | None = field(default=None, repr=False, compare=False)


def update_stagnation(fitness: Tensor, species: Tensor, sp: SpeciesState, cfg: NEATConfig,
                      generation: int) -> tuple[SpeciesState, Tensor, Tensor]:
    """Record species' best fitness; return ``(state, survivors [R, S], species_fitness [R, S])``.

    A species stagnates when its best fitness has not improved for ``max_stagnation``
    generations; the ``species_elitism`` best species of a run are never removed.
    """
    R, S = sp.alive.shape
    sf = torch.full((R, S), -torch.inf, dtype=fitness.dtype, device=fitness.device)
    sf = sf.scatter_reduce(1, species, fitness, "amax")
    improved = sp.alive & (sf > sp.best_fitness)
    best = torch.where(improved, sf, sp.best_fitness)
    last = torch.where(improved, generation, sp.last_improved)
    stagnant = sp.alive & (generation - last >= cfg.max_stagnation)
    rank = torch.argsort(torch.argsort(torch.where(sp.alive, sf, -torch.inf), dim=1, descending=True, stable=True),
                         dim=1, stable=True)
    protected = sp.alive & (rank < cfg.species_elitism)
    survivors = sp.alive & (~stagnant | protected)
    new = SpeciesState(**{**sp.tensors(), "best_fitness": best, "last_improved": last})
    return new, survivors, sf


def share_scale(fitness: Tensor) -> Tensor:
    """``[R, 1]`` float64: the factor ``allocate_offspring``'s sums take each run's fitness by.

    1, or where sums of ``P`` values and differences of two could overflow (``|f| > max / 4P``,
    about 3e305 at P = 150), the power of two ``2**-e`` with ``2**e > 4P``: a power of two scales
    exactly, so the quotas are those of unbounded exponents, and every smaller fitness is
    shared bit for bit as before. (``evolution/csrc/select.c`` has the same ``share_scale``.)"""
    P = fitness.shape[1]
    e = math.frexp(4.0 * P)[1]
    top = fitness.to(torch.float64).abs().amax(1, keepdim=True)
    big = top > torch.finfo(torch.float64).max / (4.0 * P)
    return torch.where(big, 2.0 ** -e, 1.0).to(torch.float64)


def allocate_offspring(fitness: Tensor, species: Tensor, survivors: Tensor, pop_size: int) -> Tensor:
    """Offspring per species slot, ``[R, S]`` long, summing to ``pop_size`` in every run
    that has a survivor. Explicit fitness sharing: a species' share is the sum of its
    members' shared fitness ``(f - f_min) / |species|``, i.e. its mean fitness above the
    run's minimum; all-equal shares split evenly. Rounded by largest remainder."""
    R, S = survivors.shape
    dt = torch.float64
    f = fitness.to(dt) * share_scale(fitness)
    size = torch.zeros(R, S, dtype=dt, device=fitness.device).scatter_add_(1, species, torch.ones_like(fitness, dtype=dt))
    total_f = torch.zeros(R, S, dtype=dt, device=fitness.device).scatter_add_(1, species, f)
    # [NEAT02] shares raw fitness; shift only when a run has negative fitness values.
    f_min = f.amin(1, keepdim=True).clamp_max(0.0)
    share = torch.where(survivors, total_f / size.clamp_min(1) - f_min, 0.0).clamp_min(0.0)
    total = share.sum(1, keepdim=True)
    share = torch.where(total > 0, share, survivors.to(dt))
    # Summed in slot order (cumsum is sequential; sum's order depends on vector width), the
    # order evolution.select_kernel.species_offspring sums in.
    total = share.cumsum(1)[:, -1:].clamp_min(1e-300)
    quota = pop_size * share / total
    base = quota.floor()
    remainder = (pop_size - base.sum(1, keepdim=True)).round().long()
    frac = torch.where(survivors, quota - base, -1.0)
    order = torch.argsort(frac, dim=1, descending=True, stable=True)
    rank = torch.argsort(order, dim=1, stable=True)
    counts = base.long() + (rank < remainder).long()
    return torch.where(survivors, counts, 0)


def reproduce(g: Genomes, fitness: Tensor, species: Tensor, sp: SpeciesState, cfg: NEATConfig,
              rng: RunRNG, generation: int, *, fused: bool | None = None, runs: Tensor | None = None,
              in_place: bool = False) -> tuple[Genomes, Tensor, SpeciesState, ReproductionInfo]:
    """The next generation (before speciation).

    Returns ``(children, elite [R, P] bool, species state, info)``. Runs whose species all
    went extinct get ``info.extinct``; their children are meaningless and the caller resets
    them. ``fused``: stagnation, allocation, selection and breeding by the C kernels
    (``evolution.select_kernel``, ``evolution.breed_kernel``, same result) or the tensor
    operators (``update_stagnation``, ``allocate_offspring``, ``select_parents`` and the
    operators); by default the kernels wherever they can run (CPU, compiler present).
    ``runs``: ``g`` is a larger population and the other arguments describe its runs ``runs``
    (the kernel then reads those runs' parents in place). ``in_place`` (with ``runs``): the
    children replace those runs' genomes in ``g``, which is returned (the kernel writes them
    there directly; the tensor path copies them in).
    """
    if in_place and runs is None:
        raise ValueError("in_place needs runs=")
    P = fitness.shape[1]
    use_kernels = breed_kernel.wanted(g, fused)
    if use_kernels:
        best, last, survivors, counts = select_kernel.species_offspring(
            fitness, species, sp.alive, sp.best_fitness, sp.last_improved, cfg, generation)
        sp = SpeciesState(**{**sp.tensors(), "best_fitness": best, "last_improved": last})
        first, second, do_cross, elite = select_kernel.select_parents(
            fitness, species, survivors, counts, cfg, rng)
    else:
        sp, survivors, _ = update_stagnation(fitness, species, sp, cfg, generation)
        counts = allocate_offspring(fitness, species, survivors, P)
        first, second, do_cross, elite = select_parents(fitness, species, survivors, counts, cfg, rng)
    active = ~elite
    child_genes = None
    if use_kernels and breed_kernel.usable_for_species(sp.rep_conn, sp.rep_weight):
        # The living representatives' genes: the node slots they hold, and each child's closest
        # one, which breeding finds (speciate's first step).
        rep_genes = breed_kernel.GeneBits(sp.rep_conn, sp.rep_weight, sp.rep_sigma, alive=sp.alive)
        reps, reserved = (rep_genes, sp.rep_conn, sp.alive), breed_kernel.touched_nodes(rep_genes, sp.alive)
    else:
        reps, reserved = None, _rep_nodes(sp)
    if use_kernels:
        children, refused, child_genes = breed_kernel.breed(g, first, second, do_cross, active, cfg, rng, reserved,
                                                            runs=runs, in_place=in_place, reps=reps)
    else:
        whole = g
        if runs is not None:
            g = g.select_runs(runs)
        children = crossover(g.gather(first), g.gather(second), cfg, rng, do_cross)
        children, refused = mutate_add_node(children, cfg, rng, active, reserved=reserved)
        children = mutate_add_connection(children, cfg, rng, active)
        children = mutate_weights(children, cfg, rng, active)
        children = mutate_sigma(children, cfg, rng, active)
        children = mutate_toggle_enabled(children, cfg, rng, active)
        if in_place:
            for name, t in whole.tensors().items():
                t[runs] = getattr(children, name)
            children = whole

    info = ReproductionInfo(
        extinct=~survivors.any(1),
        stagnant_removed=(sp.alive & ~survivors).sum(1),
        split_refused=refused.sum(1),
        offspring=counts,
        child_genes=child_genes,
    )
    return children, elite, sp, info


def select_parents(fitness: Tensor, species: Tensor, survivors: Tensor, counts: Tensor, cfg: NEATConfig,
                   rng: RunRNG) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Parents of every child, as tensor operations (``evolution.select_kernel`` computes the
    same in C). Returns ``(first, second, do_cross, elite)``, all ``[R, P]``: ``first`` is the
    fitter parent where ``do_cross``; elites are copied unchanged."""
    R, P = fitness.shape
    S = survivors.shape[1]
    dev = fitness.device
    # Members sorted by (species, fitness descending); dead species' members last.
    key_species = torch.where(torch.gather(survivors, 1, species), species, S)
    by_fit = torch.argsort(fitness, dim=1, descending=True, stable=True)
    by_species = torch.argsort(torch.gather(key_species, 1, by_fit), dim=1, stable=True)
    order = torch.gather(by_fit, 1, by_species)  # genome index at each sorted position
    size = torch.zeros(R, S + 1, dtype=torch.long, device=dev).scatter_add_(1, key_species, torch.ones_like(species))[:, :S]
    start = size.cumsum(1) - size
    n_parents = torch.where(size > 0, torch.ceil(cfg.survival_threshold * size).long().clamp_min(1), 0)

    # Offspring k of a run belongs to the species whose block of counts holds k.
    k = torch.arange(P, device=dev).expand(R, P).contiguous()
    ends = counts.cumsum(1)
    osp = torch.searchsorted(ends, k, right=True).clamp_max(S - 1)
    pos = k - (torch.gather(ends, 1, osp) - torch.gather(counts, 1, osp))
    o_start, o_size, o_par = (torch.gather(t, 1, osp) for t in (start, size, n_parents))
    # The species' first ``elitism`` offspring are its best members, copied unchanged.
    elite = (pos < cfg.elitism) & (pos < o_size) & (o_size >= cfg.elitism_min_species_size)

    def pick_in_species(u: Tensor) -> Tensor:
        rank = (u * o_par).long().clamp_max(o_par - 1).clamp_min(0)
        return torch.gather(order, 1, o_start + rank)

    elite_index = torch.gather(order, 1, torch.where(elite, o_start + pos, 0))
    p1 = torch.where(elite, elite_index, pick_in_species(rng.rand(P, dtype=torch.float64)))
    p2 = pick_in_species(rng.rand(P, dtype=torch.float64))
    # Interspecies mating: the second parent from any species' parents.
    sorted_species = torch.gather(key_species, 1, order)
    sorted_pos = torch.arange(P, device=dev).expand(R, P) - torch.gather(
        torch.cat([start, torch.zeros(R, 1, dtype=torch.long, device=dev)], 1), 1, sorted_species)
    sorted_par = torch.gather(torch.cat([n_parents, torch.zeros(R, 1, dtype=torch.long, device=dev)], 1), 1, sorted_species)
    is_parent = sorted_pos < sorted_par
    cum = is_parent.long().cumsum(1)
    n_all = cum[:, -1:].clamp_min(1)
    pick = (rng.rand(P, dtype=torch.float64) * n_all).long().clamp_max(n_all - 1)
    any_parent = torch.gather(order, 1, torch.searchsorted(cum, pick, right=True).clamp_max(P - 1))
    inter = rng.rand(P, dtype=torch.float64) < cfg.interspecies_crossover_prob
    p2 = torch.where(inter, any_parent, p2)

    do_cross = ~elite & (rng.rand(P, dtype=torch.float64) < cfg.crossover_prob) & (p1 != p2)
    f1, f2 = torch.gather(fitness, 1, p1), torch.gather(fitness, 1, p2)
    fitter = torch.where(f2 > f1, p2, p1)
    other = torch.where(f2 > f1, p1, p2)
    first, second = torch.where(do_cross, fitter, p1), torch.where(do_cross, other, p1)
    return first, second, do_cross, elite


def _rep_nodes(sp: SpeciesState) -> Tensor:
    """Node slots touched by any living representative's genes, ``[R, N]`` (the kernels'
    ``breed_kernel.touched_nodes`` finds the same from the representatives' bitsets)."""
    R, S, N = sp.rep_conn.shape[:3]
    live = torch.nonzero(sp.alive.flatten()).squeeze(1)
    genes = sp.rep_conn.flatten(0, 1)[live]  # living representatives only
    touched = (genes.any(-1) | genes.any(-2)).to(torch.int32)
    used = torch.zeros(R, N, dtype=torch.int32, device=genes.device).index_add_(0, live // S, touched)
    return used > 0
