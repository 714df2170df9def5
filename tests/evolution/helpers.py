"""Small populations and a slow, obviously-correct reference for the tests."""

from __future__ import annotations

import torch

from evolution.config import NEATConfig
from evolution.population import Genomes, initial_genomes
from evolution.rng import RunRNG


def small_config(**kw) -> NEATConfig:
    base = dict(num_inputs=2, num_outputs=1, num_bias=1, max_hidden=4, pop_size=6)
    base.update(kw)
    return NEATConfig(**base)


def population(cfg: NEATConfig, seeds=(0, 1)) -> tuple[Genomes, RunRNG]:
    rng = RunRNG(list(seeds))
    return initial_genomes(cfg, rng), rng


def bred_on_both_paths(cfg: NEATConfig, seeds: list[int], tells: list[tuple], **neat_kw):
    """Two NEATs of ``cfg`` told the same ``tells`` (``NEAT.tell`` arguments, one tuple per
    generation): ``(tensor path, C breeding path)``."""
    from evolution.neat import NEAT

    runs = []
    for fused in (False, True):
        neat = NEAT(cfg, seeds=seeds, **neat_kw)
        neat.fused_breeding = fused
        for args in tells:
            neat.tell(*args)
        runs.append(neat)
    return runs[0], runs[1]


def assert_same_breeding(ref, fast) -> None:
    """The two paths bred the same genomes, species and species records, bit for bit."""
    for name, t in ref.genomes.tensors().items():
        assert torch.equal(t, getattr(fast.genomes, name)), name
    assert torch.equal(ref.species, fast.species)
    for name, t in ref.species_state.tensors().items():
        assert torch.equal(t, getattr(fast.species_state, name)), name


def genome_genes(g: Genomes, r: int, p: int) -> dict[tuple[int, int], tuple[float, bool]]:
    """{(i, j): (weight, enabled)} of one genome: the list form NEAT papers use."""
    out = {}
    for i, j in torch.nonzero(g.conn[r, p]).tolist():
        out[(i, j)] = (g.weight[r, p, i, j].item(), bool(g.enabled[r, p, i, j]))
    return out


def reference_distance(a: dict, b: dict, sigma_a: float, sigma_b: float, cfg: NEATConfig, n: int) -> float:
    """Compatibility distance by gene lists, written from the definition."""
    keys_a, keys_b = set(a), set(b)
    flat = lambda k: k[0] * n + k[1]  # noqa: E731
    top_a = max((flat(k) for k in keys_a), default=-1)
    top_b = max((flat(k) for k in keys_b), default=-1)
    excess = sum(1 for k in keys_a - keys_b if flat(k) > top_b) + sum(1 for k in keys_b - keys_a if flat(k) > top_a)
    disjoint = len(keys_a ^ keys_b) - excess
    match = keys_a & keys_b
    w = sum(abs(a[k][0] - b[k][0]) for k in match) / len(match) if match else 0.0
    big = max(len(keys_a), len(keys_b))
    norm = big if big >= cfg.compatibility_normalize_min_genes else 1
    return (cfg.compatibility_excess_coefficient * excess / norm + cfg.compatibility_disjoint_coefficient * disjoint / norm
            + cfg.compatibility_weight_coefficient * w + cfg.compatibility_sigma_coefficient * abs(sigma_a - sigma_b))
