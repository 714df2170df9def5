"""The controller side of the seam: the ``Controller`` protocol the rollout relies on (a user's own
controller runs on any task, and the spec registry makes it), and the decoders both built-in
controllers share (one bang-bang with one threshold rule)."""

from dataclasses import dataclass

import pytest
import torch

from evolution import NEAT, SigmoidSpec, SpikingSpec, TaskFitness, make_controller, task_config
from evolution.phenotype import CONTROLLER_NAMES, CONTROLLERS, as_spec, register_controller, spec_name
from evolution.task import Controller
from snn_torch.modules.coding import BangBang
from tests.evolution.test_task_seam import PointMass


@dataclass(frozen=True)
class ProportionalSpec:
    """A user's controller: action = clamp(gain * sum_i w_i x_i), x in [0, 1], no state."""

    gain: float = 2.0


class ProportionalController:
    def __init__(self, genomes, config, task, spec: ProportionalSpec) -> None:
        N = genomes.num_nodes
        w = genomes.effective_weight().reshape(-1, N, N)
        self.w = w[:, : config.num_inputs, config.first_output]  # [G, inputs]
        self.num_genomes, self.gain, self.action_max = w.shape[0], spec.gain, task.action_max

    @classmethod
    def for_task(cls, genomes, config, task, spec, *, backend="auto"):
        return cls(genomes, config, task, spec)

    dtype = property(lambda self: self.w.dtype)
    device = property(lambda self: self.w.device)
    input_coding = ("unit", True)

    def initial_state(self, network):
        return network

    def act(self, inputs, network):
        drive = (inputs * self.w[network]).sum(-1, keepdim=True)
        return (self.gain * drive).clamp(-self.action_max, self.action_max), network, drive

    def select(self, network, keep):
        return network[keep]


@pytest.fixture
def registered():
    register_controller(ProportionalSpec, ProportionalController, name="proportional")
    yield
    CONTROLLERS.pop(ProportionalSpec)
    CONTROLLER_NAMES.pop("proportional")


def test_a_users_controller_runs_on_the_seam_through_the_registry(registered):
    task = PointMass()
    cfg = task_config(task, "sigmoid", pop_size=6)
    genomes = NEAT(cfg, seeds=[0, 1]).ask()
    controller = make_controller(genomes, cfg, task, ProportionalSpec(gain=1.5))
    assert isinstance(controller, ProportionalController) and isinstance(controller, Controller)
    assert spec_name(ProportionalSpec()) == "proportional" and type(as_spec("proportional")) is ProportionalSpec
    fitness = TaskFitness(task, cfg, ProportionalSpec(gain=1.5), episodes=2, seed=3)(genomes)
    assert fitness.shape == (2, 6) and torch.isfinite(fitness).all()
    # The rollout's definition, by hand, for one genome and episode: observe, code to [0, 1] over the
    # bounds, act, step, sum the rewards until termination.
    starts = task.reset(2, torch.Generator().manual_seed(3))
    w = controller.w[4]  # genome 4 = run 0, genome 4
    totals = []
    for episode in range(2):
        state, total = starts[episode : episode + 1], 0.0
        for _ in range(task.max_steps):
            x = ((task.observe(state) + 2.0) / 4.0).clamp(0.0, 1.0)
            action = (1.5 * (x * w).sum(-1, keepdim=True)).clamp(-1.0, 1.0)
            state, reward, terminated = task.step(state, action)
            total += float(reward[0])
            if bool(terminated[0]):
                break
        totals.append(total)
    assert fitness[0, 4].item() == pytest.approx(sum(totals) / 2, rel=1e-5)


def test_a_controller_without_the_protocol_is_refused_by_name():
    with pytest.raises(ValueError, match="register_controller takes a spec class and a controller class"):
        register_controller(ProportionalSpec, object)
    with pytest.raises(ValueError, match=r"spec must be one of .* got ProportionalSpec"):
        as_spec(ProportionalSpec())  # not registered


def test_both_controllers_decode_bang_bang_with_the_one_module_and_a_strict_threshold():
    task = PointMass()
    sig_cfg, snn_cfg = task_config(task, "sigmoid", pop_size=4), task_config(task, "snn", pop_size=4)
    sigmoid = make_controller(NEAT(sig_cfg).ask(), sig_cfg, task, SigmoidSpec(decoder="bang_bang"))
    spiking = make_controller(NEAT(snn_cfg).ask(), snn_cfg, task, SpikingSpec(decoder="bang_bang", threshold=2.0))
    assert type(sigmoid.decoder) is BangBang and type(spiking.decoder) is BangBang
    at = torch.tensor([[0.5], [0.5000001], [0.4999999]])
    assert sigmoid.decoder(at).flatten().tolist() == [-1.0, 1.0, -1.0]  # y > 0.5, strictly
    drive = torch.tensor([[2.0], [2.0000002], [1.9999998]])
    assert spiking.decoder(drive).flatten().tolist() == [-1.0, 1.0, -1.0]  # d > threshold, strictly
