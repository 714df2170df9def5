"""The population as tensors, and its invariants.

``R`` independent runs of ``P`` genomes over a shared node index of capacity ``N``:

- ``weight[R, P, N, N]`` float: connection (i, j) from node i to node j; exactly 0 where no gene.
- ``conn[R, P, N, N]`` bool: the gene exists. ``enabled[R, P, N, N]`` bool: it is expressed.
- ``node[R, P, N]`` bool: node present. Slots ``[0, num_inputs)`` are inputs, then
  ``num_bias`` bias nodes, then outputs, then hidden slots. Inputs, bias and outputs are
  always present.
- ``sigma[R, P]`` float: Qiu et al.'s evolved decoder gain (positive).
- ``mutation_num[R, P, N, N]`` float, only with ``NEATConfig.compat_mutation_num`` (else None):
  each gene's weight as of its genome's last weight mutation ([NEATC] ``Gene::mutation_num``),
  which the compatibility distance reads instead of the weight; exactly 0 where no gene.

Slot ``i`` is node ``i``'s historical marking; slot ``(i, j)`` is the connection's. So the
same gene sits at the same place in every genome of a run.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.rng import RunRNG
from snn_torch.functional.counter_rng import mix64

__all__ = ["Genomes", "initial_genomes", "random_genomes", "start_mutation_num", "check_invariants", "InvariantError", "reachability"]


class InvariantError(AssertionError):
    """A population tensor broke one of the invariants above."""


@dataclass
class Genomes:
    """Genome tensors with leading ``[R, P]`` axes (see the module docstring)."""

    weight: Tensor
    conn: Tensor
    enabled: Tensor
    node: Tensor
    sigma: Tensor
    mutation_num: Tensor | None = None

    @property
    def num_runs(self) -> int:
        return self.weight.shape[0]

    @property
    def pop_size(self) -> int:
        return self.weight.shape[1]

    @property
    def num_nodes(self) -> int:
        return self.weight.shape[-1]

    @property
    def device(self) -> torch.device:
        return self.weight.device

    def tensors(self) -> dict[str, Tensor]:
        """The genome tensors by field name (``mutation_num`` only where it is carried)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}

    def gather(self, index: Tensor) -> Genomes:
        """Genomes picked per run: ``index[R, K]`` -> a ``[R, K]`` population."""
        R, K = index.shape
        # Whole rows by index_select of the flattened runs (torch.gather with an index
        # expanded over every slot is several times slower on the CPU); the same copy.
        rows = (index + torch.arange(R, device=index.device).unsqueeze(1) * self.pop_size).flatten()
        return Genomes(**{name: t.flatten(0, 1).index_select(0, rows).view(R, K, *t.shape[2:])
                          for name, t in self.tensors().items()})

    def where(self, take_other: Tensor, other: Genomes) -> Genomes:
        """Per genome, ``other``'s genome where ``take_other[R, P]`` is True, else this one's."""
        out = {}
        for name, t in self.tensors().items():
            mask = take_other.view(*take_other.shape, *([1] * (t.dim() - 2)))
            out[name] = torch.where(mask, getattr(other, name), t)
        return Genomes(**out)

    def select_runs(self, runs: Tensor | list[int]) -> Genomes:
        """A copy of runs ``runs`` (indices, or an ``[R]`` bool mask)."""
        idx = run_index(runs, self.device)
        return Genomes(**{k: v.index_select(0, idx) for k, v in self.tensors().items()})

    def clone(self) -> Genomes:
        return Genomes(**{k: v.clone() for k, v in self.tensors().items()})

    def to(self, device: torch.device | str) -> Genomes:
        return Genomes(**{k: v.to(device) for k, v in self.tensors().items()})

    def effective_weight(self) -> Tensor:
        """Expressed weights ``[R, P, N, N]``: the weight where the gene is enabled, else 0."""
        return torch.where(self.enabled, self.weight, torch.zeros((), dtype=self.weight.dtype,
                                                                   device=self.weight.device))

    def fingerprint(self) -> Tensor:
        """``[R]`` int64: a hash of each run's whole population (expressed weights, genes, nodes,
        sigma), a pure function of its contents: any change to a run's genomes gives, in
        practice, another value; equal populations give equal values on any device."""
        R = self.num_runs
        words = []
        for t in (self.effective_weight(), self.conn, self.node, self.sigma):
            t = t.contiguous().reshape(R, -1)
            if t.dtype == torch.bool:
                words.append(t.to(torch.int64))
            elif t.element_size() == 4:
                words.append(t.view(torch.int32).to(torch.int64))
            else:
                words.append(t.view(torch.int64))
        w = torch.cat(words, 1)
        position = mix64(torch.arange(w.shape[1], dtype=torch.int64, device=w.device))
        return mix64(mix64(w ^ position).sum(1))  # mixed per word, then a (wrapping) sum: order-sensitive

    def num_genes(self) -> Tensor:
        """Connection genes per genome (enabled or not), ``[R, P]``."""
        return self.conn.flatten(2).sum(-1)

    def num_hidden(self, config: NEATConfig) -> Tensor:
        """Hidden nodes per genome, ``[R, P]``."""
        return self.node[..., config.first_hidden:].sum(-1)


def run_index(runs: Tensor | list[int], device: torch.device) -> Tensor:
    """``runs`` (indices, or a bool mask) as a long index tensor on ``device``, for
    ``index_select``, which copies whole rows (advanced indexing copies element by element,
    about 1.6x slower on a population)."""
    idx = torch.as_tensor(runs, device=device)
    return idx.nonzero().flatten() if idx.dtype == torch.bool else idx.to(torch.long).flatten()


def _fixed_nodes(config: NEATConfig, device: torch.device) -> Tensor:
    fixed = torch.zeros(config.num_nodes, dtype=torch.bool, device=device)
    fixed[: config.first_hidden] = True
    return fixed


def new_weights(config: NEATConfig, normal: Tensor | None, uniform: Tensor | None) -> Tensor:
    """New connection weights (a start genome's, a new link's, a replaced one's) from standard
    normal draws ``normal`` or, with ``config.weight_init_uniform``, from uniform [0, 1) draws
    ``uniform`` (float64): ``weight_init_mean + weight_init_stdev * normal``, or uniform in
    ``[max(min, mean - 2 stdev), min(max, mean + 2 stdev)]`` as neat-python draws it (computed in
    float64, then rounded to ``normal``'s dtype where given); clamped to the weight range. The
    breeding kernel (breed.c) computes the same bits."""
    if config.weight_init_uniform:
        lo = max(config.weight_min_value, config.weight_init_mean - 2.0 * config.weight_init_stdev)
        hi = min(config.weight_max_value, config.weight_init_mean + 2.0 * config.weight_init_stdev)
        weight = (lo + (hi - lo) * uniform).to(uniform.dtype if normal is None else normal.dtype)
    else:
        weight = config.weight_init_mean + config.weight_init_stdev * normal
    return weight.clamp(config.weight_min_value, config.weight_max_value)


def initial_genomes(config: NEATConfig, rng: RunRNG, *, dtype: torch.dtype = torch.float32) -> Genomes:
    """The start population: every input (and bias) wired to every output, random weights.

    With ``config.initial_self_loops`` each output also gets a self-connection
    (neat-python's "full" start for recurrent networks). With ``config.initial_hidden`` = k,
    the first k hidden slots are present in every genome, each fed by every input and bias and
    feeding every output (neat-python's ``num_hidden`` with a "full_direct" start); else no
    hidden nodes.
    """
    R, P, N = len(rng), config.pop_size, config.num_nodes
    device = rng.device
    template = torch.zeros(N, N, dtype=torch.bool, device=device)
    template[: config.first_output, config.first_output:config.first_hidden] = True
    hidden_end = config.first_hidden + config.initial_hidden
    template[: config.first_output, config.first_hidden:hidden_end] = True
    template[config.first_hidden:hidden_end, config.first_output:config.first_hidden] = True
    if config.initial_self_loops:
        outs = torch.arange(config.first_output, config.first_hidden, device=device)
        template[outs, outs] = True
    conn = template.expand(R, P, N, N).clone()
    weight = torch.where(conn, new_weights(config, *rng.randn_uniform(P, N, N, dtype=dtype)), 0.0)
    start_nodes = _fixed_nodes(config, device)
    start_nodes[config.first_hidden:hidden_end] = True
    node = start_nodes.expand(R, P, N).clone()
    sigma = config.sigma_init_mean + config.sigma_init_stdev * rng.randn(P, dtype=dtype)
    sigma = sigma.clamp(config.sigma_min_value, config.sigma_max_value)
    return Genomes(weight=weight, conn=conn, enabled=conn.clone(), node=node, sigma=sigma,
                   mutation_num=start_mutation_num(config, weight))


def start_mutation_num(config: NEATConfig, weight: Tensor) -> Tensor | None:
    """A start genome's ``mutation_num`` (with ``config.compat_mutation_num``, else None): its
    weights, as [NEATC]'s ``Population`` spawns the start population by a weight mutation."""
    return weight.clone() if config.compat_mutation_num else None


def random_genomes(config: NEATConfig, *, runs: int = 1, hidden: int = 0, density: float = 0.5, seed: int = 0,
                   device: torch.device | str = "cpu", dtype: torch.dtype = torch.float32) -> Genomes:
    """``[runs, config.pop_size]`` random genomes that hold every invariant (``check_invariants``),
    for benchmarks, tests and the curious: each has the first ``hidden`` hidden slots, and each
    possible gene between its nodes (none into inputs or bias; cycles and self-loops unless
    ``config.feed_forward``) exists with probability ``density``, enabled, with a weight drawn as
    the start population's (``new_weights``); sigma
    as the start population's. Drawn from a CPU generator seeded by ``seed``: the same genomes
    on every device."""
    for name, value, ok in (("runs", runs, isinstance(runs, int) and runs >= 1),
                            ("hidden", hidden, isinstance(hidden, int) and 0 <= hidden <= config.max_hidden),
                            ("density", density, isinstance(density, (int, float)) and 0.0 <= density <= 1.0)):
        if not ok or isinstance(value, bool):
            raise ValueError(f"random_genomes: {name} = {value!r} is not valid (runs >= 1, 0 <= hidden <= "
                             f"config.max_hidden = {config.max_hidden}, density in [0, 1])")
    R, P, N = runs, config.pop_size, config.num_nodes
    generator = torch.Generator().manual_seed(int(seed))
    node = torch.zeros(N, dtype=torch.bool)
    node[: config.first_hidden + hidden] = True
    possible = node.unsqueeze(1) & node.unsqueeze(0)
    possible[:, : config.first_output] = False  # nothing leads into an input or bias node
    if config.feed_forward:  # inputs and bias, then hidden in slot order, then outputs: a topological order
        slot = torch.arange(N)
        rank = torch.where((slot >= config.first_output) & (slot < config.first_hidden), slot + N, slot)
        possible &= rank.unsqueeze(1) < rank.unsqueeze(0)
    conn = (torch.rand(R, P, N, N, generator=generator, dtype=torch.float64) < density) & possible
    if config.weight_init_uniform:
        weight = new_weights(config, None, torch.rand(R, P, N, N, generator=generator, dtype=torch.float64))
    else:
        weight = new_weights(config, torch.randn(R, P, N, N, generator=generator, dtype=torch.float64), None)
    weight = torch.where(conn, weight, 0.0)
    sigma = config.sigma_init_mean + config.sigma_init_stdev * torch.randn(R, P, generator=generator,
                                                                             dtype=torch.float64)
    sigma = sigma.clamp(config.sigma_min_value, config.sigma_max_value)
    genomes = Genomes(weight=weight.to(dtype), conn=conn, enabled=conn.clone(), node=node.expand(R, P, N).clone(),
                      sigma=sigma.to(dtype), mutation_num=start_mutation_num(config, weight.to(dtype)))
    return genomes.to(device)


def reachability(conn: Tensor) -> Tensor:
    """Transitive closure: ``reach[..., i, j]`` is True iff a path of genes leads i -> j.

    Repeated squaring of the boolean adjacency: log2(N) batched matmuls.
    """
    n = conn.shape[-1]
    reach = conn.to(torch.float32)
    steps = max(1, (n - 1).bit_length())
    for _ in range(steps):
        reach = ((reach + reach @ reach) > 0).to(torch.float32)
    return reach > 0


def check_invariants(genomes: Genomes, config: NEATConfig) -> None:
    """Raise ``InvariantError`` naming the first broken invariant, else return None."""
    g = genomes
    N = config.num_nodes
    shapes = {"weight": (N, N), "conn": (N, N), "enabled": (N, N), "node": (N,), "sigma": ()}
    for name, tail in shapes.items():
        t = getattr(g, name)
        if tuple(t.shape[2:]) != tail or t.shape[:2] != g.weight.shape[:2]:
            raise InvariantError(f"{name} has shape {tuple(t.shape)}, expected [R, P, *{tail}]")
    if g.pop_size != config.pop_size:
        raise InvariantError(f"population has {g.pop_size} genomes, config says {config.pop_size}")
    if not bool(g.node[..., : config.first_hidden].all()):
        raise InvariantError("an input, bias or output node is missing")
    if not bool((g.conn <= (g.node.unsqueeze(-1) & g.node.unsqueeze(-2))).all()):
        raise InvariantError("a connection gene refers to a missing node")
    if not bool((g.enabled <= g.conn).all()):
        raise InvariantError("a gene is enabled but does not exist")
    if not bool(torch.isfinite(g.weight).all()) or not bool(torch.isfinite(g.sigma).all()):
        raise InvariantError("a weight or sigma is NaN or inf")
    if bool((g.weight[~g.conn] != 0).any()):
        raise InvariantError("a weight is non-zero where no gene exists")
    if (g.mutation_num is not None) != config.compat_mutation_num:
        raise InvariantError(f"mutation_num is {'carried' if g.mutation_num is not None else 'missing'} but "
                             f"config.compat_mutation_num is {config.compat_mutation_num}")
    if g.mutation_num is not None:
        if g.mutation_num.shape != g.weight.shape or g.mutation_num.dtype != g.weight.dtype:
            raise InvariantError(f"mutation_num has shape {tuple(g.mutation_num.shape)} and dtype "
                                 f"{g.mutation_num.dtype}, expected the weights' {tuple(g.weight.shape)}, {g.weight.dtype}")
        if not bool(torch.isfinite(g.mutation_num).all()) or bool((g.mutation_num[~g.conn] != 0).any()):
            raise InvariantError("a mutation_num is NaN or inf, or non-zero where no gene exists")
    if bool(((g.weight < config.weight_min_value) | (g.weight > config.weight_max_value)).any()):
        raise InvariantError("a weight lies outside [weight_min_value, weight_max_value]")
    if bool(((g.sigma < config.sigma_min_value) | (g.sigma > config.sigma_max_value)).any()):
        raise InvariantError("a sigma lies outside [sigma_min_value, sigma_max_value]")
    into_inputs = g.conn[..., : config.first_output]
    if bool(into_inputs.any()):
        raise InvariantError("a connection leads into an input or bias node")
    if config.feed_forward and bool(torch.diagonal(reachability(g.conn), dim1=-2, dim2=-1).any()):
        raise InvariantError("a feed-forward genome has a cycle")
