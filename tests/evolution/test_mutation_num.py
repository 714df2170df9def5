"""NEAT 1.2.1's ``Gene::mutation_num`` (``NEATConfig.compat_mutation_num``): the distance reads each
gene's weight as of its genome's last weight mutation, on the tensor and C breeding paths alike."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from evolution.checkpoint import CheckpointError
from evolution.crossover import crossover
from evolution.kernels import breed as breed_kernel
from evolution.mutate import mutate_add_connection, mutate_add_node, mutate_weights
from evolution.neat import NEAT
from evolution.neat121 import neat121_config
from evolution.population import InvariantError, check_invariants, random_genomes
from evolution.rng import RunRNG
from evolution.speciate import empty_species, speciate
from tests.evolution.helpers import assert_same_breeding, bred_on_both_paths, population, small_config

needs_kernel = pytest.mark.skipif(not breed_kernel.kernel_available(), reason="no C compiler: kernels unavailable")


def test_start_genomes_carry_their_weights_as_mutation_num_only_with_the_option():
    cfg = small_config(compat_mutation_num=True)
    g, _ = population(cfg)
    assert torch.equal(g.mutation_num, g.weight) and g.mutation_num.data_ptr() != g.weight.data_ptr()
    assert population(small_config())[0].mutation_num is None
    assert "mutation_num" not in population(small_config())[0].tensors()
    check_invariants(random_genomes(cfg, runs=2, hidden=2, seed=3), cfg)
    with pytest.raises(InvariantError, match="compat_mutation_num"):
        check_invariants(dataclasses.replace(g, mutation_num=None), cfg)
    with pytest.raises(InvariantError, match="non-zero where no gene"):
        check_invariants(dataclasses.replace(g, mutation_num=torch.ones_like(g.weight)), cfg)


def test_a_link_added_again_in_a_generation_records_0_the_first_one_its_weight():
    # The start genomes' only free slot is the output's self-loop: every genome adds it.
    cfg = small_config(pop_size=12, max_hidden=0, conn_add_prob=1.0, compat_mutation_num=True)
    g, _ = population(cfg, seeds=(0, 1))
    loop = (cfg.first_output, cfg.first_output)
    out = mutate_add_connection(g, cfg, RunRNG([4, 5]), torch.ones(2, cfg.pop_size, dtype=torch.bool))
    added = out.weight[..., loop[0], loop[1]]
    mnum = out.mutation_num[..., loop[0], loop[1]]
    assert bool((added != 0).all())
    assert torch.equal(mnum[:, 0], added[:, 0])  # each run's first child: its new weight
    assert bool((mnum[:, 1:] == 0).all())  # the rest: 0, whatever their weight
    old = g.conn
    assert torch.equal(out.mutation_num[old], g.mutation_num[old])  # the other genes keep theirs


def test_a_new_nodes_genes_record_0():
    cfg = small_config(pop_size=8, node_add_prob=1.0, compat_mutation_num=True)
    g, rng = population(cfg, seeds=(2,))
    out, refused = mutate_add_node(g, cfg, rng, torch.ones(1, cfg.pop_size, dtype=torch.bool))
    new = out.conn & ~g.conn
    assert int(new.sum()) == 2 * int((~refused).sum()) > 0
    assert bool((out.mutation_num[new] == 0).all())
    assert bool((out.weight[new] != 0).any())  # the in-link's weight is 1: mutation_num is not the weight
    assert torch.equal(out.mutation_num[g.conn], g.mutation_num[g.conn])


@pytest.mark.parametrize("rule", ["neatc", "per_gene", "neat02"])
def test_a_weight_mutation_records_every_gene_of_the_genomes_it_mutates(rule):
    cfg = small_config(pop_size=30, weight_mutate_rate=0.5, compat_mutation_num=True,
                       weight_mutate_neatc=rule == "neatc", weight_mutate_per_gene=rule == "per_gene")
    g = random_genomes(cfg, runs=2, hidden=2, density=0.6, seed=5)
    g = dataclasses.replace(g, mutation_num=torch.where(g.conn, torch.full_like(g.weight, 0.25), 0.0))
    active = torch.ones(2, cfg.pop_size, dtype=torch.bool)
    active[:, :5] = False
    out = mutate_weights(g, cfg, RunRNG([7, 8]), active)
    changed = (out.weight != g.weight).flatten(2).any(-1)
    recorded = (out.mutation_num == out.weight).flatten(2).all(-1)
    untouched = torch.equal  # noqa: E731
    assert bool(changed.any()) and bool(recorded[changed].all())  # a genome whose weights changed records all
    assert untouched(out.mutation_num[~active], g.mutation_num[~active])  # elites keep theirs
    if rule == "per_gene":  # every active genome passes through the per-gene rule
        assert bool(recorded[active].all())
    else:  # weight_mutate_rate 0.5: the active genomes that drew no weight mutation keep theirs
        kept = active & ~recorded
        assert bool(kept.any()) and not bool(changed[kept].any())
        assert untouched(out.mutation_num[kept], g.mutation_num[kept])


def test_crossover_inherits_mutation_num_as_it_inherits_weights():
    cfg = small_config(pop_size=20, compat_mutation_num=True)
    a = random_genomes(cfg, runs=1, hidden=2, density=0.7, seed=1)
    b = random_genomes(cfg, runs=1, hidden=2, density=0.7, seed=2)
    a = dataclasses.replace(a, mutation_num=a.weight * 3)  # told apart from the weights
    b = dataclasses.replace(b, mutation_num=b.weight * 3)
    active = torch.ones(1, cfg.pop_size, dtype=torch.bool)
    average = torch.arange(cfg.pop_size).unsqueeze(0) % 2 == 0
    child = crossover(a, b, cfg, RunRNG([3]), active, average)
    assert torch.allclose(child.mutation_num, child.weight * 3)  # the same choice and the same mean
    matching = a.conn & b.conn
    even = matching[:, ::2]
    assert torch.allclose(child.mutation_num[:, ::2][even], ((a.mutation_num + b.mutation_num) / 2)[:, ::2][even])


@pytest.mark.parametrize("fused", [False, pytest.param(True, marks=needs_kernel)])
def test_the_distance_reads_mutation_num(fused):
    # Two genomes alike but for their mutation_num: one species when the distance reads the
    # weights, two when it reads mutation_num ([NEATC]).
    cfg = small_config(pop_size=2, compatibility_weight_coefficient=3.0, compatibility_threshold=1.0)
    g, rng = population(cfg, seeds=(0,))
    g = g.gather(torch.zeros(1, 2, dtype=torch.long))  # two copies of genome 0
    mnum = g.weight.clone()
    mnum[0, 1] = torch.where(g.conn[0, 1], mnum[0, 1] + 2.0, 0.0)
    species = {}
    for on in (False, True):
        c = dataclasses.replace(cfg, compat_mutation_num=on)
        genomes = dataclasses.replace(g, mutation_num=mnum if on else None)
        sp = empty_species(1, c.num_nodes, 2, device=g.device, dtype=g.weight.dtype)
        species[on], sp = speciate(genomes, sp, c, RunRNG([0]), 0, fused=fused)
        if on:  # the representatives hold what the distance reads
            rep = int(species[on][0, 0])
            assert torch.equal(sp.rep_weight[0, rep], mnum[0, 0])
    assert species[False][0, 0] == species[False][0, 1]
    assert species[True][0, 0] != species[True][0, 1]


def _tells(P: int, generations: int, seed: int = 0, runs: int = 2) -> list[tuple]:
    g = torch.Generator().manual_seed(seed)
    return [(torch.rand(runs, P, generator=g, dtype=torch.float64) * 4,) for _ in range(generations)]


@needs_kernel
@pytest.mark.parametrize("preset", ["dpv", "dpnv"])
def test_the_c_breeding_path_breeds_mutation_num_as_the_tensor_path(preset):
    # NEAT 1.2.1's presets with mutation_num, new links and nodes often (many later links, many
    # new nodes' genes at 0): both paths breed the same genomes, mutation_num included, and the
    # same species (the kernel's closest representatives go by mutation_num).
    cfg = neat121_config(preset, num_inputs=3, num_outputs=1, num_bias=1, max_hidden=6, pop_size=60,
                         compat_mutation_num=True, conn_add_prob=0.6, node_add_prob=0.2)
    tells = _tells(cfg.pop_size, 8, runs=3)
    solved = torch.zeros(3, cfg.pop_size, dtype=torch.bool)
    solved[1, 0] = True  # run 1 freezes at generation 3: later steps breed the others in place
    tells[3] = (tells[3][0], solved)
    ref, fast = bred_on_both_paths(cfg, [3, 4, 5], tells)
    assert ref.solved_generation.tolist() == [-1, 4, -1]
    assert_same_breeding(ref, fast)
    g = ref.genomes
    later = g.conn & (g.mutation_num == 0) & (g.weight != 0)
    assert int(later.sum()) > 0  # the mechanism acted
    assert not torch.equal(g.mutation_num, g.weight)
    check_invariants(g, cfg)


def test_a_checkpoint_keeps_mutation_num(tmp_path):
    cfg = small_config(pop_size=16, conn_add_prob=0.5, node_add_prob=0.2, compat_mutation_num=True)
    neat = NEAT(cfg, seeds=[1, 2])
    tells = _tells(cfg.pop_size, 4, seed=1)
    for args in tells[:2]:
        neat.tell(*args)
    path = neat.save_checkpoint(tmp_path / "run.ckpt")
    resumed = NEAT.restore(path)
    assert torch.equal(resumed.genomes.mutation_num, neat.genomes.mutation_num)
    for args in tells[2:]:
        neat.tell(*args)
        resumed.tell(*args)
    assert_same_breeding(neat, resumed)
    # a state whose config asks for mutation_num but whose genomes lack it is refused, by name
    state = neat.state_dict()
    del state["genomes"]["mutation_num"]
    with pytest.raises(CheckpointError, match="genomes.mutation_num"):
        NEAT.from_state_dict(state)
