"""Parent selection and the choice of representatives as C kernels (CPU).

``evolution.reproduce`` selects parents and ``evolution.speciate`` chooses each species'
representative with about a hundred small tensor operations over ``[R, P]`` (sorts, gathers,
searches, scatters): the readable reference, and the CUDA path. On the CPU their per-op
overhead made them a third of a generation's GA work, so these kernels do the same a run at
a time (threads share out the runs), with the same draws (addressed by counter,
``evolution.rng``) and the same arithmetic, so the results are the same bit for bit.

- ``species_state_offspring``: the species' records, stagnation, offspring per species, the
  run's record and [NEATC]'s obliteration and delta coding (``reproduce.species_offspring``,
  three dozen tensor operations on ``[R, S]``); ``species_offspring``, its older form.
- ``select_parents``: members sorted by (species, fitness descending, index), the elites,
  the two parents of each child (within the species, or the second from any species' parents
  for interspecies mating), the crossover decision.
- ``choose_representatives``: each species' member with the highest score (the last such
  member on an exact tie, as the reference's scatter), its genes copied as whole rows; slots
  without members emptied.

The C is ``evolution/kernels/csrc/select.c`` (exports declared in ``select.h``), built once per machine
by ``snn_torch.kernels.build``. Each entry point takes structs declared there: the config's
parameters (``SelectParams``, built by ``select_params``) and its arrays and sizes (``*IO``).
"""

from __future__ import annotations

import ctypes
import dataclasses
from pathlib import Path

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.population import Genomes
from evolution.rng import RunRNG
from evolution.species_state import SpeciesState
from snn_torch.kernels.build import KernelLibrary, KernelStruct, load_library

__all__ = ["kernel_available", "select_parents", "species_offspring", "species_state_offspring", "choose_representatives",
           "SELECTION_DRAWS", "SelectParams", "SelectParentsIO", "OffspringIO", "RepsIO", "select_params"]

SELECTION_DRAWS = 5  # float64 uniform blocks of P per run: p1, p2, any parent, interspecies, crossover

_CSRC = Path(__file__).resolve().parent / "csrc"
LIBRARY = ("neat_select", _CSRC / "select.c", _CSRC / "select.h")  # (name, source, header)


_i64, _f64, _int, _ptr = ctypes.c_int64, ctypes.c_double, ctypes.c_int, ctypes.c_void_p


class SelectParams(KernelStruct):
    """``select_params`` of ``select.h``: what the kernels take from ``NEATConfig``."""
    _fields_ = [("survival", _f64), ("survival_neatc", _int), ("elitism", _i64), ("elitism_min", _i64),
                ("inter_prob", _f64), ("cross_prob", _f64), ("max_stagnation", _i64), ("species_elitism", _i64),
                ("penalty", _f64), ("obliterate_interval", _i64), ("obliterate_min_age", _i64),
                ("pop_stagnation", _i64), ("clock_before", _i64)]


class SelectParentsIO(KernelStruct):
    """``select_parents_io`` of ``select.h``: ``select_parents``' arrays (pointers) and sizes."""
    _fields_ = [("fitness", _ptr), ("species", _ptr), ("survivors", _ptr), ("counts", _ptr), ("keys", _ptr),
                ("base", _ptr), ("champions", _ptr), ("R", _i64), ("P", _i64), ("S", _i64), ("first", _ptr),
                ("second", _ptr), ("do_cross", _ptr), ("elite", _ptr), ("threads", _int)]


class OffspringIO(KernelStruct):
    """``offspring_io`` of ``select.h``: ``species_offspring``'s arrays (pointers) and sizes."""
    _fields_ = [("fitness", _ptr), ("species", _ptr), ("alive", _ptr), ("best_in", _ptr), ("last_in", _ptr),
                ("created", _ptr), ("obl_in", _ptr), ("run_best_in", _ptr), ("run_stale_in", _ptr), ("R", _i64),
                ("P", _i64), ("S", _i64), ("generation", _i64), ("best_out", _ptr), ("last_out", _ptr),
                ("obl_out", _ptr), ("run_best_out", _ptr), ("run_stale_out", _ptr), ("survivors", _ptr),
                ("counts", _ptr), ("delta", _ptr), ("threads", _int)]


class RepsIO(KernelStruct):
    """``reps_io`` of ``select.h``: ``choose_representatives``' arrays (pointers) and sizes."""
    _fields_ = [("species", _ptr), ("conn", _ptr), ("weight", _ptr), ("sigma", _ptr), ("runs", _ptr),
                ("keys", _ptr), ("base", _ptr), ("R", _i64), ("P", _i64), ("S", _i64), ("NN", _i64),
                ("alive", _ptr), ("rep_conn", _ptr), ("rep_weight", _ptr), ("rep_sigma", _ptr), ("threads", _int)]


def select_params(cfg: NEATConfig) -> SelectParams:
    """The selection kernels' parameters from ``cfg``."""
    return SelectParams(
        survival=float(cfg.survival_threshold), survival_neatc=int(cfg.survival_neatc), elitism=int(cfg.elitism),
        elitism_min=int(cfg.elitism_min_species_size), inter_prob=float(cfg.interspecies_crossover_prob),
        cross_prob=float(cfg.crossover_prob), max_stagnation=int(cfg.max_stagnation),
        species_elitism=int(cfg.species_elitism), penalty=float(cfg.stagnant_fitness_factor),
        obliterate_interval=int(cfg.obliterate_interval), obliterate_min_age=int(cfg.obliterate_min_age),
        pop_stagnation=int(cfg.population_stagnation), clock_before=int(cfg.stagnation_clock_before))


def _library() -> KernelLibrary | None:
    return load_library(*LIBRARY)


def kernel_available() -> bool:
    """True if the selection kernels compiled (once per machine) and are enabled."""
    return _library() is not None


def _require() -> KernelLibrary:
    lib = _library()
    if lib is None:
        raise RuntimeError("the C selection kernels are unavailable (no compiler, or SNN_NEAT_C_KERNELS=0); "
                           "use fused=False")
    return lib


def select_parents(fitness: Tensor, species: Tensor, survivors: Tensor, counts: Tensor, cfg: NEATConfig,
                   rng: RunRNG, champions: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """``reproduce``'s selection for ``fitness[R, P]`` (float64), ``species[R, P]``,
    ``survivors[R, S]`` and ``counts[R, S]`` (offspring per slot); takes ``SELECTION_DRAWS``
    blocks of ``P`` counters per run. Returns ``(first, second, do_cross, elite)``, all
    ``[R, P]``: the parents (``first`` the fitter where ``do_cross``), whether to cross, and
    the elites (copied unchanged). ``champions[R]``: those runs' children are clones of their
    species' champions ([NEATC] delta coding, ``reproduce.select_parents``)."""
    lib = _require()
    R, P = fitness.shape
    S = survivors.shape[1]
    total = counts.sum(1)
    if bool((counts < 0).any() | ((total != P) & (total != 0)).any()):  # the C indexes by them: refuse, not crash
        raise ValueError(f"select_parents: offspring counts must be >= 0 and sum to {P} (or 0) per run, "
                         f"got sums {total.tolist()}")
    base = rng.take(SELECTION_DRAWS * P)
    first, second = torch.empty(R, P, dtype=torch.int64), torch.empty(R, P, dtype=torch.int64)
    do_cross, elite = torch.empty(R, P, dtype=torch.uint8), torch.empty(R, P, dtype=torch.uint8)
    f = fitness.to(torch.float64).contiguous()
    sp, sv, cnt = species.contiguous(), survivors.to(torch.uint8).contiguous(), counts.contiguous()
    keys = rng.keys.contiguous()
    champ = None if champions is None else champions.to(torch.uint8).contiguous()
    io = SelectParentsIO(fitness=f.data_ptr(), species=sp.data_ptr(), survivors=sv.data_ptr(), counts=cnt.data_ptr(),
                         keys=keys.data_ptr(), base=base.data_ptr(),
                         champions=None if champ is None else champ.data_ptr(), R=R, P=P, S=S,
                         first=first.data_ptr(), second=second.data_ptr(), do_cross=do_cross.data_ptr(),
                         elite=elite.data_ptr(), threads=torch.get_num_threads())
    lib.select_parents(ctypes.byref(select_params(cfg)), ctypes.byref(io))
    return first, second, do_cross.bool(), elite.bool()


def species_offspring(fitness: Tensor, species: Tensor, alive: Tensor, best_fitness: Tensor, last_improved: Tensor,
                      cfg: NEATConfig, generation: int) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """``reproduce``'s ``update_stagnation`` then ``allocate_offspring`` in one call, the same
    bit for bit: ``fitness[R, P]``, ``species[R, P]``, and the species slots' ``alive``,
    ``best_fitness`` and ``last_improved`` (``[R, S]``). Returns ``(best_fitness,
    last_improved, survivors, counts)``, all ``[R, S]``: the updated records, the species
    kept, and offspring per slot (``P`` in every run with a survivor). For a config without
    [NEATC]'s obliteration and delta coding (else ``species_state_offspring``)."""
    R, S = alive.shape
    out = _offspring(fitness, species, alive, best_fitness, last_improved, torch.zeros(R, S, dtype=torch.int64),
                     torch.zeros(R, S, dtype=torch.bool), torch.full((R,), -torch.inf, dtype=torch.float64),
                     torch.zeros(R, dtype=torch.int64), cfg, generation)
    return out["best_fitness"], out["last_improved"], out["survivors"], out["counts"]


def species_state_offspring(fitness: Tensor, species: Tensor, sp: SpeciesState, cfg: NEATConfig, generation: int
                            ) -> tuple[SpeciesState, Tensor, Tensor, Tensor]:
    """``reproduce.species_offspring`` in one call, the same bit for bit: the species' records
    (best fitness, last improvement, obliteration), stagnation, offspring per species, the
    run's record and [NEATC]'s delta coding. Returns ``(state, survivors [R, S], counts [R, S],
    delta [R])``."""
    out = _offspring(fitness, species, sp.alive, sp.best_fitness, sp.last_improved, sp.created, sp.obliterated,
                     sp.run_best, sp.run_stale, cfg, generation)
    new = dataclasses.replace(sp, **{k: out[k] for k in ("best_fitness", "last_improved", "obliterated", "run_best",
                                                          "run_stale")})
    return new, out["survivors"], out["counts"], out["delta"]


def _offspring(fitness: Tensor, species: Tensor, alive: Tensor, best_fitness: Tensor, last_improved: Tensor,
               created: Tensor, obliterated: Tensor, run_best: Tensor, run_stale: Tensor, cfg: NEATConfig,
               generation: int) -> dict[str, Tensor]:
    """The C call behind ``species_offspring`` and ``species_state_offspring``: the slots' new
    records, ``survivors``, ``counts`` and the runs' ``delta`` coding, by name."""
    lib = _require()
    R, S = alive.shape
    P = fitness.shape[1]
    best, last = torch.empty(R, S, dtype=torch.float64), torch.empty(R, S, dtype=torch.int64)
    obl, run_best_out, run_stale_out = torch.empty(R, S, dtype=torch.uint8), torch.empty(R, dtype=torch.float64), \
        torch.empty(R, dtype=torch.int64)
    survivors, counts = torch.empty(R, S, dtype=torch.uint8), torch.empty(R, S, dtype=torch.int64)
    delta = torch.empty(R, dtype=torch.uint8)
    f = fitness.to(torch.float64).contiguous()
    spc, al = species.to(torch.int64).contiguous(), alive.to(torch.uint8).contiguous()
    b_in, l_in = best_fitness.to(torch.float64).contiguous(), last_improved.to(torch.int64).contiguous()
    created, o_in = created.to(torch.int64).contiguous(), obliterated.to(torch.uint8).contiguous()
    rb_in, rs_in = run_best.to(torch.float64).contiguous(), run_stale.to(torch.int64).contiguous()
    io = OffspringIO(fitness=f.data_ptr(), species=spc.data_ptr(), alive=al.data_ptr(), best_in=b_in.data_ptr(),
                     last_in=l_in.data_ptr(), created=created.data_ptr(), obl_in=o_in.data_ptr(),
                     run_best_in=rb_in.data_ptr(), run_stale_in=rs_in.data_ptr(), R=R, P=P, S=S,
                     generation=int(generation), best_out=best.data_ptr(), last_out=last.data_ptr(),
                     obl_out=obl.data_ptr(), run_best_out=run_best_out.data_ptr(),
                     run_stale_out=run_stale_out.data_ptr(), survivors=survivors.data_ptr(),
                     counts=counts.data_ptr(), delta=delta.data_ptr(), threads=torch.get_num_threads())
    lib.species_offspring(ctypes.byref(select_params(cfg)), ctypes.byref(io))
    return {"best_fitness": best, "last_improved": last, "obliterated": obl.bool(), "run_best": run_best_out,
            "run_stale": run_stale_out, "survivors": survivors.bool(), "counts": counts, "delta": delta.bool()}


def choose_representatives(g: Genomes, species: Tensor, capacity: int, rng: RunRNG, runs: Tensor | None = None
                           ) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """``speciate``'s representatives: ``(alive [R, S], rep_conn, rep_weight, rep_sigma)``
    for ``capacity`` slots; takes one block of ``P`` counters per run. ``runs``: the genomes
    ``species[R, P]`` describes are those runs of ``g`` (read in place)."""
    lib = _require()
    R, P, N = species.shape[0], g.pop_size, g.num_nodes
    base = rng.take(P)
    T = g.weight.dtype
    alive = torch.empty(R, capacity, dtype=torch.uint8)
    rep_conn = torch.empty(R, capacity, N, N, dtype=torch.bool)
    rep_weight = torch.empty(R, capacity, N, N, dtype=T)
    rep_sigma = torch.empty(R, capacity, dtype=T)
    conn, weight, sigma = g.conn.contiguous(), g.weight.contiguous(), g.sigma.contiguous()
    sp, keys = species.contiguous(), rng.keys.contiguous()
    rows = None if runs is None else runs.to(torch.int64).cpu().contiguous()
    io = RepsIO(species=sp.data_ptr(), conn=conn.data_ptr(), weight=weight.data_ptr(), sigma=sigma.data_ptr(),
                runs=None if rows is None else rows.data_ptr(), keys=keys.data_ptr(), base=base.data_ptr(), R=R,
                P=P, S=capacity, NN=N * N, alive=alive.data_ptr(), rep_conn=rep_conn.data_ptr(),
                rep_weight=rep_weight.data_ptr(), rep_sigma=rep_sigma.data_ptr(), threads=torch.get_num_threads())
    getattr(lib, f"choose_representatives_{'f32' if T == torch.float32 else 'f64'}")(ctypes.byref(io))
    return alive.bool(), rep_conn, rep_weight, rep_sigma
