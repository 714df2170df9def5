"""Whole episodes in one native call (evolution.kernels.episodes): the torch rollout's bits, or a clear error."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
import torch

from evolution import NEAT, Task, TaskError, episode_starts, fresh_starts, make_controller, rollout
from evolution.kernels.episodes import native_episodes_available, native_rollout
from evolution.kernels.native_plant import native_plant
from evolution.phenotype import SigmoidSpec, SpikingSpec
from evolution.population import Genomes
from evolution.task import NativeStep
from tasks.cartpole import CartPoleTask
from tasks.double_pole import DoublePoleTask
from tasks.studies.cartpole import PAPER_SPECS, controller_config, markov_config
from tasks.studies.generalization import generalization_starts

_TEST_CSRC = Path(__file__).resolve().parent.parent / "csrc"

pytestmark = pytest.mark.skipif(not native_episodes_available(), reason="no C compiler: nothing native to compare")


def _genomes(cfg, seeds=(0, 1), generations=8, seed=0):
    """Populations with some structure: a few generations of NEAT under random fitness."""
    neat = NEAT(cfg, seeds=list(seeds))
    g = torch.Generator().manual_seed(seed)
    for _ in range(generations):
        neat.tell(torch.rand(len(seeds), cfg.pop_size, generator=g, dtype=torch.float64))
    return neat.ask()


def _as(genomes, dtype):
    """The population with its floating-point genes (weights, sigma) in ``dtype``."""
    return Genomes(**{k: v.to(dtype) if v.is_floating_point() else v for k, v in genomes.tensors().items()})


def _both(task, genomes, cfg, spec, kind, **kwargs):
    """``(native, python loop)`` rollouts of one population (fresh controllers: no shared state)."""
    controller = make_controller(genomes, cfg, task, spec)
    episodes = kwargs.get("episodes", 1)
    starts = kwargs.get("starts")
    if starts is None:
        starts = episode_starts(task, episodes, kwargs.get("seed", 0), dtype=controller.weight.dtype)
    assert native_rollout(task, controller, starts, episodes=episodes, max_steps=task.max_steps) is not None
    native = rollout(task, make_controller(genomes, cfg, task, spec), **kwargs)
    python = rollout(task, make_controller(genomes, cfg, task, spec), native=False, **kwargs)
    return native, python


def _assert_same(a, b):
    assert torch.equal(a.steps, b.steps)
    assert torch.equal(a.returns, b.returns)  # float64 sums in step order: bit for bit
    assert torch.equal(a.terminated, b.terminated)


SPIKING_SPECS = {
    "paper table2": PAPER_SPECS[("table2", "snn")],
    "paper table1 (bernoulli, bang-bang, rest-relative)": PAPER_SPECS[("table1", "snn")],
    "linear decoder, window 2": SpikingSpec(decoder="linear", rate_window_steps=2),
    "bang-bang above a threshold": SpikingSpec(decoder="bang_bang", threshold=25.0),
    "the library's task default (signed, synapses over 10 ms, spread start)": SpikingSpec(
        input_coding="signed", rate_window_steps=3, rest_relative=True, synapse_kick_mv=30.0, synapse_tau_ms=10.0,
        start="spread"),
}


@pytest.mark.parametrize("name", list(SPIKING_SPECS))
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_spiking_episodes_are_the_python_loops_bits(name, dtype):
    spec = SPIKING_SPECS[name]
    markov = spec.encoder == "bernoulli"
    cfg = markov_config("snn") if markov else controller_config("snn")
    task = CartPoleTask.markov(max_steps=400) if markov else CartPoleTask.nonmarkov(max_steps=400)
    genomes = _as(_genomes(cfg), dtype)
    native, python = _both(task, genomes, cfg, spec, "snn", episodes=3)
    _assert_same(native, python)
    assert int(native.steps.max()) > int(native.steps.min())  # rows end at different steps


@pytest.mark.parametrize("spec", [SigmoidSpec(), SigmoidSpec(decoder="bang_bang"), SigmoidSpec(updates_per_step=3)])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_sigmoid_episodes_are_the_python_loops_bits(spec, dtype):
    cfg = markov_config("sigmoid")
    task = CartPoleTask.markov(max_steps=400)
    genomes = _as(_genomes(cfg), dtype)
    native, python = _both(task, genomes, cfg, spec, "sigmoid", episodes=2)
    _assert_same(native, python)


def test_a_bias_value_runs_natively_to_the_python_loops_bits():
    cfg = replace(markov_config("sigmoid"), bias_value=0.5)  # NEAT C++ 1.2.1's bias input
    task = CartPoleTask.markov(max_steps=400)
    native, python = _both(task, _genomes(cfg), cfg, SigmoidSpec(), "sigmoid", episodes=2)
    _assert_same(native, python)


@pytest.mark.parametrize("velocities", [True, False])
@pytest.mark.parametrize("kind", ["snn", "sigmoid"])
def test_double_pole_episodes_are_the_python_loops_bits(velocities, kind):
    """From 25 of the 625 generalisation starts, with Gruau's damping fitness for DPNV."""
    task = DoublePoleTask(velocities=velocities, fitness="steps" if velocities else "damping", max_steps=300)
    cfg = replace(controller_config(kind), num_inputs=task.observation_size)
    starts = task.starts(generalization_starts()[::25])
    spec = SpikingSpec() if kind == "snn" else SigmoidSpec()
    native, python = _both(task, _genomes(cfg), cfg, spec, kind, episodes=starts.shape[0], starts=starts)
    _assert_same(native, python)


def test_thread_count_and_c_kernels_do_not_change_the_answer(monkeypatch):
    cfg = controller_config("snn")
    task = CartPoleTask.nonmarkov(max_steps=300)
    genomes = _genomes(cfg, seeds=(3, 4, 5))
    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        one = rollout(task, make_controller(genomes, cfg, task, SpikingSpec()), episodes=2)
        torch.set_num_threads(2)
        two = rollout(task, make_controller(genomes, cfg, task, SpikingSpec()), episodes=2)
    finally:
        torch.set_num_threads(threads)
    _assert_same(one, two)
    monkeypatch.setenv("SNN_NEAT_C_KERNELS", "0")  # no C at all: the torch modules and the torch plant
    fresh = CartPoleTask.nonmarkov(max_steps=300)
    torch_only = rollout(fresh, make_controller(genomes, cfg, fresh, SpikingSpec()), episodes=2)
    assert native_plant(fresh, torch.float32) is None
    _assert_same(one, torch_only)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_cartpole_native_step_is_the_torch_step(dtype):
    """Step by step from spread-out states under random forces, including failing ones."""
    task = CartPoleTask.markov()
    plant = native_plant(task, dtype)
    assert plant is not None
    g = torch.Generator().manual_seed(5)
    state = ((torch.rand(4000, 4, generator=g, dtype=torch.float64) - 0.5) * torch.tensor([5.0, 4.0, 0.5, 4.0],
                                                                                           dtype=torch.float64)).to(dtype)
    for _ in range(50):
        action = ((torch.rand(4000, 1, generator=g, dtype=torch.float64) * 2 - 1) * 10).to(dtype)
        ref = task.step(state, action)
        ours = plant.step(state, action)
        for a, b in zip(ours, ref, strict=True):
            assert torch.equal(a, b)
        assert torch.equal(plant.observe(state), task.observe(state))
        state = ref[0]


class PointMass(Task):
    """A unit mass on a line (state x, v, t), with a native twin in tests/csrc/point_mass.c."""

    observation_low, observation_high = (-2.0, -2.0), (2.0, 2.0)
    action_size, action_max = 1, 1.0
    max_steps, control_period_s = 60, 0.02

    def __init__(self, mode: int = 0) -> None:
        self.mode, self.name = mode, f"point-mass-{mode}"
        self.native = NativeStep(_TEST_CSRC / "point_mass.c", "point_mass", 3,
                                 params=(self.control_period_s * 5, mode, 0))

    def reset(self, batch, generator, *, device="cpu", dtype=torch.float32):
        x0 = torch.rand(batch, generator=generator, dtype=torch.float64) * 2.0 - 1.0
        return torch.stack([x0, torch.zeros_like(x0), torch.zeros_like(x0)], -1).to(device=device, dtype=dtype)

    def step(self, state, action):
        x, v, t = state.unbind(-1)
        dt = self.control_period_s * 5
        v = v + dt * (action[:, 0] - 0.5 * v)
        x = x + dt * v
        t = t + 1
        reward = -(x * x)
        if self.mode == 3:
            reward = torch.where((t == 30) & (x > 0), math.nan, reward)
        if self.mode == 5:
            v = torch.where(t == 10, math.nan, v)
        return torch.stack([x, v, t], -1), reward, x.abs() > 2.0

    def observe(self, state):
        return state[:, :2]


def _point_mass_genomes():
    cfg = controller_config("sigmoid")
    return cfg, _genomes(cfg)


def test_a_users_native_plant_runs_whole_episodes():
    task = PointMass(0)
    cfg, genomes = _point_mass_genomes()
    for dtype in (torch.float32, torch.float64):
        assert native_plant(task, dtype) is not None  # built and checked against the torch step
    native, python = _both(task, genomes, cfg, SigmoidSpec(), "sigmoid", episodes=4, seed=3)
    _assert_same(native, python)
    starts = task.reset(4, torch.Generator().manual_seed(3))
    ctrl = make_controller(genomes, cfg, task, SigmoidSpec())
    assert native_rollout(task, ctrl, starts, episodes=4, max_steps=60) is not None  # it did run natively


@pytest.mark.parametrize("kind", ["snn", "sigmoid"])
def test_a_start_per_row_runs_natively_to_the_python_loops_bits(kind):
    """``fresh_starts`` gives every run its own starts: one start state per row, in C as in torch."""
    task = PointMass(0)
    cfg = controller_config(kind)
    genomes = _genomes(cfg, seeds=(0, 1, 2))
    starts = fresh_starts(task, genomes, 3, 11)
    assert starts.shape == (3 * cfg.pop_size * 3, 3)
    native, python = _both(task, genomes, cfg, None, kind, episodes=3, starts=starts)
    _assert_same(native, python)
    shared = rollout(task, make_controller(genomes, cfg, task, kind), episodes=3, seed=11)
    assert not torch.equal(native.returns, shared.returns)  # the per-row starts were used


@pytest.mark.parametrize("mode, message", [(1, "native step's state differs from the torch step's"),
                                           (2, "native step returned error code 7")])
def test_a_native_step_that_disagrees_or_fails_is_caught_when_bound(mode, message):
    task = PointMass(mode)
    cfg, genomes = _point_mass_genomes()
    with pytest.raises(TaskError, match=message) as info:
        rollout(task, make_controller(genomes, cfg, task, SigmoidSpec()), episodes=2)
    assert task.name in str(info.value)


def test_a_native_step_that_crashes_is_reported_where_it_is_bound(tmp_path):
    """A segfault in a plant's C code ends the process, as in any C extension; it happens in the
    check when the plant is bound, before any evaluation, and Python's fault handler (on in
    ``snn-neat``, and here) names that frame."""
    script = tmp_path / "crash.py"
    script.write_text(
        "import faulthandler, sys\n"
        "faulthandler.enable()\n"
        f"sys.path.insert(0, {str(Path(__file__).resolve().parents[2])!r})\n"
        "from tests.evolution.test_native_episodes import PointMass, _point_mass_genomes\n"
        "from evolution import make_controller, rollout\n"
        "from evolution.phenotype import SigmoidSpec\n"
        "task = PointMass(4)\n"
        "cfg, genomes = _point_mass_genomes()\n"
        "rollout(task, make_controller(genomes, cfg, task, SigmoidSpec()), episodes=2)\n"
        "print('survived')\n")
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == -signal.SIGSEGV and "survived" not in proc.stdout
    assert "Segmentation fault" in proc.stderr and "native_plant.py" in proc.stderr  # in the check, named


def test_nan_reward_in_a_native_episode_names_the_task_and_row():
    task = PointMass(3)
    cfg, genomes = _point_mass_genomes()
    messages = []
    for native in (True, False):
        with pytest.raises(TaskError, match=r"step\(\) returned reward holding NaN or inf") as info:
            rollout(task, make_controller(genomes, cfg, task, SigmoidSpec()), episodes=3, seed=1,
                    native=native)
        messages.append(str(info.value))
    assert all("'point-mass-3'" in m and "(genome " in m for m in messages)


def test_native_step_fields_are_checked():
    with pytest.raises(ValueError, match="prefix"):
        NativeStep(_TEST_CSRC / "point_mass.c", "point-mass", 3)
    with pytest.raises(ValueError, match="state_width"):
        NativeStep(_TEST_CSRC / "point_mass.c", "point_mass", 0)
    with pytest.raises(ValueError, match="dtypes"):
        NativeStep(_TEST_CSRC / "point_mass.c", "point_mass", 3, dtypes=("float16",))
    with pytest.raises(ValueError, match="params"):
        NativeStep(_TEST_CSRC / "point_mass.c", "point_mass", 3, params=(math.nan,))


def _doc_blocks(language: str) -> list[str]:
    text = (Path(__file__).resolve().parents[2] / "docs" / "writing-a-task.md").read_text()
    blocks = text.split("```" + language + "\n")[1:]
    return [b.split("```")[0] for b in blocks]


def test_the_docs_native_pendulum_is_its_torch_step(tmp_path):
    """docs/writing-a-task.md's native step example, as a user would save it: built, checked
    against its torch step, and its episodes the Python loop's."""
    c_source = next(b for b in _doc_blocks("c") if "PENDULUM(f32, float)" in b)
    (tmp_path / "pendulum.c").write_text(c_source)
    task_code, check_code = [b for b in _doc_blocks("python") if "NativePendulum" in b]
    namespace = {"__file__": str(tmp_path / "plant.py")}
    exec(task_code, namespace)
    exec(check_code, namespace)  # the page's own check: the native step equals the torch step
    task = namespace["NativePendulum"]()
    cfg = replace(controller_config("snn"), num_inputs=2)
    genomes = _genomes(cfg)
    native, python = _both(task, genomes, cfg, SpikingSpec(), "snn", episodes=3, seed=2)
    _assert_same(native, python)
    assert float(native.returns.abs().sum()) > 0


@pytest.mark.parametrize("kind, spec", [("snn", PAPER_SPECS[("table2", "snn")]), ("snn", PAPER_SPECS[("table1", "snn")]),
                                        ("sigmoid", SigmoidSpec(updates_per_step=2))])
def test_the_static_map_ablation_runs_natively_with_the_same_bits(kind, spec):
    """evolution.ablation.StaticMapController (from rest, settle steps on each observation) in the
    episode loop: the Python loop's returns and steps."""
    from evolution.ablation import StaticMapController

    markov = kind == "sigmoid" or spec.encoder == "bernoulli"
    cfg = markov_config(kind) if markov else controller_config(kind)
    task = CartPoleTask.markov(max_steps=150) if markov else CartPoleTask.nonmarkov(max_steps=150)
    genomes = _genomes(cfg)
    maps = [StaticMapController(make_controller(genomes, cfg, task, spec), 3) for _ in range(2)]
    starts = episode_starts(task, 2, 0)
    assert native_rollout(task, maps[0], starts, episodes=2, max_steps=150) is not None
    native = rollout(task, maps[0], episodes=2)
    python = rollout(task, maps[1], episodes=2, native=False)
    _assert_same(native, python)
    assert int(native.steps.max()) > int(native.steps.min())


def test_nan_in_the_state_a_step_returns_is_caught_on_both_paths():
    """Not one step later on observe(), nor never on a last step: the state step() returns, for
    the rows alive before the step."""
    task = PointMass(5)
    cfg, genomes = _point_mass_genomes()
    for native in (True, False):
        for max_steps in (60, 10):  # step 10 is the last one in the second case
            with pytest.raises(TaskError, match=r"'point-mass-5': step\(\) returned state holding NaN or inf"):
                rollout(task, make_controller(genomes, cfg, task, SigmoidSpec()), episodes=3, seed=1,
                        native=native, max_steps=max_steps)
