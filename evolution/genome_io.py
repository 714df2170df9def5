"""One genome on disk (versioned JSON) and as a networkx graph.

File format ``snn-neat-genome`` version 1 (JSON, human-readable)::

    {"format": "snn-neat-genome", "version": 1,
     "layout": {"num_inputs": 2, "num_bias": 1, "num_outputs": 1, "num_nodes": 36},
     "nodes": [{"id": 0, "kind": "input"}, ..., {"id": 7, "kind": "hidden"}],
     "connections": [{"from": 0, "to": 3, "weight": 0.52, "enabled": true}, ...],
     "sigma": 1.0, "fitness": 12.5}

Node ids are the slots of the shared node index (their historical markings).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import networkx as nx
import torch

from evolution.checkpoint import CheckpointError, atomic_write_bytes
from evolution.config import NEATConfig
from evolution.population import Genomes, InvariantError, check_invariants, start_mutation_num

__all__ = ["GENOME_FORMAT", "GENOME_VERSION", "genome_to_dict", "genome_from_dict", "save_genome", "load_genome",
           "to_networkx", "node_kind"]

GENOME_FORMAT = "snn-neat-genome"
GENOME_VERSION = 1


def node_kind(config: NEATConfig, slot: int) -> str:
    if slot < config.num_inputs:
        return "input"
    if slot < config.first_output:
        return "bias"
    if slot < config.first_hidden:
        return "output"
    return "hidden"


def genome_to_dict(genomes: Genomes, config: NEATConfig, run: int = 0, index: int = 0,
                   fitness: float | None = None) -> dict:
    """Genome ``[run, index]`` of ``genomes`` as a plain dict in the file format."""
    node = genomes.node[run, index].cpu()
    conn = genomes.conn[run, index].cpu()
    weight = genomes.weight[run, index].double().cpu()
    enabled = genomes.enabled[run, index].cpu()
    return {
        "format": GENOME_FORMAT,
        "version": GENOME_VERSION,
        "layout": {"num_inputs": config.num_inputs, "num_bias": config.num_bias,
                   "num_outputs": config.num_outputs, "num_nodes": config.num_nodes,
                   **({"bias_value": config.bias_value} if config.bias_value != 1.0 else {})},
        "nodes": [{"id": i, "kind": node_kind(config, i)} for i in torch.nonzero(node).flatten().tolist()],
        "connections": [{"from": i, "to": j, "weight": weight[i, j].item(), "enabled": bool(enabled[i, j])}
                        for i, j in torch.nonzero(conn).tolist()],
        "sigma": genomes.sigma[run, index].item(),
        "fitness": None if fitness is None else float(fitness),
    }


def _fail(where: str, what: str) -> CheckpointError:
    return CheckpointError(f"genome file {where}: {what}")


def genome_from_dict(data: dict, config: NEATConfig, *, where: str = "<dict>",
                     dtype: torch.dtype = torch.float32) -> Genomes:
    """A ``[1, 1]`` population holding the genome in ``data``, placed in ``config``'s index.

    Everything is checked against ``config`` (layout, node kinds, weight and sigma limits, the
    population invariants): a ``CheckpointError`` names ``where`` and the field at fault."""
    if not isinstance(data, dict) or data.get("format") != GENOME_FORMAT:
        raise _fail(where, f"not an {GENOME_FORMAT} file")
    if data.get("version") != GENOME_VERSION:
        raise _fail(where, f"version {_short(data.get('version'))} is not supported (this snn-neat reads {GENOME_VERSION})")
    layout = data.get("layout")
    want = {"num_inputs": config.num_inputs, "num_bias": config.num_bias, "num_outputs": config.num_outputs,
            "num_nodes": config.num_nodes}
    if not isinstance(layout, dict) or any(type(layout.get(k)) is not int or layout.get(k) != v
                                           for k, v in want.items()):
        raise _fail(where, f"layout {_short(layout)} does not match the config's {want}")
    bias_value = layout.get("bias_value", 1.0)  # written only where it is not 1
    if bias_value != config.bias_value:
        raise _fail(where, f"layout bias_value {_short(bias_value)} does not match the config's "
                           f"{config.bias_value} (the network would act differently)")
    N = config.num_nodes
    node = torch.zeros(N, dtype=torch.bool)
    node[: config.first_hidden] = True
    seen: set[int] = set()
    for entry in _list(data, "nodes", where):
        i = _slot(entry, "id", where, N)
        if i in seen:
            raise _fail(where, f"node {i} appears twice in 'nodes'")
        seen.add(i)
        if entry.get("kind") != node_kind(config, i):
            raise _fail(where, f"node {i} has kind {_short(entry.get('kind'))}; in this layout it is "
                               f"{node_kind(config, i)!r}")
        node[i] = True
    conn = torch.zeros(N, N, dtype=torch.bool)
    enabled = torch.zeros(N, N, dtype=torch.bool)
    weight = torch.zeros(N, N, dtype=dtype)
    lo, hi = config.weight_min_value, config.weight_max_value
    for entry in _list(data, "connections", where):
        i, j = _slot(entry, "from", where, N), _slot(entry, "to", where, N)
        w = _number(entry.get("weight"), where, f"connection {i}->{j} weight")
        if not lo <= w <= hi:
            raise _fail(where, f"connection {i}->{j} weight {w!r} lies outside the config's [{lo}, {hi}] "
                               "(weight_min_value, weight_max_value)")
        if not isinstance(entry.get("enabled"), bool):
            raise _fail(where, f"connection {i}->{j} has enabled={_short(entry.get('enabled'))}; expected true/false")
        if not (node[i] and node[j]):
            raise _fail(where, f"connection {i}->{j} refers to a node missing from 'nodes'")
        if conn[i, j]:
            raise _fail(where, f"connection {i}->{j} appears twice")
        if j < config.first_output:
            raise _fail(where, f"connection {i}->{j} leads into an input or bias node")
        conn[i, j], enabled[i, j], weight[i, j] = True, entry["enabled"], w
    sigma = _number(data.get("sigma"), where, "sigma")
    # a float32 genome clamped to a bound holds the bound rounded to float32, which may lie just outside it
    lo, hi = config.sigma_min_value, config.sigma_max_value
    lo32, hi32 = (float(torch.tensor(v, dtype=torch.float32)) for v in (lo, hi))
    if not min(lo, lo32) <= sigma <= max(hi, hi32):
        raise _fail(where, f"sigma {sigma!r} lies outside the config's [{config.sigma_min_value}, "
                           f"{config.sigma_max_value}] (sigma_min_value, sigma_max_value)")
    fitness = data.get("fitness")
    if fitness is not None:
        _number(fitness, where, "fitness")
    # the file holds no mutation_num ([NEATC]'s bookkeeping for the distance): a loaded genome's is its weights
    g = Genomes(weight=weight[None, None], conn=conn[None, None], enabled=enabled[None, None],
                node=node[None, None], sigma=torch.tensor([[sigma]], dtype=dtype),
                mutation_num=start_mutation_num(config, weight[None, None]))
    try:  # what the kernels and distances rely on (a feed-forward config's genome has no cycle, ...)
        check_invariants(Genomes(**{k: v.expand(1, config.pop_size, *v.shape[2:]) for k, v in g.tensors().items()}),
                         config)
    except InvariantError as exc:
        raise _fail(where, f"the genome breaks an invariant of this config: {exc}") from None
    return g


def _short(value: object, limit: int = 80) -> str:
    """``repr(value)``, cut to ``limit`` characters (a 400-digit number or a huge list stays readable)."""
    try:
        text = repr(value)
    except ValueError:  # an int too long for repr (sys.set_int_max_str_digits)
        text = f"<{type(value).__name__} too long to print>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _number(value: object, where: str, what: str) -> float:
    """``value`` as a finite float (a JSON number), else ``CheckpointError`` naming ``what``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _fail(where, f"{what} is {_short(value)}; expected a finite number")
    try:
        x = float(value)
    except OverflowError:  # an integer beyond float range
        x = math.inf
    if not math.isfinite(x):
        raise _fail(where, f"{what} is {_short(value)}; expected a finite number")
    return x


def _list(data: dict, key: str, where: str) -> list:
    value = data.get(key)
    if not isinstance(value, list) or not all(isinstance(e, dict) for e in value):
        raise _fail(where, f"'{key}' must be a list of objects")
    return value


def _slot(entry: dict, key: str, where: str, n: int) -> int:
    value = entry.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < n:
        raise _fail(where, f"'{key}' is {_short(value)}; expected a node id in [0, {n})")
    return value


def save_genome(path: str | os.PathLike, genomes: Genomes, config: NEATConfig, run: int = 0, index: int = 0,
                fitness: float | None = None) -> Path:
    """Write one genome as JSON, atomically."""
    text = json.dumps(genome_to_dict(genomes, config, run, index, fitness), indent=1)
    return atomic_write_bytes(path, text.encode())


def load_genome(path: str | os.PathLike, config: NEATConfig, *, dtype: torch.dtype = torch.float32) -> Genomes:
    """Read a genome file into a ``[1, 1]`` population; ``CheckpointError`` names the file and the fault."""
    name = os.fspath(path)
    try:
        with open(name, encoding="utf-8") as fh:
            data = json.load(fh)
    except FileNotFoundError:
        raise _fail(repr(name), "does not exist") from None
    except (OSError, ValueError, RecursionError) as exc:  # ValueError: bad JSON, UTF-8, or a 5000-digit int
        raise _fail(repr(name), f"is not valid JSON ({_short(str(exc), 200)})") from exc
    return genome_from_dict(data, config, where=repr(name), dtype=dtype)


def to_networkx(genomes: Genomes, config: NEATConfig, run: int = 0, index: int = 0) -> nx.DiGraph:
    """The genome as a ``networkx.DiGraph``: node attribute ``kind``; edge attributes
    ``weight`` and ``enabled``. Self-connections are self-loops."""
    d = genome_to_dict(genomes, config, run, index)
    graph = nx.DiGraph(sigma=d["sigma"])
    for n in d["nodes"]:
        graph.add_node(n["id"], kind=n["kind"])
    for c in d["connections"]:
        graph.add_edge(c["from"], c["to"], weight=c["weight"], enabled=c["enabled"])
    return graph
