"""NEAT 1.2.1's choice of the gene to split (``NEATConfig.node_add_neatc``): never a gene from a bias
node, the first good one of 20 random tries, in small genomes and large alike (NEAT 1.2.1's walk over
a small genome's genes is dead code there); the same on both breeding paths."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from evolution.kernels import breed as breed_kernel
from evolution.mutate import SPLIT_TRIES, _pick_split_neatc, mutate_add_node
from evolution.population import random_genomes
from evolution.reproduce import reproduce
from evolution.rng import RunRNG
from evolution.speciate import empty_species, speciate
from tests.evolution.helpers import population, small_config

needs_kernel = pytest.mark.skipif(not breed_kernel.kernel_available(), reason="no C compiler: kernels unavailable")
N, FIRST_BIAS, FIRST_OUTPUT = 6, 3, 4  # inputs 0-2, bias 3, output 4, hidden 5


def _genome(genes: list[tuple[int, int]], disabled: tuple[tuple[int, int], ...] = ()) -> tuple[torch.Tensor, torch.Tensor]:
    conn = torch.zeros(1, N, N, dtype=torch.bool)
    for i, j in genes:
        conn[0, i, j] = True
    enabled = conn.clone()
    for i, j in disabled:
        enabled[0, i, j] = False
    return conn, enabled


def _split(conn, enabled, u: float):
    i, j, ok = _pick_split_neatc(conn, enabled, torch.tensor([u], dtype=torch.float64), FIRST_BIAS, FIRST_OUTPUT)
    return (int(i), int(j)) if bool(ok) else None


def test_a_small_genome_never_splits_a_bias_gene_and_draws_its_genes_uniformly():
    # The DPNV start genome: three inputs and the bias to the output. Three of four genes can be split:
    # 20 tries all fail with (1/4)^20 (never, here); each of the three a third of the time, the bias never.
    conn, enabled = _genome([(0, 4), (1, 4), (2, 4), (3, 4)])
    u = (torch.arange(30_000, dtype=torch.float64) + 0.5) / 30_000
    i, j, ok = _pick_split_neatc(conn.expand(len(u), N, N), enabled.expand(len(u), N, N), u, FIRST_BIAS, FIRST_OUTPUT)
    assert bool(ok.all()) and bool((j == 4).all())
    assert [float((i == k).double().mean()) for k in range(4)] == pytest.approx([1 / 3, 1 / 3, 1 / 3, 0.0], abs=1e-4)
    # a disabled gene is never split either: the two enabled non-bias genes share the draws
    conn, enabled = _genome([(3, 4), (0, 4), (1, 4), (2, 4)], disabled=((1, 4),))
    i, j, ok = _pick_split_neatc(conn.expand(len(u), N, N), enabled.expand(len(u), N, N), u, FIRST_BIAS, FIRST_OUTPUT)
    fail = (1 - 2 / 4) ** SPLIT_TRIES
    assert float((~ok).double().mean()) == pytest.approx(fail, abs=1e-4)
    assert [float(((i == k) & ok).double().mean()) for k in range(4)] == pytest.approx([0.5, 0.0, 0.5, 0.0], abs=1e-4)
    conn, enabled = _genome([(3, 4)])
    assert _split(conn, enabled, 0.95) is None  # only a bias gene


def test_a_large_genome_takes_the_first_good_gene_of_20_random_tries():
    big = 8  # inputs 0-2, bias 3, output 4, hidden 5-7
    conn = torch.zeros(1, big, big, dtype=torch.bool)
    conn[0, :, FIRST_OUTPUT:] = True  # 32 genes, 4 of them from the bias node
    enabled = conn.clone()
    enabled[0, :3, :] = False  # the inputs' 12 genes disabled: 16 of the 32 can be split
    n, m = int(conn.sum()), 16
    fail = (1 - m / n) ** SPLIT_TRIES
    u = (torch.arange(200_000, dtype=torch.float64) + 0.5) / 200_000
    i, j, ok = _pick_split_neatc(conn.expand(len(u), big, big), enabled.expand(len(u), big, big), u, FIRST_BIAS,
                                 FIRST_OUTPUT)
    assert float((~ok).double().mean()) == pytest.approx(fail, abs=1e-4)
    chosen = torch.stack([i[ok], j[ok]], 1)
    assert bool((chosen[:, 0] != FIRST_BIAS).all())  # never from the bias node
    assert bool(enabled[0, chosen[:, 0], chosen[:, 1]].all())  # only enabled genes
    counts = torch.unique(chosen, dim=0, return_counts=True)[1].double()
    assert len(counts) == m and float(counts.max() / counts.min()) == pytest.approx(1.0, abs=0.01)  # uniformly


def test_the_option_changes_which_genes_split():
    cfg = small_config(pop_size=400, node_add_prob=1.0)  # inputs 0-1, bias 2, output 3
    g, rng = population(cfg, seeds=(5,))
    everyone = torch.ones(1, cfg.pop_size, dtype=torch.bool)
    split_from = {}
    for on in (False, True):
        c = dataclasses.replace(cfg, node_add_neatc=on)
        out, _ = mutate_add_node(g, c, RunRNG([5]), everyone)
        disabled = g.enabled & ~out.enabled  # the split genes
        split_from[on] = disabled[0].sum(0)[:, cfg.first_output]  # splits per source node
    assert int(split_from[False][cfg.num_inputs]) > 50  # uniformly: about a third from the bias
    assert int(split_from[True][cfg.num_inputs]) == 0
    assert sum(int(split_from[True][k]) for k in range(cfg.num_inputs)) == int(split_from[False].sum())


def _bred_alike_on_both_paths(g, cfg, seeds: list[int], *, one_species: bool):
    """One generation bred from ``g`` (two runs) on the tensor and the C path; asserts they are equal and
    returns the children and the refused splits. ``one_species``: every genome in species 0, else speciated."""
    out = []
    for fused in (False, True):
        rng = RunRNG(seeds)
        sp = empty_species(2, cfg.num_nodes, 2, device=g.device, dtype=g.weight.dtype)
        if one_species:
            species = torch.zeros(2, cfg.pop_size, dtype=torch.long)
            sp.alive[:, 0] = True
        else:
            species, sp = speciate(g, sp, cfg, rng, 0, fused=fused)
        fitness = rng.rand(cfg.pop_size, dtype=torch.float64)
        children, _, _, info = reproduce(g, fitness, species, sp, cfg, rng, 0, fused=fused)
        out.append((children, info.split_refused))
    (a, ra), (b, rb) = out
    for name, t in a.tensors().items():
        assert torch.equal(t, getattr(b, name)), name
    assert torch.equal(ra, rb)
    return a, ra


@needs_kernel
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_c_breeding_path_splits_as_the_tensor_path_in_small_and_large_genomes(seed):
    # Dense random genomes (many with 15 or more genes, some with fewer) and every child splitting.
    cfg = small_config(pop_size=40, max_hidden=4, node_add_prob=1.0, conn_add_prob=0.3, node_add_neatc=True,
                       enabled_mutate_rate=0.2)
    g = random_genomes(cfg, runs=2, hidden=3, density=0.5, seed=seed)
    genes = g.num_genes()
    assert bool((genes >= 15).any()) and bool((genes < 15).any())
    a, ra = _bred_alike_on_both_paths(g, cfg, [seed, seed + 7], one_species=False)
    assert bool((a.node[..., cfg.first_hidden:].sum(-1) > g.node[..., cfg.first_hidden:].sum(-1).max()).any() |
                (ra > 0).any())  # splits happened (or were refused for want of a slot)


@needs_kernel
def test_the_c_breeding_path_draws_the_20_tries_as_the_tensor_path():
    # Large genomes with few genes that can be split: 20 tries often all fail, so the law of the
    # failure, (1 - m / n)^20, decides many children.
    cfg = small_config(pop_size=400, max_hidden=30, node_add_prob=1.0, conn_add_prob=0.0, node_add_neatc=True,
                       crossover_prob=0.0, elitism=0)
    g = random_genomes(cfg, runs=2, hidden=4, density=1.0, seed=9)
    keep = torch.rand(g.enabled.shape, generator=torch.Generator().manual_seed(9)) < 0.12
    g = dataclasses.replace(g, enabled=g.conn & keep)
    assert bool((g.num_genes() >= 15).all())
    a, ra = _bred_alike_on_both_paths(g, cfg, [11, 12], one_species=True)
    splits = int((a.node.sum(-1) > 4 + cfg.first_hidden).sum() + ra.sum())
    assert 0.2 * 2 * cfg.pop_size < splits < 0.9 * 2 * cfg.pop_size  # some children split, others drew 20 failing tries
