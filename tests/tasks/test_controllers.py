import math

import pytest
import torch

from evolution import NEAT, NEATConfig
from snn_torch.compiled import CompiledSubstep
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


def test_compiled_torch_path_balances_the_same_steps_as_the_eager_one():
    # The path CUDA takes (the torch loop, not the C kernels), with and without torch.compile.
    g = _population(SNN_CFG)
    compiled = SpikingPolicy(g, SNN_CFG, SpikingSpec(), 0.01, PLANT, use_fused=False, compile_step=True)
    eager = SpikingPolicy(g, SNN_CFG, SpikingSpec(), 0.01, PLANT, use_fused=False, compile_step=False)
    assert isinstance(compiled.network_step, CompiledSubstep)
    assert not isinstance(eager.network_step, CompiledSubstep)
    got, _ = closed_loop(compiled, _start(24), tau_s=0.01, max_steps=200, compact_below=0.99)
    assert compiled.network_step.compiled, compiled.network_step.reason
    want, _ = closed_loop(eager, _start(24), tau_s=0.01, max_steps=200, compact_below=0.99)
    assert len(set(want.tolist())) > 2  # rows fail at different steps: compaction changed the batch size
    assert torch.equal(got, want)
    # By default only CUDA compiles; the C kernels take the CPU batch.
    assert not isinstance(SpikingPolicy(g, SNN_CFG, SpikingSpec(), 0.01, PLANT, use_fused=False).network_step,
                          CompiledSubstep)
    with pytest.raises(ValueError, match="compile_step"):
        SpikingPolicy(g, SNN_CFG, SpikingSpec(), 0.01, PLANT, compile_step="yes")


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


def _markov_hand_wired(weights):
    """The Markov start genome (inputs x, x_dot, theta, theta_dot wired to the output) with
    the given input weights, one genome per row of ``weights``."""
    from tasks.experiments.cartpole import markov_config

    cfg = markov_config("snn", pop_size=len(weights))
    g = NEAT(cfg, seeds=[0]).ask()
    g.weight[0, :, :4, cfg.first_output] = torch.tensor(weights)
    assert bool(g.enabled[0, :, :4, cfg.first_output].all())
    return g, cfg


def test_markov_weighted_rate_decoder_pushes_towards_balance():
    """A stabilising linear law (push the cart the way the pole and cart drift) holds the pole;
    the same weights negated drop it at once. Rates are taken relative to rest, so an
    all-positive weight vector is not simply 'always +10 N'."""
    from tasks.controllers import MarkovSpikingPolicy, MarkovSpikingSpec
    from tasks.experiments.cartpole import markov_start

    g, cfg = _markov_hand_wired([(2.0, 1.0, 4.0, 6.0), (-2.0, -1.0, -4.0, -6.0), (1.0, 1.0, 1.0, 1.0)])
    spec = MarkovSpikingSpec(input_rate_max_hz=2000.0)  # one spike per 0.5 ms substep at input 1
    steps, _ = closed_loop(MarkovSpikingPolicy(g, cfg, spec, 0.02, PLANT), markov_start(3), tau_s=0.02,
                           max_steps=20_000)
    assert steps[0] == 20_000
    assert steps[1] < 50
    assert 0 < steps[2] < 20_000  # too little theta feedback: balances a while, then falls


def test_markov_row_result_does_not_depend_on_batch():
    from tasks.controllers import MarkovSpikingPolicy, MarkovSpikingSpec
    from tasks.experiments.cartpole import markov_config, markov_start

    cfg = markov_config("snn", pop_size=12, node_add_prob=0.5, conn_add_prob=0.5)
    neat = NEAT(cfg, seeds=[0, 1])
    neat.run(lambda g: g.num_genes().double(), 3)  # grow some structure
    g = neat.genomes
    for decoder in ("weighted_rate", "output_neuron"):
        spec = MarkovSpikingSpec(decoder=decoder)
        steps, _ = closed_loop(MarkovSpikingPolicy(g, cfg, spec, 0.02, PLANT), markov_start(24), tau_s=0.02,
                               max_steps=2000)
        assert len(set(steps.tolist())) > 2
        for r, p in [(0, 0), (0, 5), (1, 11)]:
            one = g.select_runs([r]).gather(torch.tensor([[p]]))
            alone, _ = closed_loop(MarkovSpikingPolicy(one, cfg, spec, 0.02, PLANT), markov_start(1), tau_s=0.02,
                                   max_steps=2000)
            assert alone.item() == steps[r * 12 + p].item()


def test_markov_spec_validation():
    from tasks.controllers import MarkovSpikingSpec

    with pytest.raises(ValueError, match="decoder"):
        MarkovSpikingSpec(decoder="mean")
    with pytest.raises(ValueError, match="input_rate_max_hz"):
        MarkovSpikingSpec(input_rate_max_hz=2500.0)


def test_markov_noise_seed_redraws_the_input_spikes():
    from tasks.controllers import MarkovSpikingPolicy, MarkovSpikingSpec
    from tasks.experiments.cartpole import markov_start
    from tasks.experiments.markov_noise_retest import retest_steps

    g, cfg = _markov_hand_wired([(2.0, 1.0, 4.0, 6.0), (1.0, 1.0, 1.0, 1.0), (0.5, 0.5, 2.0, 1.0)])
    spec = MarkovSpikingSpec()

    def steps(noise_seed, fused=True):
        policy = MarkovSpikingPolicy(g, cfg, spec, 0.02, PLANT, noise_seed=noise_seed, use_fused=fused)
        return closed_loop(policy, markov_start(3), tau_s=0.02, max_steps=3000)[0]

    assert torch.equal(steps(0), steps(0))
    assert torch.equal(steps(7), steps(7))
    assert not torch.equal(steps(0), steps(7))  # a fresh realisation of the spike trains
    champions = type(g)(**{k: v.reshape(3, 1, *v.shape[2:]) for k, v in g.tensors().items()})
    retest = retest_steps(champions, 2, max_steps=3000)
    assert retest.shape == (3, 2)
    assert torch.equal(retest[:, 0], steps(1)) and torch.equal(retest[:, 1], steps(2))
