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
from evolution.population import Genomes

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
                   "num_outputs": config.num_outputs, "num_nodes": config.num_nodes},
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
    """A ``[1, 1]`` population holding the genome in ``data``, placed in ``config``'s index."""
    if not isinstance(data, dict) or data.get("format") != GENOME_FORMAT:
        raise _fail(where, f"not an {GENOME_FORMAT} file")
    if data.get("version") != GENOME_VERSION:
        raise _fail(where, f"version {data.get('version')!r} is not supported (this snn-neat reads {GENOME_VERSION})")
    layout = data.get("layout")
    want = {"num_inputs": config.num_inputs, "num_bias": config.num_bias, "num_outputs": config.num_outputs}
    if not isinstance(layout, dict) or any(layout.get(k) != v for k, v in want.items()):
        raise _fail(where, f"layout {layout!r} does not match the config's {want}")
    N = config.num_nodes
    node = torch.zeros(N, dtype=torch.bool)
    node[: config.first_hidden] = True
    for entry in _list(data, "nodes", where):
        i = _slot(entry, "id", where, N)
        node[i] = True
    conn = torch.zeros(N, N, dtype=torch.bool)
    enabled = torch.zeros(N, N, dtype=torch.bool)
    weight = torch.zeros(N, N, dtype=dtype)
    for entry in _list(data, "connections", where):
        i, j = _slot(entry, "from", where, N), _slot(entry, "to", where, N)
        w = entry.get("weight")
        if isinstance(w, bool) or not isinstance(w, (int, float)) or not math.isfinite(w):
            raise _fail(where, f"connection {i}->{j} has weight {w!r}; expected a finite number")
        if not isinstance(entry.get("enabled"), bool):
            raise _fail(where, f"connection {i}->{j} has enabled={entry.get('enabled')!r}; expected true/false")
        if not (node[i] and node[j]):
            raise _fail(where, f"connection {i}->{j} refers to a node missing from 'nodes'")
        if conn[i, j]:
            raise _fail(where, f"connection {i}->{j} appears twice")
        if j < config.first_output:
            raise _fail(where, f"connection {i}->{j} leads into an input or bias node")
        conn[i, j], enabled[i, j], weight[i, j] = True, entry["enabled"], float(w)
    sigma = data.get("sigma")
    if isinstance(sigma, bool) or not isinstance(sigma, (int, float)) or not math.isfinite(sigma):
        raise _fail(where, f"sigma is {sigma!r}; expected a finite number")
    return Genomes(weight=weight[None, None], conn=conn[None, None], enabled=enabled[None, None],
                   node=node[None, None], sigma=torch.tensor([[float(sigma)]], dtype=dtype))


def _list(data: dict, key: str, where: str) -> list:
    value = data.get(key)
    if not isinstance(value, list) or not all(isinstance(e, dict) for e in value):
        raise _fail(where, f"'{key}' must be a list of objects")
    return value


def _slot(entry: dict, key: str, where: str, n: int) -> int:
    value = entry.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < n:
        raise _fail(where, f"'{key}' is {value!r}; expected a node id in [0, {n})")
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
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise _fail(repr(name), f"is not valid JSON ({exc})") from exc
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
