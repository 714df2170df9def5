"""The memory ablation's policies really are memoryless, and the evolved one is not."""

import math

import torch

from evolution.neat import NEAT
from evolution.phenotype import SpikingController
from experiments.memory_ablation import StaticMapController, WipedStateController, ablation_steps
from tasks.studies.cartpole import controller_config, nonmarkov_fitness


def _genomes():
    cfg = controller_config("snn", pop_size=12)
    neat = NEAT(cfg, seeds=[3])
    neat.run(nonmarkov_fitness("snn", cfg, max_steps=300), 3)
    return neat.ask(), cfg


def _forces(cls, genomes, cfg):
    policy = cls(genomes, cfg, period_s=0.01, action_max=10.0, observation_size=2)
    state = policy.initial_state(torch.arange(genomes.pop_size))
    a = torch.tensor([[0.5 + 0.1 / 4.8, 0.5 + math.radians(2.0) / math.radians(24.0)]]).expand(genomes.pop_size, 2)
    b = torch.tensor([[0.5 - 0.5 / 4.8, 0.5 - math.radians(4.0) / math.radians(24.0)]]).expand(genomes.pop_size, 2)
    first, state, _ = policy.act(a, state)
    _, state, _ = policy.act(b, state)
    again, _, _ = policy.act(a, state)
    return first, again


def test_ablations_are_memoryless_and_the_evolved_policy_is_not():
    g, cfg = _genomes()
    for cls in (WipedStateController, StaticMapController):
        first, again = _forces(cls, g, cfg)
        assert torch.equal(first, again), cls.__name__
    first, again = _forces(SpikingController, g, cfg)
    assert not torch.equal(first, again)


def test_ablation_steps_match_the_fitness_as_evolved():
    g, cfg = _genomes()
    out = ablation_steps(g, max_steps=300)
    assert set(out) == {"as evolved", "state wiped", "static map"}
    fitness = nonmarkov_fitness("snn", cfg, max_steps=300)(g)[0]
    assert torch.equal(out["as evolved"].double(), fitness)
    for steps in out.values():
        assert steps.shape == (g.pop_size,) and int(steps.min()) >= 0 and int(steps.max()) <= 300
