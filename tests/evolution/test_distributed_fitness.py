"""RayFitness: a population evaluated in shards on a local Ray equals the local evaluation."""

from __future__ import annotations

import pytest
import torch

ray = pytest.importorskip("ray")

from evolution import NEAT  # noqa: E402
from evolution.distributed import RayFitness, split_genomes  # noqa: E402
from tasks.studies.cartpole import controller_config, markov_config, markov_fitness, nonmarkov_fitness  # noqa: E402


@pytest.fixture(scope="module")
def local_ray():
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)  # a fresh local Ray
    yield
    ray.shutdown()


def _evolved(config, fitness, seeds=(0, 1, 2), generations=3):
    """A population with some structure: a few generations of real evolution."""
    neat = NEAT(config, seeds=list(seeds))
    for _ in range(generations):
        neat.tell(fitness(neat.ask()))
    return neat.ask()


def test_split_genomes_covers_the_population_in_order():
    cfg = controller_config("sigmoid", pop_size=10)
    g = NEAT(cfg, seeds=[0, 1]).ask()
    parts = split_genomes(g, 3)
    assert [p.pop_size for p in parts] == [4, 3, 3]
    for name, t in g.tensors().items():
        assert torch.equal(torch.cat([getattr(p, name) for p in parts], dim=1), t)
    assert len(split_genomes(g, 50)) == 10
    with pytest.raises(ValueError, match="shards"):
        split_genomes(g, 0)


@pytest.mark.parametrize("task", ["table2-snn", "table1-snn", "table2-sigmoid"])
def test_sharded_evaluation_equals_local(local_ray, task):
    table, controller = task.split("-")
    if table == "table1":
        cfg = markov_config(controller, pop_size=24)
        fitness = markov_fitness(controller, cfg, max_steps=300)
    else:
        cfg = controller_config(controller, pop_size=24)
        fitness = nonmarkov_fitness(controller, cfg, max_steps=300)
    genomes = _evolved(cfg, fitness)
    local = fitness(genomes)
    remote = RayFitness(fitness, shards=5)(genomes)
    assert remote.shape == local.shape == (3, 24)
    assert torch.equal(remote, local)
    assert local.std() > 0  # the comparison is not between constant tensors


def test_neat_run_on_ray_equals_local(local_ray):
    cfg = controller_config("sigmoid", pop_size=30)
    fitness = nonmarkov_fitness("sigmoid", cfg, max_steps=500)
    local = NEAT(cfg, seeds=[3, 4]).run(fitness, generations=4)
    remote = NEAT(cfg, seeds=[3, 4]).run(RayFitness(fitness, shards=3), generations=4)
    assert torch.equal(local.best_fitness, remote.best_fitness)
    for name, t in local.best_genomes.tensors().items():
        assert torch.equal(t, getattr(remote.best_genomes, name)), name


def test_bad_fitness_shape_and_bad_shards_are_clear_errors(local_ray):
    cfg = controller_config("sigmoid", pop_size=8)
    g = NEAT(cfg, seeds=[0]).ask()
    with pytest.raises(ValueError, match=r"returned \(1,\) for a shard"):
        RayFitness(lambda genomes: torch.zeros(1), shards=2)(g)
    with pytest.raises(ValueError, match="shards must be >= 1"):
        RayFitness(lambda genomes: torch.zeros(1), shards=0)


def test_needs_ray_init():
    if ray.is_initialized():
        ray.shutdown()
    with pytest.raises(RuntimeError, match="ray.init"):
        RayFitness(lambda genomes: genomes.sigma, shards=2)
