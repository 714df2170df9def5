"""One generation of reproduction, as tensor operations over ``[R, P]``.

[Qiu19]: a (P, P) evolution strategy plus species elitism. Per species: stagnation check
([NEAT02], top ``species_elitism`` species protected), explicit fitness sharing (offspring
in proportion to the species' mean fitness above the run's minimum, rounded by largest
remainder so the population stays exactly P), the champion copied unchanged when the species
has more than 5 members (``elitism`` best members, ``elitism_min_species_size``), the best
20 % as parents, crossover or cloning, then mutation.
Parents are discarded.

NEAT C++ 1.2.1's mechanisms ([NEATC], ``evolution.neat121``) are options of ``NEATConfig``,
all off by default: stagnant species penalised instead of removed, obliteration of the
worst old species, delta coding after whole-population stagnation, exclusive mutations,
unmutated children of crossover, its weight perturbation, averaging crossover, new links by
recurrence, one gene toggled and one re-enabled. Their per-child draws (``extra_draws``)
and the toggles' blocks are taken only when they are on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.crossover import crossover
from evolution.kernels import breed as breed_kernel
from evolution.kernels import select as select_kernel
from evolution.mutate import (
    mutate_add_connection,
    mutate_add_node,
    mutate_sigma,
    mutate_toggle_enabled,
    mutate_toggle_one,
    mutate_weights,
)
from evolution.neat121 import CLONE_LINK_PROB
from evolution.population import Genomes
from evolution.rng import RunRNG
from evolution.speciate import SpeciesState, distance_view

__all__ = ["ReproductionInfo", "allocate_offspring", "share_scale", "reproduce", "select_parents", "update_stagnation",
           "species_records", "species_order", "population_stagnation", "species_offspring", "extra_draws"]


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
    generations (or it was obliterated, ``cfg.obliterate_interval``); the ``species_elitism``
    best species of a run are never removed. With ``cfg.stagnant_fitness_factor`` > 0 no
    species is removed (``species_records`` says which are penalised instead).
    """
    new, survivors, sf, _ = species_records(fitness, species, sp, cfg, generation)
    return new, survivors, sf


def species_order(alive: Tensor, sf: Tensor) -> Tensor:
    """``[R, S]``: each run's living species slots best first (their best fitness this
    generation, ties by slot), then the dead ones."""
    order = torch.argsort(torch.where(alive, sf, -torch.inf), dim=1, descending=True, stable=True)
    dead_last = torch.argsort((~torch.gather(alive, 1, order)).to(torch.int8), dim=1, stable=True)
    return torch.gather(order, 1, dead_last)


def species_records(fitness: Tensor, species: Tensor, sp: SpeciesState, cfg: NEATConfig, generation: int
                    ) -> tuple[SpeciesState, Tensor, Tensor, Tensor]:
    """``update_stagnation`` and which surviving species are penalised ([R, S] bool: their
    fitness shares multiplied by ``cfg.stagnant_fitness_factor``); returns ``(state,
    survivors, species_fitness, penalised)``.

    [NEATC] ``Population::epoch``: every ``obliterate_interval`` generations (counted from 1,
    as NEAT C++ counts them) the worst living species of age >= ``obliterate_min_age`` (age 1
    in the generation it was founded), or the best one if none is that old, is marked
    ``obliterated``: stagnant from then on."""
    R, S = sp.alive.shape
    sf = torch.full((R, S), -torch.inf, dtype=fitness.dtype, device=fitness.device)
    sf = sf.scatter_reduce(1, species, fitness, "amax")
    improved = sp.alive & (sf > sp.best_fitness)
    best = torch.where(improved, sf, sp.best_fitness)
    last = torch.where(improved, generation, sp.last_improved)
    obliterated = sp.obliterated
    if cfg.obliterate_interval > 0 and (generation + 1) % cfg.obliterate_interval == 0:
        order = species_order(sp.alive, sf)
        pos = torch.arange(S, device=sf.device)
        old = torch.gather(generation - sp.created + 1, 1, order) >= cfg.obliterate_min_age
        ok = (old | (pos == 0)) & (pos < sp.alive.sum(1, keepdim=True))
        pick = torch.where(ok, pos, -1).amax(1, keepdim=True)  # the worst such, -1: no species
        mark = torch.zeros_like(sp.alive).scatter_(1, torch.gather(order, 1, pick.clamp_min(0)), pick >= 0)
        obliterated = obliterated | mark
    clock = sp.last_improved if cfg.stagnation_clock_before else last  # [NEATC]: read before the update
    stagnant = sp.alive & ((generation - clock >= cfg.max_stagnation) | obliterated)
    rank = torch.argsort(torch.argsort(torch.where(sp.alive, sf, -torch.inf), dim=1, descending=True, stable=True),
                         dim=1, stable=True)
    protected = sp.alive & (rank < cfg.species_elitism)
    if cfg.stagnant_fitness_factor > 0:
        survivors, penalised = sp.alive.clone(), stagnant & ~protected
    else:
        survivors, penalised = sp.alive & (~stagnant | protected), torch.zeros_like(stagnant)
    new = SpeciesState(**{**sp.tensors(), "best_fitness": best, "last_improved": last, "obliterated": obliterated})
    return new, survivors, sf, penalised


def population_stagnation(fitness: Tensor, sp: SpeciesState, survivors: Tensor, counts: Tensor, sf: Tensor,
                          cfg: NEATConfig, generation: int) -> tuple[SpeciesState, Tensor, Tensor, Tensor]:
    """The run's best fitness record, and [NEATC]'s "delta coding": a run whose best fitness
    has not improved for ``cfg.population_stagnation`` generations gives all its offspring to
    its two best species (``P // 2`` to the best, the rest to the second; all to the best if
    it is alone), restarts their stagnation clocks and its own. Returns ``(state, survivors,
    counts, delta [R])``: ``delta`` marks the runs delta-coded now, whose offspring
    ``select_parents`` then breeds from the two species' champions alone."""
    P = fitness.shape[1]
    top = fitness.to(torch.float64).amax(1)
    better = top > sp.run_best
    run_best = torch.where(better, top, sp.run_best)
    stale = torch.where(better, 0, sp.run_stale + 1)
    last = sp.last_improved
    delta = torch.zeros_like(better)
    if cfg.population_stagnation > 0:
        delta = stale >= cfg.population_stagnation
        stale = torch.where(delta, 0, stale)
        order = species_order(sp.alive, sf)
        rank = torch.argsort(order, dim=1, stable=True)
        first, second = sp.alive & (rank == 0), sp.alive & (rank == 1)
        n_alive = sp.alive.sum(1, keepdim=True)
        split = torch.where(first, torch.where(n_alive >= 2, P // 2, P), torch.where(second, P - P // 2, 0))
        d = delta.unsqueeze(1)
        counts = torch.where(d, split, counts)
        survivors = torch.where(d, first | second, survivors)
        last = torch.where(d & (first | second), generation, last)
    new = SpeciesState(**{**sp.tensors(), "last_improved": last, "run_best": run_best, "run_stale": stale})
    return new, survivors, counts, delta


def species_offspring(fitness: Tensor, species: Tensor, sp: SpeciesState, cfg: NEATConfig, generation: int
                      ) -> tuple[SpeciesState, Tensor, Tensor, Tensor]:
    """The tensor reference of ``select_kernel.species_state_offspring``: ``species_records``,
    ``allocate_offspring``, ``population_stagnation``; returns ``(state, survivors, counts,
    delta)``."""
    sp, survivors, sf, penalised = species_records(fitness, species, sp, cfg, generation)
    counts = allocate_offspring(fitness, species, survivors, fitness.shape[1], penalised,
                                cfg.stagnant_fitness_factor)
    return population_stagnation(fitness, sp, survivors, counts, sf, cfg, generation)


def share_scale(fitness: Tensor) -> Tensor:
    """``[R, 1]`` float64: the factor ``allocate_offspring``'s sums take each run's fitness by.

    1, or where sums of ``P`` values and differences of two could overflow (``|f| > max / 4P``,
    about 3e305 at P = 150), the power of two ``2**-e`` with ``2**e > 4P``: a power of two scales
    exactly, so the quotas are those of unbounded exponents, and every smaller fitness is
    shared bit for bit as before. (``evolution/kernels/csrc/select.c`` has the same ``share_scale``.)"""
    P = fitness.shape[1]
    e = math.frexp(4.0 * P)[1]
    top = fitness.to(torch.float64).abs().amax(1, keepdim=True)
    big = top > torch.finfo(torch.float64).max / (4.0 * P)
    return torch.where(big, 2.0 ** -e, 1.0).to(torch.float64)


def allocate_offspring(fitness: Tensor, species: Tensor, survivors: Tensor, pop_size: int,
                       penalised: Tensor | None = None, factor: float = 1.0) -> Tensor:
    """Offspring per species slot, ``[R, S]`` long, summing to ``pop_size`` in every run
    that has a survivor. Explicit fitness sharing: a species' share is the sum of its
    members' shared fitness ``(f - f_min) / |species|``, i.e. its mean fitness above the
    run's minimum; all-equal shares split evenly. Rounded by largest remainder.
    ``penalised[R, S]``: those species' shares are multiplied by ``factor`` ([NEATC])."""
    R, S = survivors.shape
    dt = torch.float64
    f = fitness.to(dt) * share_scale(fitness)
    size = torch.zeros(R, S, dtype=dt, device=fitness.device).scatter_add_(1, species, torch.ones_like(fitness, dtype=dt))
    total_f = torch.zeros(R, S, dtype=dt, device=fitness.device).scatter_add_(1, species, f)
    # [NEAT02] shares raw fitness; shift only when a run has negative fitness values.
    f_min = f.amin(1, keepdim=True).clamp_max(0.0)
    share = torch.where(survivors, total_f / size.clamp_min(1) - f_min, 0.0)
    if penalised is not None:
        share = torch.where(penalised, share * factor, share)
    share = share.clamp_min(0.0)
    total = share.sum(1, keepdim=True)
    share = torch.where(total > 0, share, survivors.to(dt))
    # Summed in slot order (cumsum is sequential; sum's order depends on vector width), the
    # order evolution.kernels.select.species_offspring sums in.
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
    (``evolution.kernels.select``, ``evolution.kernels.breed``, same result) or the tensor
    operators (``update_stagnation``, ``allocate_offspring``, ``select_parents`` and the
    operators); by default the kernels wherever they can run (CPU, compiler present).
    ``runs``: ``g`` is a larger population and the other arguments describe its runs ``runs``
    (the kernel then reads those runs' parents in place). ``in_place`` (with ``runs``): the
    children replace those runs' genomes in ``g``, which is returned (the kernel writes them
    there directly; the tensor path copies them in).
    """
    if in_place and runs is None:
        raise ValueError("in_place needs runs=")
    use_kernels = breed_kernel.wanted(g, fused)
    if use_kernels:
        sp, survivors, counts, delta = select_kernel.species_state_offspring(fitness, species, sp, cfg, generation)
        first, second, do_cross, elite = select_kernel.select_parents(
            fitness, species, survivors, counts, cfg, rng, champions=delta)
    else:
        sp, survivors, counts, delta = species_offspring(fitness, species, sp, cfg, generation)
        first, second, do_cross, elite = select_parents(fitness, species, survivors, counts, cfg, rng,
                                                        champions=delta)
    if cfg.speciate_neatc:  # [NEATC]: the children are compared with their species' champions
        sp = champion_representatives(g, fitness, species, sp, runs)
    active = ~elite
    # [NEATC] delta coding: the champions' clones (all but the last, copied as it is) get
    # weights (80 %) or a new link (20 %), nothing else
    clones = (delta.unsqueeze(1) & active) if cfg.population_stagnation > 0 else None
    extra = extra_draws(cfg, rng, fitness.shape[1])
    if "mate_only" in extra:  # [NEATC]: some children of crossover are left as they are
        active = active & ~(do_cross & (extra["mate_only"] < cfg.mate_only_prob))
    average = do_cross & (extra["average"] < cfg.crossover_average_prob) if "average" in extra else None
    severe = extra["severe"] < 0.5 if "severe" in extra else None
    recurrent = extra["recurrent"] < cfg.recur_only_prob if "recurrent" in extra else None
    child_genes = None
    if use_kernels and breed_kernel.usable_for_species(sp.rep_conn, sp.rep_weight):
        # The living representatives' genes: the node slots they hold, and each child's closest
        # one, which breeding finds (speciate's first step).
        rep_genes = breed_kernel.GeneBits(sp.rep_conn, sp.rep_weight, sp.rep_sigma, alive=sp.alive)
        reps, reserved = (rep_genes, sp.rep_conn, sp.alive, sp.ident), breed_kernel.touched_nodes(rep_genes, sp.alive)
    else:
        reps, reserved = None, _rep_nodes(sp)
    if use_kernels:
        children, refused, child_genes = breed_kernel.breed(g, first, second, do_cross, active, cfg, rng, reserved,
                                                            runs=runs, in_place=in_place, reps=reps,
                                                            average=average, severe=severe, recurrent=recurrent,
                                                            clones=clones)
    else:
        whole = g
        if runs is not None:
            g = g.select_runs(runs)
        children = crossover(g.gather(first), g.gather(second), cfg, rng, do_cross, average)
        plain = active if clones is None else active & ~clones
        children, refused, node_wanted = mutate_add_node(children, cfg, rng, plain, reserved=reserved,
                                                         return_wanted=True)
        # [NEATC]: add-node, else add-connection, else the other mutations
        conn_active = active & ~node_wanted if cfg.mutation_exclusive else active
        link_prob = None if clones is None else torch.where(clones, CLONE_LINK_PROB if cfg.conn_add_prob > 0 else 0.0,
                                                               cfg.conn_add_prob)
        children, conn_wanted = mutate_add_connection(children, cfg, rng, conn_active, return_wanted=True,
                                                      recurrent=recurrent, prob=link_prob)
        rest = conn_active & ~conn_wanted if cfg.mutation_exclusive else active
        if clones is not None:
            rest = torch.where(clones, ~conn_wanted, rest)
        children = mutate_weights(children, cfg, rng, rest, severe, force=clones)
        rest = rest if clones is None else rest & ~clones
        children = mutate_sigma(children, cfg, rng, rest)
        children = mutate_toggle_enabled(children, cfg, rng, rest)
        if breed_kernel.toggles_one(cfg):
            children = mutate_toggle_one(children, cfg, rng, rest)
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




def champion_representatives(g: Genomes, fitness: Tensor, species: Tensor, sp: SpeciesState,
                             runs: Tensor | None = None) -> SpeciesState:
    """[NEATC]'s representatives: each living species' best member of the evaluated population
    (the first on ties), its rows copied into ``sp.rep_*``; species without a member keep theirs.
    ``runs``: ``g`` is a larger population and ``fitness``, ``species``, ``sp`` describe those runs."""
    R, P = species.shape
    S = sp.capacity
    g = distance_view(g)
    f = fitness.to(torch.float64)
    best = torch.full((R, S), -torch.inf, dtype=torch.float64, device=f.device).scatter_reduce(1, species, f, "amax")
    first = torch.where(f == best.gather(1, species), P - torch.arange(P, device=f.device), 0)
    top = torch.zeros(R, S, dtype=torch.long, device=f.device).scatter_reduce(1, species, first, "amax")
    has = sp.alive & (top > 0)
    run_rows = torch.arange(R, device=f.device) if runs is None else runs.to(f.device)
    rows = (run_rows.unsqueeze(1) * P + (P - top).clamp_max(P - 1)).flatten()
    reps = {k: getattr(g, k).flatten(0, 1).index_select(0, rows).view(R, S, *getattr(g, k).shape[2:])
            for k in ("conn", "weight", "sigma")}
    keep = has.view(R, S, 1, 1)
    return replace(sp, rep_conn=torch.where(keep, reps["conn"], sp.rep_conn),
                   rep_weight=torch.where(keep, reps["weight"], sp.rep_weight),
                   rep_sigma=torch.where(has, reps["sigma"], sp.rep_sigma))


def extra_draws(cfg: NEATConfig, rng: RunRNG, P: int) -> dict[str, Tensor]:
    """The per-child float64 uniforms ``[R, P]`` of the [NEATC] options that are on, in this
    order: ``mate_only`` (``cfg.mate_only_prob``), ``average`` (``cfg.crossover_average_prob``),
    ``severe`` (``cfg.weight_mutate_neatc``), ``recurrent`` (``cfg.conn_add_recurrence``). One block of ``P`` counters per run each, taken
    after selection on both paths, and none when all are off (the streams stay as they were)."""
    names = [name for name, on in (("mate_only", cfg.mate_only_prob > 0), ("average", cfg.crossover_average_prob > 0),
                                   ("severe", cfg.weight_mutate_neatc), ("recurrent", cfg.conn_add_recurrence)) if on]
    if not names:
        return {}
    u = rng.rand(len(names), P, dtype=torch.float64)
    return {name: u[:, k] for k, name in enumerate(names)}


def _parents_per_species(size: Tensor, cfg: NEATConfig) -> Tensor:
    """Parents of species of ``size`` members (long): [NEATC] ``floor(s * size + 1)`` (at most
    ``size``), computed in float64 as NEAT 1.2.1 does, or ``ceil(s * size)`` (at least 1) in
    float32, as a long tensor times a Python float is."""
    if cfg.survival_neatc:
        return torch.minimum(torch.floor(size.double() * cfg.survival_threshold + 1.0).long(), size)
    return torch.ceil(cfg.survival_threshold * size).long().clamp_min(1)


def select_parents(fitness: Tensor, species: Tensor, survivors: Tensor, counts: Tensor, cfg: NEATConfig,
                   rng: RunRNG, champions: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Parents of every child, as tensor operations (``evolution.kernels.select`` computes the
    same in C). Returns ``(first, second, do_cross, elite)``, all ``[R, P]``: ``first`` is the
    fitter parent where ``do_cross``; elites are copied unchanged. ``champions[R]``: in those
    runs every child is a clone of its species' best member, the last one its elite ([NEATC]
    delta coding); the same draws are taken."""
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
    n_parents = torch.where(size > 0, _parents_per_species(size, cfg), 0)

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
    if champions is not None and bool(champions.any()):
        clone = champions.unsqueeze(1).expand(R, P)
        champ = torch.gather(order, 1, o_start)
        elite = torch.where(clone, pos == torch.gather(counts, 1, osp) - 1, elite)
        p1, p2 = torch.where(clone, champ, p1), torch.where(clone, champ, p2)
        do_cross = do_cross & ~clone
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
