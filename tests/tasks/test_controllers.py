import math

import pytest
import torch

from evolution import NEAT, NEATConfig
from tasks.cartpole import CartPoleParams, PlantError
from tasks.controllers import SigmoidPolicy, SigmoidSpec, SpikingPolicy, SpikingSpec, closed_loop

PLANT = CartPoleParams()
SNN_CFG = NEATConfig(num_inputs=2, num_outputs=1, num_bias=0, max_hidden=6, pop_size=12, sigma_init_mean=0.05,
                     sigma_min_value=1e-4, sigma_max_value=1.0, node_add_prob=0.5, conn_add_prob=0.5)
SIG_CFG = NEATConfig(num_inputs=2, num_outputs=1, num_bias=1, max_hidden=6, pop_size=12, node_add_prob=0.5,
                     conn_add_prob=0.5)


def _population(cfg):
    neat = NEAT(cfg, seeds=[0, 1])
    neat.run(lambda g: g.num_genes().double(), 3)  # grow some structure
    return neat.genomes


def _start(B):
    s = torch.zeros(B, 4)
    s[:, 2] = math.radians(3)
    return s


def _policy(kind, g, cfg):
    if kind == "snn":
        return SpikingPolicy(g, cfg, SpikingSpec(), 0.01, PLANT)
    return SigmoidPolicy(g, cfg, SigmoidSpec(), PLANT)


@pytest.mark.parametrize("kind, cfg", [("snn", SNN_CFG), ("sigmoid", SIG_CFG)])
def test_batched_evaluation_equals_each_genome_alone(kind, cfg):
    g = _population(cfg)
    steps, _ = closed_loop(_policy(kind, g, cfg), _start(24), tau_s=0.01, max_steps=300)
    assert len(set(steps.tolist())) > 2  # the genomes really differ
    for r, p in [(0, 0), (0, 7), (1, 3), (1, 11)]:
        one = g.select_runs([r]).gather(torch.tensor([[p]]))
        alone, _ = closed_loop(_policy(kind, one, cfg), _start(1), tau_s=0.01, max_steps=300)
        assert alone.item() == steps[r * 12 + p].item()


@pytest.mark.parametrize("kind, cfg", [("snn", SNN_CFG), ("sigmoid", SIG_CFG)])
def test_compaction_does_not_change_results(kind, cfg):
    g = _population(cfg)
    compacted, _ = closed_loop(_policy(kind, g, cfg), _start(24), tau_s=0.01, max_steps=300, compact_below=0.99)
    plain, _ = closed_loop(_policy(kind, g, cfg), _start(24), tau_s=0.01, max_steps=300, compact_below=0.0)
    assert torch.equal(compacted, plain)


def test_record_returns_traces_and_spikes():
    g = _population(SNN_CFG)
    one = g.select_runs([0]).gather(torch.tensor([[0]]))
    policy = _policy("snn", one, SNN_CFG)
    steps, trace = closed_loop(policy, _start(1), tau_s=0.01, max_steps=50, record=True)
    T = trace["x"].shape[0]
    assert T == min(50, steps.item() + 1)
    # Activity columns are the node slots the genome uses, in slot order.
    assert policy.nodes.tolist() == torch.nonzero(one.node[0, 0]).flatten().tolist()
    assert trace["activity"].shape == (T, 1, len(policy.nodes)) and trace["activity"].sum() > 0
    assert bool((trace["force"].abs() <= 10).all())


def test_bad_plant_state_is_caught():
    g = _population(SIG_CFG)
    s = _start(24)
    s[5, 1] = float("nan")
    with pytest.raises(PlantError, match=r"\[5\]"):
        closed_loop(_policy("sigmoid", g, SIG_CFG), s, tau_s=0.01, max_steps=10)


def test_spec_validation():
    with pytest.raises(ValueError, match="dt_ms"):
        SpikingSpec(dt_ms=0.0)
    with pytest.raises(ValueError, match="rate_window_steps"):
        SpikingSpec(rate_window_steps=0)
    g = _population(SNN_CFG)
    with pytest.raises(ValueError, match="whole number"):
        SpikingPolicy(g, SNN_CFG, SpikingSpec(dt_ms=0.3), 0.01, PLANT)
