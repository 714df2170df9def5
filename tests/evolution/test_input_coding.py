"""Input codings (unit, signed, push-pull) for both controllers: the values, the layouts, and the
same bits from the Python loop and the C episode loop."""

import dataclasses
import math

import pytest
import torch

from evolution import (
    NEAT,
    SigmoidSpec,
    SpikingSpec,
    TaskFitness,
    make_controller,
    random_genomes,
    rollout,
    task_config,
)
from evolution.input_coding import code_observations, coding_constants
from evolution.kernels.episodes import native_rollout
from tasks.cartpole import CartPoleTask
from tasks.pendulum import PendulumTask


def test_the_codings_values():
    low, high = torch.tensor([-2.0, 0.0]), torch.tensor([2.0, 10.0])
    obs = torch.tensor([[-2.0, 0.0], [0.0, 5.0], [1.0, 7.5], [3.0, -5.0]])
    unit = code_observations(obs, *coding_constants(low, high, "unit"), "unit", True)
    assert unit.tolist() == [[0.0, 0.0], [0.5, 0.5], [0.75, 0.75], [1.0, 0.0]]
    signed = code_observations(obs, *coding_constants(low, high, "signed"), "signed", True)
    assert signed.tolist() == [[-1.0, -1.0], [0.0, 0.0], [0.5, 0.5], [1.0, -1.0]]
    free = code_observations(obs, *coding_constants(low, high, "signed"), "signed", False)
    assert free[3].tolist() == [1.5, -2.0]  # unclipped, as NEAT 1.2.1 feeds its state
    pair = code_observations(obs, *coding_constants(low, high, "push_pull"), "push_pull", True)
    assert pair.tolist() == [[0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.5, 0.0], [1.0, 0.0, 0.0, 1.0]]


def test_bad_codings_are_errors_naming_the_field():
    with pytest.raises(ValueError, match=r"SpikingSpec.input_coding must be one of \('unit', 'signed', 'push_pull'\)"):
        SpikingSpec(input_coding="bipolar")
    with pytest.raises(ValueError, match=r"SigmoidSpec.clip_inputs=False needs input_coding 'signed' or 'push_pull'"):
        SigmoidSpec(clip_inputs=False)
    with pytest.raises(ValueError, match=r"'signed' cannot drive the Bernoulli encoder .* use 'push_pull'"):
        SpikingSpec(encoder="bernoulli", input_coding="signed")
    SpikingSpec(encoder="bernoulli", input_coding="push_pull")  # non-negative: fine


def test_push_pull_needs_two_inputs_per_variable_and_task_config_gives_them():
    task = CartPoleTask.nonmarkov()
    spec = SpikingSpec(input_coding="push_pull")
    cfg = task_config(task, spec, pop_size=8)
    assert cfg.num_inputs == 4
    TaskFitness(task, cfg, spec=spec)
    with pytest.raises(ValueError, match=r"2 observations \(coded as 4 inputs\) .* num_inputs=2"):
        TaskFitness(task, task_config(task, "snn", pop_size=8), spec=spec)
    with pytest.raises(ValueError, match=r"coded 'push_pull': 4 inputs"):
        make_controller(NEAT(task_config(task, pop_size=8)).ask(), task_config(task, pop_size=8), task, spec)


def _genomes(cfg, dtype, seed=0):
    g = random_genomes(cfg, runs=2, hidden=3, density=0.6, seed=seed)
    return type(g)(**{k: v.to(dtype) if v.is_floating_point() else v for k, v in g.tensors().items()})


SPECS = [SpikingSpec(input_coding="signed"), SpikingSpec(input_coding="push_pull", rest_relative=True),
         SpikingSpec(input_coding="signed", clip_inputs=False, decoder="linear"),
         SpikingSpec(input_coding="push_pull", encoder="bernoulli", input_rate_max_hz=400.0),
         SigmoidSpec(input_coding="signed", clip_inputs=False), SigmoidSpec(input_coding="push_pull")]


@pytest.mark.parametrize("spec", SPECS, ids=lambda s: f"{type(s).__name__}-{s.input_coding}-{s.clip_inputs}")
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_every_coding_runs_natively_to_the_python_loops_bits(spec, dtype):
    task = PendulumTask(max_steps=120)  # theta_dot spans +-8 rad/s: all of the range is used
    cfg = task_config(task, spec, pop_size=10, weight_init_stdev=2.0)
    genomes = _genomes(cfg, dtype)
    starts = task.reset(3, torch.Generator().manual_seed(4), dtype=dtype)
    assert native_rollout(task, make_controller(genomes, cfg, task, spec), starts, episodes=3,
                          max_steps=120) is not None
    native = rollout(task, make_controller(genomes, cfg, task, spec), episodes=3, seed=4)
    python = rollout(task, make_controller(genomes, cfg, task, spec), episodes=3, seed=4, native=False)
    assert torch.equal(native.returns, python.returns)
    assert native.returns.std() > 0


def test_the_coding_reaches_the_network():
    """The same genomes under unit and signed coding act differently; a sigmoid network's input
    nodes hold the coded values themselves."""
    task = PendulumTask(max_steps=5)
    unit, signed = SigmoidSpec(), SigmoidSpec(input_coding="signed")
    cfg = task_config(task, unit, pop_size=4)
    genomes = _genomes(cfg, torch.float64)
    traces = [rollout(task, make_controller(genomes, cfg, task, s), seed=1, record=True).trace for s in (unit, signed)]
    obs = traces[0]["observation"][0]
    assert torch.allclose(traces[0]["activity"][0][:, :3], (obs - torch.tensor([-1.0, -1.0, -8.0], dtype=torch.float64))
                          / torch.tensor([2.0, 2.0, 16.0], dtype=torch.float64))
    assert torch.allclose(traces[1]["activity"][0][:, :3], obs / torch.tensor([1.0, 1.0, 8.0], dtype=torch.float64))
    assert not torch.equal(traces[0]["action"], traces[1]["action"])


def test_rest_relative_inputs_rest_at_the_middle_of_the_range():
    """Under the signed codings the middle of the range is input 0: the rest rate an input node
    is measured against is the background's alone."""
    task = CartPoleTask.nonmarkov()
    for coding, inputs in (("unit", 2), ("signed", 2), ("push_pull", 4)):
        spec = SpikingSpec(input_coding=coding, rest_relative=True)
        cfg = task_config(task, spec, pop_size=4)
        controller = make_controller(NEAT(cfg).ask(), cfg, task, spec)
        rest_in, rest_hidden = controller.rest[:inputs], controller.rest[-1]
        if coding == "unit":
            assert bool((rest_in > rest_hidden).all())
        else:
            assert torch.equal(rest_in, rest_hidden.expand(inputs))
        assert math.isfinite(float(controller.rest.sum()))


def test_a_bias_value_of_one_half_acts_as_halved_bias_weights():
    """``NEATConfig.bias_value`` (NEAT C++ 1.2.1 feeds 0.5): a sigmoid network acts as with bias value 1
    and the bias node's outgoing weights halved, not as with the genomes' own weights; a spiking
    network's bias current scales with it."""
    task = PendulumTask(max_steps=8)
    spec = SigmoidSpec(input_coding="signed")
    cfg = task_config(task, spec, pop_size=6)
    half = dataclasses.replace(cfg, bias_value=0.5)
    genomes = _genomes(cfg, torch.float64)
    halved_weight = genomes.weight.clone()
    halved_weight[..., cfg.num_inputs, :] *= 0.5
    halved = type(genomes)(**{**genomes.tensors(), "weight": halved_weight})
    actions = [rollout(task, make_controller(g, c, task, spec), seed=3, record=True).trace["action"]
               for g, c in ((genomes, half), (halved, cfg), (genomes, cfg))]
    assert torch.equal(actions[0], actions[1])
    assert not torch.equal(actions[0], actions[2])
    snn = dataclasses.replace(task_config(task, SpikingSpec(), pop_size=6), num_bias=1)
    snn_genomes = _genomes(snn, torch.float64)
    actions = [rollout(task, make_controller(snn_genomes, dataclasses.replace(snn, bias_value=b), task, SpikingSpec()),
                       seed=3, record=True).trace["action"] for b in (1.0, 0.5)]
    assert not torch.equal(actions[0], actions[1])
