"""The breeding step and the compatibility distances as C kernels (CPU).

The tensor operators (``crossover``, ``mutate_*``, ``distance``) are the readable reference:
each touches every slot of every genome and draws a random number for every slot. These
kernels compute the same step a run at a time (threads share out the runs) and a child at a
time within it, touching only the child's genes and evaluating only the draws it uses: a
draw is addressed by its counter in the run's stream (``evolution.rng``), so skipping the
unused ones changes nothing, and the result is the same with any thread count.

- ``breed``: crossover, add-node (with the run's node registry in between), add-connection,
  weight, sigma and enabled mutations, in the reference's order and with its arithmetic
  (no contraction; float32 genomes round where torch rounds), and the same normals
  (``evolution.rng.box_muller``), so the children are the same bit for bit. It also writes
  the children's gene bitsets (``GeneBits``) and, given the representatives, each child's
  closest one (``speciate``'s first step), while a run's children are still in cache. The
  [NEATC] options (``reproduce``'s docstring lists them) are computed here too, the same.
- ``assign_species``: ``speciate``'s rule (closest living representative within the
  threshold, else found a species in genome order) from per-genome gene bitsets: excess,
  disjoint and matching genes by popcounts (against all living representatives at once, as
  vector loops), the weight term summed in double and skipped once the other terms reach
  the bound (the tests' ``tests/evolution/kernel_entry_points.gene_distances`` gives the distances themselves).
  The reference sums the weight term another way (``L1 - a_only - b_only``), so the two
  agree to about 1e-15.
- ``touched_nodes``: the node slots the living representatives use, from their bitsets
  (the node registry's reserved slots).

The C is ``evolution/kernels/csrc/breed.c`` (exports declared in ``breed.h``; the draws in
``counter_rng.h`` and ``box_muller.h``, the distance in ``gene_distance.h``), built once per
machine by ``snn_torch.kernels.build``; ``SNN_NEAT_C_KERNELS=0`` disables the kernels. ``breed``
and ``assign_species`` take structs declared in ``breed.h``: the config's parameters
(``BreedParams``, built by ``breed_params``), gene sets (``GeneSet``) and their arrays and sizes.
"""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.kernels import select as select_kernel
from evolution.neat121 import CLONE_LINK_PROB
from evolution.population import Genomes
from evolution.rng import RunRNG
from snn_torch.kernels.build import KernelLibrary, KernelStruct, load_libraries

__all__ = ["kernel_available", "usable_for", "wanted", "breed", "breed_blocks", "toggles_one", "GeneBits", "assign_species",
           "touched_nodes", "found_species", "put_rows", "BreedParams", "GeneSet", "BreedIO", "AssignIO",
           "breed_params", "gene_set"]

# Draw blocks of one breeding step, in the reference's order (the C enum B_* lists them in the
# same order): (name, "nn" for a [P, N, N] block or "p" for a [P] block, counters per draw).
_BLOCKS = (
    ("from_other", "nn", 1), ("stays_disabled", "nn", 1), ("sigma_pick", "p", 1),  # crossover
    ("node_want", "p", 1), ("node_pick", "p", 1),  # mutate_add_node
    ("conn_want", "p", 1), ("conn_pick", "p", 1), ("conn_init", "p", 2),  # mutate_add_connection
    ("w_genome", "p", 1), ("w_u", "nn", 1), ("w_noise", "nn", 2),  # mutate_weights
    ("s_want", "p", 1), ("s_noise", "p", 2),  # mutate_sigma
    ("toggle", "nn", 1),  # mutate_toggle_enabled
)
# mutate_toggle_one ([NEATC]): taken only when ``toggles_one(cfg)``, so that the default
# configs' streams stay as they were.
_TOGGLE_ONE_BLOCKS = (("one_want", "p", 1), ("one_pick", "p", 1), ("reenable_want", "p", 1))


def _clone_link_prob(cfg: NEATConfig) -> float:
    return CLONE_LINK_PROB if cfg.conn_add_prob > 0 else 0.0


def toggles_one(cfg: NEATConfig) -> bool:
    """Whether a breeding step runs ``mutate_toggle_one`` (and takes its draws)."""
    return cfg.toggle_enable_prob > 0 or cfg.gene_reenable_prob > 0


def breed_blocks(P: int, N: int, cfg: NEATConfig | None = None) -> tuple[list[int], int]:
    """Each block's first counter relative to the step's first, and the step's total."""
    starts, at = [], 0
    blocks = _BLOCKS + (_TOGGLE_ONE_BLOCKS if cfg is not None and toggles_one(cfg) else ())
    for _, kind, per in blocks:
        starts.append(at)
        at += (P * N * N if kind == "nn" else P) * per
    return starts, at


_CSRC = Path(__file__).resolve().parent / "csrc"
LIBRARY = ("neat_breed", _CSRC / "breed.c", _CSRC / "breed.h")  # (name, source, header)
MAX_NODES = 64  # the feed-forward closure keeps a row of the adjacency in one 64-bit word


_i64, _f64, _int, _ptr = ctypes.c_int64, ctypes.c_double, ctypes.c_int, ctypes.c_void_p


class BreedParams(KernelStruct):
    """``breed_params`` of ``breed.h``: what the kernels take from ``NEATConfig``."""
    _fields_ = [("inherit_disabled", _f64), ("node_add_prob", _f64), ("first_output", _i64),
                ("first_hidden", _i64), ("feed_forward", _int), ("per_gene", _int), ("conn_add_prob", _f64),
                ("w_mean", _f64), ("w_stdev", _f64), ("w_min", _f64), ("w_max", _f64), ("w_rate", _f64),
                ("w_rate_sum", _f64), ("w_replace", _f64), ("w_power", _f64), ("s_rate", _f64), ("s_power", _f64),
                ("s_min", _f64), ("s_max", _f64), ("toggle_rate", _f64), ("exclusive", _int), ("neatc", _int),
                ("recur_split", _int), ("one_on", _int), ("one_prob", _f64), ("re_prob", _f64),
                ("clone_link_prob", _f64), ("conn_tries", _i64), ("w_uniform", _int), ("shared_link", _int),
                ("split_first_bias", _i64), ("coef", _f64 * 5), ("thr", _f64)]


class GeneSet(KernelStruct):
    """``gene_set`` of ``breed.h``: a ``GeneBits``' arrays (pointers)."""
    _fields_ = [("bits", _ptr), ("before", _ptr), ("count", _ptr), ("top", _ptr), ("weight", _ptr),
                ("sigma", _ptr), ("map", _ptr)]


class BreedIO(KernelStruct):
    """``breed_io`` of ``breed.h``: ``breed``'s arrays (pointers) and sizes."""
    _fields_ = [("pw", _ptr), ("pc", _ptr), ("pe", _ptr), ("pn", _ptr), ("ps", _ptr), ("pm", _ptr), ("a_idx", _ptr),
                ("b_idx", _ptr), ("do_cross", _ptr), ("active", _ptr), ("cw", _ptr), ("cc", _ptr), ("ce", _ptr),
                ("cn", _ptr), ("cs", _ptr), ("cm", _ptr), ("src", _ptr), ("dst", _ptr), ("request", _ptr),
                ("new_node", _ptr), ("granted", _ptr), ("keys", _ptr), ("base", _ptr), ("blocks", _ptr),
                ("reserved", _ptr), ("dest_runs", _ptr), ("R", _i64), ("P", _i64), ("N", _i64), ("gbits", _ptr),
                ("gbefore", _ptr), ("gcount", _ptr), ("gtop", _ptr), ("gmap", _ptr), ("reps", _ptr),
                ("r_alive", _ptr), ("r_ident", _ptr), ("S", _i64), ("nearest", _ptr), ("threads", _int)]


class AssignIO(KernelStruct):
    """``assign_io`` of ``breed.h``: ``assign_species``' arrays (pointers) and sizes."""
    _fields_ = [("alive", _ptr), ("R", _i64), ("P", _i64), ("S", _i64), ("NN", _i64), ("W", _i64),
                ("species", _ptr), ("founded", _ptr), ("n_founded", _ptr), ("taken", _ptr), ("nearest", _ptr),
                ("r_ident", _ptr), ("threads", _int)]


def breed_params(cfg: NEATConfig) -> BreedParams:
    """The breeding and speciation kernels' parameters from ``cfg``."""
    return BreedParams(
        inherit_disabled=float(cfg.disabled_inherit_prob), node_add_prob=float(cfg.node_add_prob),
        first_output=cfg.first_output, first_hidden=cfg.first_hidden, feed_forward=int(cfg.feed_forward),
        per_gene=int(cfg.weight_mutate_per_gene), conn_add_prob=float(cfg.conn_add_prob),
        w_mean=float(cfg.weight_init_mean), w_stdev=float(cfg.weight_init_stdev), w_min=float(cfg.weight_min_value),
        w_max=float(cfg.weight_max_value), w_rate=float(cfg.weight_mutate_rate),
        w_rate_sum=float(cfg.weight_mutate_rate + cfg.weight_replace_rate), w_replace=float(cfg.weight_replace_rate),
        w_power=float(cfg.weight_mutate_power), s_rate=float(cfg.sigma_mutate_rate),
        s_power=float(cfg.sigma_mutate_power), s_min=float(cfg.sigma_min_value), s_max=float(cfg.sigma_max_value),
        toggle_rate=float(cfg.enabled_mutate_rate), exclusive=int(cfg.mutation_exclusive),
        neatc=int(cfg.weight_mutate_neatc), recur_split=int(cfg.conn_add_recurrence), one_on=int(toggles_one(cfg)),
        one_prob=float(cfg.toggle_enable_prob), re_prob=float(cfg.gene_reenable_prob),
        clone_link_prob=_clone_link_prob(cfg), conn_tries=int(cfg.conn_add_tries),
        w_uniform=int(cfg.weight_init_uniform), shared_link=int(cfg.conn_add_shared_weight),
        split_first_bias=cfg.num_inputs if cfg.node_add_neatc else -1,
        coef=(_f64 * 5)(cfg.compatibility_excess_coefficient, cfg.compatibility_disjoint_coefficient,
                        cfg.compatibility_weight_coefficient, cfg.compatibility_sigma_coefficient,
                        cfg.compatibility_normalize_min_genes),
        thr=float(cfg.compatibility_threshold))


def gene_set(g: GeneBits) -> GeneSet:
    """The kernels' view of ``g`` (its tensors' addresses: valid while ``g`` lives)."""
    return GeneSet(bits=g.bits.data_ptr(), before=g.before.data_ptr(), count=g.count.data_ptr(),
                   top=g.top.data_ptr(), weight=g.weight.data_ptr(), sigma=g.sigma.data_ptr(),
                   map=None if g.map is None else g.map.data_ptr())


def _library() -> KernelLibrary | None:
    # A GA step uses both libraries: a cold start builds them side by side.
    return load_libraries([LIBRARY, select_kernel.LIBRARY])[0]


def kernel_available() -> bool:
    """True if the breeding kernels compiled (once per machine) and are enabled."""
    return _library() is not None


def _unsupported(conn: Tensor, weight: Tensor) -> str | None:
    """Why the kernels cannot take these genes, or None if they can."""
    if conn.device.type != "cpu" or weight.dtype not in (torch.float32, torch.float64) or conn.shape[-1] > MAX_NODES:
        return (f"the C breeding kernels take CPU float32/float64 genomes of at most {MAX_NODES} nodes, "
                f"got {weight.dtype} on {conn.device} with {conn.shape[-1]} nodes")
    return None


def usable_for(g: Genomes) -> bool:
    """The kernels take CPU genomes of float32/float64 with at most ``MAX_NODES`` nodes."""
    return _unsupported(g.conn, g.weight) is None and kernel_available()


def wanted(g: Genomes, fused: bool | None) -> bool:
    """Whether a step on ``g`` runs on the C kernels (these and ``evolution.kernels.select``):
    ``fused`` when given, else wherever they can run."""
    return (usable_for(g) and select_kernel.kernel_available()) if fused is None else fused


def usable_for_species(sp_conn: Tensor, sp_weight: Tensor) -> bool:
    """``usable_for`` for species representatives ``[R, S, N, N]``."""
    return _unsupported(sp_conn, sp_weight) is None and kernel_available()


def _sfx(dtype: torch.dtype) -> str:
    return "f32" if dtype == torch.float32 else "f64"


def _kernels() -> KernelLibrary:
    lib = _library()
    if lib is None:
        raise RuntimeError("the C breeding kernels are unavailable (no compiler, or SNN_NEAT_C_KERNELS=0); "
                           "use fused=False")
    return lib


def _require(conn: Tensor, weight: Tensor) -> KernelLibrary:
    """The kernels; refuse, by name, what they cannot take (asked for with ``fused=True``)."""
    lib = _kernels()
    reason = _unsupported(conn, weight)
    if reason is not None:
        raise ValueError(f"{reason}; use fused=False")
    return lib


def breed(g: Genomes, first: Tensor, second: Tensor, do_cross: Tensor, active: Tensor, cfg: NEATConfig,
          rng: RunRNG, reserved: Tensor | None, *, runs: Tensor | None = None, in_place: bool = False,
          reps: tuple[GeneBits, Tensor, Tensor, Tensor] | None = None, average: Tensor | None = None,
          severe: Tensor | None = None, recurrent: Tensor | None = None, clones: Tensor | None = None
          ) -> tuple[Genomes, Tensor, GeneBits]:
    """Children ``[R, P]`` of parents ``first`` / ``second`` (``[R, P]`` genome indices of
    ``g``; ``first`` is the fitter where ``do_cross``), mutated where ``active``: the same as
    ``crossover`` then ``mutate_add_node``, ``mutate_add_connection``, ``mutate_weights``,
    ``mutate_sigma`` and ``mutate_toggle_enabled``, and the same draws. Returns the children,
    ``[R, P]`` bool: splits refused for want of a free node slot, and the children's
    ``GeneBits`` (built as the genes are written, so ``speciate`` need not scan them again;
    valid while the children are unchanged). ``runs[R]``: the parents are those runs of ``g``
    (a larger population), read in place; with ``in_place`` the children overwrite them (each
    run's parents are copied aside first) and ``g`` itself is returned. ``reps``: ``(bits,
    rep_conn, alive, ident)`` of the species representatives ``[R, S]``; each child's closest
    living one within the threshold (with ``cfg.speciate_neatc`` the first in ``ident`` order) is then found as the run's children are written (speciate's first
    step, while they are in cache), kept in the returned ``GeneBits`` for ``speciate``.
    ``average[R, P]``, ``severe[R, P]``, ``recurrent[R, P]``: [NEATC]'s averaging crossovers,
    severe weight mutations and recurrent new links (``reproduce.extra_draws``), as
    ``crossover``, ``mutate_weights`` and ``mutate_add_connection`` take them;
    ``cfg.mutation_exclusive`` as ``reproduce`` gates the mutations, and ``mutate_toggle_one``
    last where ``toggles_one(cfg)``. ``clones[R, P]``: delta coding's clones of a champion,
    mutated as ``reproduce`` mutates them (a new link with ``neat121.CLONE_LINK_PROB``, else
    every weight). ``g.mutation_num``, where carried, is bred as the reference breeds it, and the
    closest representatives go by the children's (``speciate.distance_view``)."""
    lib = _require(g.conn, g.weight)
    (R, P), N = first.shape, g.num_nodes
    T = g.weight.dtype
    threads = torch.get_num_threads()
    starts, total = breed_blocks(P, N, cfg)
    base = rng.take(total)
    keys, blocks = rng.keys.contiguous(), torch.tensor(starts, dtype=torch.int64)
    if in_place and (runs is None or not all(t.is_contiguous() for t in g.tensors().values())):
        raise ValueError("in_place breeding needs runs= and contiguous genome tensors")
    parents = {k: v.contiguous() for k, v in g.tensors().items()}
    rows = (torch.arange(R) if runs is None else runs.to(torch.int64).cpu()).unsqueeze(1) * P
    a_idx, b_idx = (first + rows).contiguous(), (second + rows).contiguous()
    cross, act = do_cross.to(torch.uint8), active.to(torch.uint8)
    if average is not None:  # 2: average the matching genes' weights
        cross = cross + (do_cross & average).to(torch.uint8)
    # active's further bits, where active: 2 a severe weight mutation, 4 a recurrent new link,
    # 8 a champion's clone
    for flags, bit in ((severe, 2), (recurrent, 4), (clones, 8)):
        if flags is not None:
            act = act | (active & flags).to(torch.uint8) * bit
    cross, act = cross.contiguous(), act.contiguous()
    child = g if in_place else Genomes(**{k: torch.empty((R, P, *t.shape[2:]), dtype=t.dtype)
                                          for k, t in parents.items()})
    dest = runs.to(torch.int64).cpu().contiguous() if in_place else None
    src = torch.empty(R, P, dtype=torch.int64)
    dst = torch.empty(R, P, dtype=torch.int64)
    request = torch.empty(R, P, dtype=torch.uint8)
    new_node = torch.empty(R, P, dtype=torch.int64)
    granted = torch.empty(R, P, dtype=torch.uint8)
    reserved8 = (torch.zeros(R, N, dtype=torch.uint8) if reserved is None
                 else reserved.to(torch.uint8).contiguous())
    words = (N * N + 63) // 64
    genes = GeneBits.__new__(GeneBits)
    # the distance reads mutation_num where it is carried (speciate.distance_view)
    genes._bind(child.weight if child.mutation_num is None else child.mutation_num, child.sigma, dest)
    rep_set, rep_ident, alive8, S = None, None, None, 0
    if reps is not None:
        rep_bits, rep_conn, alive, ident = reps
        # [NEATC]'s first fit goes by the species' numbers; the closest rule needs none
        rep_ident = ident.to(torch.int64).contiguous() if cfg.speciate_neatc else None
        genes.nearest = torch.empty(R, P, dtype=torch.int64)
        genes.nearest_to = (rep_bits, rep_conn, alive.clone())
        rep_set, alive8, S = gene_set(rep_bits), alive.to(torch.uint8).contiguous(), alive.shape[1]
    bits, before = torch.empty(R * P, words, dtype=torch.int64), torch.empty(R * P, words, dtype=torch.int64)
    count, top = torch.empty(R * P, dtype=torch.int64), torch.empty(R * P, dtype=torch.int64)
    carried = g.mutation_num is not None
    io = BreedIO(
        pw=parents["weight"].data_ptr(), pc=parents["conn"].data_ptr(), pe=parents["enabled"].data_ptr(),
        pn=parents["node"].data_ptr(), ps=parents["sigma"].data_ptr(),
        pm=parents["mutation_num"].data_ptr() if carried else None, a_idx=a_idx.data_ptr(), b_idx=b_idx.data_ptr(),
        do_cross=cross.data_ptr(), active=act.data_ptr(), cw=child.weight.data_ptr(), cc=child.conn.data_ptr(),
        ce=child.enabled.data_ptr(), cn=child.node.data_ptr(), cs=child.sigma.data_ptr(),
        cm=child.mutation_num.data_ptr() if carried else None, src=src.data_ptr(), dst=dst.data_ptr(),
        request=request.data_ptr(), new_node=new_node.data_ptr(), granted=granted.data_ptr(), keys=keys.data_ptr(),
        base=base.data_ptr(), blocks=blocks.data_ptr(), reserved=reserved8.data_ptr(),
        dest_runs=None if dest is None else dest.data_ptr(), R=R, P=P, N=N, gbits=bits.data_ptr(),
        gbefore=before.data_ptr(), gcount=count.data_ptr(), gtop=top.data_ptr(),
        gmap=None if genes.map is None else genes.map.data_ptr(),
        reps=None if rep_set is None else ctypes.addressof(rep_set), r_alive=None if alive8 is None else alive8.data_ptr(),
        r_ident=None if rep_ident is None else rep_ident.data_ptr(), S=S,
        nearest=None if genes.nearest is None else genes.nearest.data_ptr(), threads=threads)
    getattr(lib, f"breed_{_sfx(T)}")(ctypes.byref(breed_params(cfg)), ctypes.byref(io))
    genes.bits, genes.before, genes.count, genes.top = bits, before, count, top
    return child, request.bool() & ~granted.bool(), genes


class GeneBits:
    """Gene bitsets of a set of genomes ``conn [..., N, N]`` (flattened to rows), with their
    weights and sigmas, for the compatibility distances. ``runs``: of those runs of ``conn [R, P, N, N]``
    only (the tensors are read in place, not copied). ``alive`` (one flag per row): rows not
    alive (dead species' slots) get no genes, unread."""

    def __init__(self, conn: Tensor, weight: Tensor, sigma: Tensor, runs: Tensor | None = None,
                 alive: Tensor | None = None) -> None:
        lib = _require(conn, weight)
        self._bind(weight, sigma, runs)
        c = conn.reshape(-1, self.nn).contiguous()
        M = self.rows
        live = None if alive is None else alive.reshape(-1).to(torch.uint8).contiguous()
        if live is not None and live.numel() != M:
            raise ValueError(f"alive has {live.numel()} flags for {M} rows")
        self.bits = torch.empty(M, self.words, dtype=torch.int64)
        self.before = torch.empty(M, self.words, dtype=torch.int64)  # genes in the words before
        self.count = torch.empty(M, dtype=torch.int64)
        self.top = torch.empty(M, dtype=torch.int64)
        lib.gene_bits(c.data_ptr(), None if self.map is None else self.map.data_ptr(),
                       None if live is None else live.data_ptr(), M, self.nn, self.words,
                       self.bits.data_ptr(), self.before.data_ptr(), self.count.data_ptr(), self.top.data_ptr(),
                       torch.get_num_threads())

    def _bind(self, weight: Tensor, sigma: Tensor, runs: Tensor | None) -> None:
        """The genomes' weights and sigmas (``[R, P, N, N]``, ``[R, P]``), and the row map."""
        N = weight.shape[-1]
        self.nn = N * N
        self.words = (self.nn + 63) // 64
        self.weight = weight.reshape(-1, self.nn).contiguous()
        self.sigma = sigma.reshape(-1).to(weight.dtype).contiguous()
        self.map: Tensor | None = None  # the weight and sigma row of each bitset row
        if runs is not None:
            P = weight.shape[1]
            self.map = (runs.to(torch.int64).cpu().unsqueeze(1) * P + torch.arange(P)).flatten().contiguous()
        self.rows = self.weight.shape[0] if self.map is None else self.map.shape[0]
        # breed's closest representatives (``reps=``), and of which: (bits, rep_conn, alive)
        self.nearest: Tensor | None = None
        self.nearest_to: tuple[GeneBits, Tensor, Tensor] | None = None


def found_species(founded: Tensor, n_founded: Tensor, generation: int, alive: Tensor, best_fitness: Tensor,
                  last_improved: Tensor, created: Tensor, ident: Tensor, next_id: Tensor) -> None:
    """Record, in place, the species ``assign_species`` founded (run ``r``'s in slots
    ``founded[r, :n_founded[r]]``, all below ``S``): alive, no best fitness yet, created and
    improved in ``generation``, numbered from the run's ``next_id`` on, which advances. The
    species state tensors (``[R, S]``, ``next_id [R]``) must be contiguous CPU tensors of
    their usual dtypes (bool, float64, int64)."""
    R, S = alive.shape
    state = (alive, best_fitness, last_improved, created, ident, next_id)
    want = (torch.bool, torch.float64, torch.int64, torch.int64, torch.int64, torch.int64)
    if any(t.dtype != d or not t.is_contiguous() or t.device.type != "cpu" for t, d in zip(state, want, strict=True)):
        raise ValueError("found_species takes contiguous CPU species state tensors of their usual dtypes")
    f, n = founded.to(torch.int64).contiguous(), n_founded.to(torch.int64).contiguous()
    if _kernels().found_species(f.data_ptr(), n.data_ptr(), R, f.shape[1], S, int(generation),
                          *(t.data_ptr() for t in state)):
        raise ValueError(f"a founded slot is beyond the {S} slots: grow the state first")


def put_rows(dst: Tensor, idx: Tensor, src: Tensor) -> None:
    """``dst[idx] = src`` along the first dimension, whole rows by ``memcpy`` (CPU; ``dst``
    contiguous). Indexed assignment copies element by element, 2x slower on a population's
    representatives."""
    lib = _library()
    if lib is None:
        raise RuntimeError("the C breeding kernels are unavailable; use dst[idx] = src")
    if dst.device.type != "cpu" or not dst.is_contiguous() or src.dtype != dst.dtype:
        raise ValueError(f"put_rows takes a contiguous CPU dst and a src of its dtype, got {dst.dtype} on "
                         f"{dst.device} and {src.dtype}")
    rows = idx.to(torch.int64).cpu().contiguous()
    if tuple(src.shape) != (rows.numel(), *dst.shape[1:]):
        raise ValueError(f"src has shape {tuple(src.shape)}, expected {(rows.numel(), *dst.shape[1:])}")
    s = src.contiguous()
    row_bytes = dst[0].numel() * dst.element_size() if dst.shape[0] else 0
    if lib.put_rows(dst.data_ptr(), s.data_ptr(), rows.data_ptr(), rows.numel(), dst.shape[0], row_bytes):
        raise IndexError(f"put_rows: an index is outside [0, {dst.shape[0]})")


def touched_nodes(genes: GeneBits, alive: Tensor) -> Tensor:
    """``[R, N]`` bool: node slots touched by a gene of a living row, ``alive[R, S]``, of the
    representatives' bitsets ``genes`` (``R x S`` rows)."""
    R, S = alive.shape
    N = math.isqrt(genes.nn)
    if genes.rows != R * S:
        raise ValueError(f"genes has {genes.rows} rows, alive flags {R} x {S}")
    out = torch.empty(R, N, dtype=torch.bool)
    a = alive.to(torch.uint8).contiguous()
    _kernels().touched_nodes(genes.bits.data_ptr(), a.data_ptr(), R, S, genes.words, N, out.data_ptr())
    return out


def assign_species(genes: GeneBits, reps: GeneBits, alive: Tensor, cfg: NEATConfig,
                   nearest: Tensor | None = None, ident: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor]:
    """``speciate``'s assignment for genomes ``genes`` (``R x P`` rows) and representatives
    ``reps`` (``R x S`` rows, ``alive[R, S]``): the closest living representative within the
    threshold, else a new species founded in genome order (``evolution.speciate``).

    Returns ``(species [R, P], founded [R, P], n_founded [R])``: run ``r``'s new species are
    in slots ``founded[r, :n_founded[r]]``, in founding order; a slot >= S asks for growth.
    ``nearest[R, P]``: each genome's closest representative (-1: none), already found by
    ``breed(..., reps=)``; only the founding is left. ``ident[R, S]`` (int64, with
    ``cfg.speciate_neatc``): the species' numbers; a genome then joins the first species within
    the threshold in that order ([NEATC]), not the closest."""
    if cfg.speciate_neatc and ident is None:
        raise ValueError("assign_species: cfg.speciate_neatc needs the species' numbers (ident=)")
    ident = ident.to(torch.int64).contiguous() if cfg.speciate_neatc else None
    R, S = alive.shape
    P = genes.count.shape[0] // R
    species = torch.empty(R, P, dtype=torch.int64)
    founded = torch.zeros(R, P, dtype=torch.int64)
    n_founded = torch.empty(R, dtype=torch.int64)
    taken = torch.empty(R, S + P, dtype=torch.uint8)
    alive8 = alive.to(torch.uint8).contiguous()
    near = None if nearest is None else nearest.to(torch.int64).contiguous()
    io = AssignIO(alive=alive8.data_ptr(), R=R, P=P, S=S, NN=genes.nn, W=genes.words, species=species.data_ptr(),
                  founded=founded.data_ptr(), n_founded=n_founded.data_ptr(), taken=taken.data_ptr(),
                  nearest=None if near is None else near.data_ptr(), r_ident=None if ident is None else ident.data_ptr(),
                  threads=torch.get_num_threads())
    getattr(_kernels(), f"assign_species_{_sfx(genes.weight.dtype)}")(
        ctypes.byref(breed_params(cfg)), ctypes.byref(gene_set(genes)), ctypes.byref(gene_set(reps)), ctypes.byref(io))
    return species, founded, n_founded
