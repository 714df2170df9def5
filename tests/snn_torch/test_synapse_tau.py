"""Exponential (current-based) synapses: ``synapse_tau_ms`` of the population layer and of SpikingSpec."""

import math
from dataclasses import replace

import pytest
import torch

from evolution import NEAT
from evolution.kernels.episodes import native_episodes_available, native_rollout
from evolution.phenotype import SpikingSpec, make_controller
from evolution.rollout import rollout
from snn_torch import PopulationRecurrentIzhikevich
from snn_torch.functional.izhikevich import QIU2019
from snn_torch.functional.recurrent import (
    RecurrentState,
    SynapticState,
    recurrent_init,
    recurrent_izhikevich_step,
    synaptic_decay,
)
from snn_torch.kernels.network import kernel_available
from tasks.studies.double_pole import damping_fitness_starts, study_config, study_spec, study_task


def _layer(tau, backend="auto", w=None):
    w = torch.tensor([[[0.0, 40.0], [0.0, 0.0]]]) if w is None else w  # neuron 0 -> neuron 1
    return PopulationRecurrentIzhikevich(w, w != 0, QIU2019, synapse_kick_mv=None, synapse_tau_ms=tau, backend=backend)


def test_a_spike_delivers_the_instantaneous_charge_spread_over_tau():
    tau, dt = 10.0, 0.5
    k = synaptic_decay(tau, dt)
    assert k == pytest.approx(math.exp(-dt / tau))
    w = torch.tensor([[[0.0, 40.0], [0.0, 0.0]]])
    state = SynapticState(*(torch.zeros(1, 2) for _ in range(3)), torch.zeros(1, 2))
    state = state._replace(v=torch.full((1, 2), -70.0), u=torch.full((1, 2), -14.0), z=torch.tensor([[1.0, 0.0]]))
    currents = []
    for _ in range(400):  # 200 ms: one spike of neuron 0, then silence (no external current)
        _, state = recurrent_izhikevich_step(torch.zeros(1, 2), state, w, QIU2019, dt_ms=dt, syn_decay=k)
        currents.append(float(state.s[0, 1]))
    assert currents[0] == pytest.approx(40.0 * (1 - k))  # a fraction arrives at once ...
    assert currents[20] / currents[0] == pytest.approx(math.exp(-20 * dt / tau), rel=1e-4)  # ... the rest decays
    assert sum(currents) == pytest.approx(40.0, rel=1e-3)  # the same charge as the one-step synapse's 40


def test_tau_zero_is_the_instantaneous_synapse_and_a_tiny_tau_gives_its_bits():
    assert synaptic_decay(0.0, 0.5) is None
    g = torch.Generator().manual_seed(3)
    mask = torch.rand(5, 6, 6, generator=g) < 0.5
    w = torch.randn(5, 6, 6, generator=g) * 20 * mask
    i_ext = 10 + 40 * torch.rand(5, 6, generator=g)
    out = {}
    for tau in (0.0, 1e-6):  # exp(-0.5 / 1e-6) is exactly 0: s = drive, bit for bit
        layer = PopulationRecurrentIzhikevich(w, mask, QIU2019, synapse_tau_ms=tau)
        state = layer.initial_state(i_ext)
        assert isinstance(state, SynapticState if tau else RecurrentState)
        counts, state = layer.control_step(i_ext, state, substeps=40)
        out[tau] = (counts, state.v, layer.path(state))
    assert out[0.0][2] == out[1e-6][2]  # the same path with or without (tiny) synapses
    assert torch.equal(out[0.0][0], out[1e-6][0]) and torch.equal(out[0.0][1], out[1e-6][1])


def test_a_synaptic_time_constant_lags_the_postsynaptic_neuron():
    # neuron 0 driven hard, neuron 1 only through the synapse: with tau it starts firing later
    first = {}
    for tau in (0.0, 20.0):
        layer = _layer(tau)
        i_ext = torch.tensor([[60.0, 0.0]])
        state = layer.initial_state(i_ext)
        for step in range(40):
            counts, state = layer.control_step(i_ext, state, substeps=2)
            if counts[0, 1] > 0:
                first[tau] = step
                break
    assert first[0.0] < first[20.0]


def test_bad_taus_and_paths_name_the_setting():
    for bad in (-1.0, float("nan"), float("inf"), "20", True):
        with pytest.raises(ValueError, match="synapse_tau_ms"):
            _layer(bad)
        with pytest.raises(ValueError, match="SpikingSpec.synapse_tau_ms"):
            SpikingSpec(synapse_tau_ms=bad)
    with pytest.raises(ValueError, match="synaptic"):
        _layer(20.0, backend="compiled").control_step(torch.zeros(1, 2), substeps=2)
    with pytest.raises(ValueError, match="SynapticState"):  # a plain state where synapses need one
        recurrent_izhikevich_step(torch.zeros(1, 2), recurrent_init((1, 2), QIU2019), torch.zeros(1, 2, 2),
                                  QIU2019, syn_decay=0.9)


def _evolved_genomes(dtype=torch.float32):
    """A DPNV population with hidden neurons (a few generations of random fitness), where the
    synapses into hidden neurons matter (the decoder reads the rates of the nodes wired to the output)."""
    cfg = study_config("dpnv", "snn", coding="signed", pop_size=24, node_add_prob=0.5, conn_add_prob=0.5)
    neat = NEAT(cfg, seeds=[0], dtype=dtype)
    g = torch.Generator().manual_seed(0)
    for _ in range(6):
        neat.tell(torch.rand(1, cfg.pop_size, generator=g, dtype=torch.float64))
    assert int(neat.genomes.num_hidden(cfg).max()) > 0
    return neat.genomes, cfg


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_episode_kernel_runs_synapses_with_the_python_loops_bits(dtype):
    task = study_task("dpnv", "signed")  # a plant with a native step
    genomes, cfg = _evolved_genomes(dtype)
    starts = damping_fitness_starts(task, 8)  # the standard start and 7 random ones
    out = {}
    for tau in (0.0, 20.0):
        controller = make_controller(genomes, cfg, task, replace(study_spec("dpnv", "snn", "signed"), synapse_tau_ms=tau))
        assert native_rollout(task, controller, starts, episodes=8, max_steps=300) is not None or \
            not native_episodes_available()
        fast = rollout(task, controller, episodes=8, starts=starts, max_steps=300)
        slow = rollout(task, controller, episodes=8, starts=starts, max_steps=300, native=False)
        assert torch.equal(fast.returns, slow.returns) and torch.equal(fast.steps, slow.steps)
        out[tau] = fast.returns
    assert not torch.equal(out[0.0], out[20.0])  # the synapses changed what the controllers did


def test_spiking_controllers_with_synapses_keep_their_current_through_select():
    task = study_task("dpnv", "signed")
    genomes, cfg = _evolved_genomes()
    controller = make_controller(genomes, cfg, task, replace(study_spec("dpnv", "snn", "signed"), synapse_tau_ms=20.0))
    state = controller.initial_state(torch.arange(4))
    _, state, _ = controller.act(torch.rand(4, task.observation_size), state)
    kept = controller.select(state, torch.tensor([2, 0]))
    assert isinstance(kept.neurons, SynapticState)
    assert torch.equal(kept.neurons.s, state.neurons.s[[2, 0]])


@pytest.mark.skipif(not kernel_available(), reason="no C compiler: the torch step runs instead")
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_network_kernel_runs_synapses_with_the_torch_steps_bits(dtype):
    g = torch.Generator().manual_seed(5)
    G, B, N = 7, 19, 9
    mask = torch.rand(G, N, N, generator=g) < 0.4
    w = (torch.randn(G, N, N, generator=g) * 16 * mask).to(dtype)
    rows = torch.randint(0, G, (B,), generator=g)
    i_ext = (5 + 60 * torch.rand(B, N, generator=g)).to(dtype)
    fast = PopulationRecurrentIzhikevich(w, mask, QIU2019, synapse_tau_ms=15.0, backend="kernel")
    slow = PopulationRecurrentIzhikevich(w, mask, QIU2019, synapse_tau_ms=15.0, backend="torch")
    a = b = fast.initial_state(i_ext)
    for _ in range(6):  # the synaptic current carried across control steps
        ca, a = fast.control_step(i_ext, a, substeps=20, network=rows)
        cb, b = slow.control_step(i_ext, b, substeps=20, network=rows)
        assert torch.equal(ca, cb)
    assert isinstance(a, SynapticState) and all(torch.equal(x, y) for x, y in zip(a, b, strict=True))
    assert bool((a.s != 0).any())


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_a_controller_with_synapses_acts_alike_on_the_kernel_and_torch_paths(dtype):
    task = study_task("dpnv", "signed")
    genomes, cfg = _evolved_genomes(dtype)
    spec = replace(study_spec("dpnv", "snn", "signed"), synapse_tau_ms=20.0)
    obs = torch.rand(12, task.observation_size, generator=torch.Generator().manual_seed(1), dtype=dtype) * 2 - 1
    actions = []
    for backend in ("auto", "torch"):
        controller = make_controller(genomes, cfg, task, spec, backend=backend)
        state = controller.initial_state(torch.arange(12) % cfg.pop_size)
        expect = "kernel" if backend == "auto" and kernel_available() else "torch"
        assert controller.network.path(state.neurons) == expect
        trace = []
        for _ in range(5):
            action, state, _ = controller.act(obs, state)
            trace.append(action.clone())
        actions.append(torch.stack(trace))
    assert torch.equal(actions[0], actions[1])
