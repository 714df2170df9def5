"""The task seam: a plant written here, in plain torch, runs every controller through the public API."""

import math

import pytest
import torch

from evolution import NEAT, NEATConfig, Task, TaskError, TaskFitness, make_controller, rollout
from evolution.phenotype import SigmoidSpec, SpikingSpec
from tasks.cartpole import CartPoleTask
from tasks.studies.cartpole import controller_config, nonmarkov_fitness


class PointMass(Task):
    """A unit mass on a line, pushed towards x = 0 from random starts; reward -x^2 per step."""

    name = "point-mass"
    observation_low, observation_high = (-2.0, -2.0), (2.0, 2.0)
    action_size, action_max = 1, 1.0
    max_steps, control_period_s = 60, 0.02

    def reset(self, batch, generator, *, device="cpu", dtype=torch.float32):
        x0 = torch.rand(batch, generator=generator, dtype=torch.float64) * 2.0 - 1.0
        return torch.stack([x0, torch.zeros_like(x0)], -1).to(device=device, dtype=dtype)

    def step(self, state, action):
        x, v = state.unbind(-1)
        dt = self.control_period_s * 5
        v = v + dt * (action[:, 0] - 0.5 * v)
        x = x + dt * v
        new = torch.stack([x, v], -1)
        return new, -(x * x), x.abs() > 2.0

    def observe(self, state):
        return state


def _config(kind, **kw):
    return NEATConfig(num_inputs=2, num_outputs=1, num_bias=0 if kind == "snn" else 1, max_hidden=6, pop_size=24,
                      **({"sigma_init_mean": 0.005, "sigma_mutate_power": 0.001} if kind == "snn" else
                         {"sigma_mutate_rate": 0.0, "compatibility_sigma_coefficient": 0.0}), **kw)


@pytest.mark.parametrize("kind", ["snn", "sigmoid"])
def test_a_task_defined_here_evolves_through_the_public_api(kind):
    cfg = _config(kind)
    fitness = TaskFitness(PointMass(), cfg, kind, episodes=3, seed=7)
    neat = NEAT(cfg, seeds=[0, 1])
    first = fitness(neat.ask())
    result = neat.run(fitness, generations=20)
    assert first.shape == (2, 24) and first.dtype == torch.float64
    assert result.best_fitness.shape == (2,)
    improved = result.best_fitness > first.max(-1).values
    # NEAT-SNN: every run found a better controller than its first population's best. Sigmoid NEAT's
    # start genome is already near the best it reaches here, and with 24 genomes its small species
    # lose their champions (no elitism below 5 members): one of its two runs improves.
    assert bool(improved.all()) if kind == "snn" else bool(improved.any())


def _population(cfg, seed=0, runs=2):
    neat = NEAT(cfg, seeds=list(range(seed, seed + runs)))
    neat.run(TaskFitness(PointMass(), cfg, "snn" if cfg.num_bias == 0 else "sigmoid", max_steps=20), 3)
    return neat.ask()


@pytest.mark.parametrize("kind", ["snn", "sigmoid"])
def test_same_genome_same_fitness_in_every_path_and_batch_position(kind):
    cfg = _config(kind)
    g = _population(cfg)
    task = PointMass()
    full = TaskFitness(task, cfg, kind, episodes=4, seed=3)(g)
    # every genome alone, in a reversed batch, and on the torch path with no kernel
    alone = torch.stack([TaskFitness(task, cfg, kind, episodes=4, seed=3)(g.select_runs([r]))[0] for r in range(2)])
    assert torch.equal(alone, full)
    flip = torch.flip(torch.arange(g.pop_size), [0]).expand(2, -1)
    assert torch.equal(TaskFitness(task, cfg, kind, episodes=4, seed=3)(g.gather(flip)), full.flip(-1))
    torch_path = TaskFitness(task, cfg, kind, episodes=4, seed=3, backend="torch")(g)
    assert torch.equal(torch_path, full)


def test_cartpole_fitness_is_the_same_on_every_path(monkeypatch):
    cfg = controller_config("snn", pop_size=20)
    neat = NEAT(cfg, seeds=[4])
    neat.run(nonmarkov_fitness("snn", cfg, max_steps=400), 3)
    g = neat.ask()
    kernel = nonmarkov_fitness("snn", cfg, max_steps=400)(g)
    assert torch.equal(nonmarkov_fitness("snn", cfg, max_steps=400, backend="torch")(g), kernel)
    monkeypatch.setenv("SNN_NEAT_C_KERNELS", "0")  # as on a machine without a C compiler
    assert torch.equal(nonmarkov_fitness("snn", cfg, max_steps=400)(g), kernel)
    assert int(kernel.max()) > 50  # some genomes balance for a while


def test_episodes_equal_each_start_alone_and_compaction_changes_nothing():
    cfg = _config("snn")
    g = _population(cfg, runs=1)
    task = PointMass()
    controller = make_controller(g, cfg, task)
    starts = task.reset(5, torch.Generator().manual_seed(1))
    batch = rollout(task, controller, episodes=5, starts=starts)
    never = rollout(task, controller, episodes=5, starts=starts, compact_below=0.0)
    assert torch.equal(batch.returns, never.returns) and torch.equal(batch.steps, never.steps)
    for e in range(5):
        one = rollout(task, controller, episodes=1, starts=starts[e : e + 1])
        assert torch.equal(one.returns[:, 0], batch.returns[:, e])


class Broken(PointMass):
    def __init__(self, fault):
        self.fault = fault

    def step(self, state, action):
        new, reward, done = super().step(state, action)
        if self.fault == "nan":
            reward = reward.clone()
            reward[[3, 10]] = math.nan
        elif self.fault == "shape":
            reward = reward[:-1]
        elif self.fault == "dtype":
            done = done.float()
        return new, reward, done

    def observe(self, state):
        return state[:, :1] if self.fault == "obs" else state


@pytest.mark.parametrize("fault, words", [
    ("nan", ["point-mass", "step()", "reward", "NaN", "(genome 1, episode 1)", "(genome 5, episode 0)"]),
    ("shape", ["point-mass", "reward", "shape"]),
    ("dtype", ["point-mass", "terminated", "bool"]),
    ("obs", ["point-mass", "observe()", "observation", "shape"]),
])
def test_bad_task_output_names_the_task_the_field_and_the_rows(fault, words):
    cfg = _config("snn")
    g = _population(cfg, runs=1)
    task = Broken(fault)
    task.name = "point-mass"
    with pytest.raises(TaskError) as err:
        rollout(task, make_controller(g, cfg, task), episodes=2)
    for word in words:
        assert word in str(err.value), (word, str(err.value))


def test_bad_task_declarations_and_layouts_are_refused():
    class NoBounds(PointMass):
        observation_low = (-1.0,)

    with pytest.raises(TaskError, match="observation_low"):
        TaskFitness(NoBounds(), _config("snn"))
    with pytest.raises(ValueError, match="num_inputs"):
        cfg = NEATConfig(num_inputs=3, num_outputs=1, num_bias=0, pop_size=4)
        TaskFitness(PointMass(), cfg)(NEAT(cfg, seeds=[0]).ask())
    with pytest.raises(ValueError, match="SpikingSpec.decoder"):
        SpikingSpec(decoder="softmax")
    with pytest.raises(ValueError, match="SigmoidSpec"):
        SigmoidSpec(updates_per_step=0)
    with pytest.raises(ValueError, match="whole number"):
        make_controller(NEAT(_config("snn"), seeds=[0]).ask(), _config("snn"), CartPoleTask(tau_s=0.0123))


def test_terminated_tells_a_task_end_from_the_step_limit():
    cfg = _config("snn")
    g = _population(cfg, runs=1)
    task = PointMass()
    starts = torch.tensor([[1.9, 3.0], [0.0, 0.0]])  # the first leaves |x| <= 2 at once, the second cannot
    result = rollout(task, make_controller(g, cfg, task), episodes=2, starts=starts, max_steps=5)
    assert bool(result.terminated[:, 0].all()) and not bool(result.terminated[:, 1].any())
    assert bool((result.steps[:, 1] == 5).all()) and bool((result.steps[:, 0] == 0).all())


def test_markov_cartpole_with_bernoulli_inputs_is_the_same_on_every_path(monkeypatch):
    from tasks.studies.cartpole import markov_config, markov_fitness

    cfg = markov_config("snn", pop_size=12)
    neat = NEAT(cfg, seeds=[2])
    neat.run(markov_fitness("snn", cfg, max_steps=150), 2)
    g = neat.ask()
    kernel = markov_fitness("snn", cfg, max_steps=150)(g)
    assert torch.equal(markov_fitness("snn", cfg, max_steps=150, backend="torch")(g), kernel)
    monkeypatch.setenv("SNN_NEAT_C_KERNELS", "0")
    assert torch.equal(markov_fitness("snn", cfg, max_steps=150)(g), kernel)
    assert int(kernel.max()) > 20


def test_evolution_imports_nothing_from_tasks():
    import subprocess
    import sys

    code = ("import pkgutil, importlib, sys, evolution\n"
            "for m in pkgutil.iter_modules(evolution.__path__):\n"
            "    importlib.import_module('evolution.' + m.name)\n"
            "print(sorted(k for k in sys.modules if k == 'tasks' or k.startswith('tasks.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


class TupleMass(PointMass):
    """PointMass with its state as a plain tuple ``(x, v)`` of ``[B]`` tensors, as the docs allow."""

    name = "tuple-mass"

    def __init__(self, bad_start: int | None = None) -> None:
        self.bad_start = bad_start

    def reset(self, batch, generator, *, device="cpu", dtype=torch.float32):
        x, v = super().reset(batch, generator, device=device, dtype=dtype).unbind(-1)
        if self.bad_start is not None:
            x = x.clone()
            x[self.bad_start] = math.nan
        return (x, v)

    def step(self, state, action):
        new, reward, done = super().step(torch.stack(state, -1), action)
        return tuple(new.unbind(-1)), reward, done

    def observe(self, state):
        return torch.stack(state, -1)


@pytest.mark.parametrize("kind", ["snn", "sigmoid"])
def test_a_plain_tuple_state_runs_as_its_stacked_twin(kind):
    cfg = _config(kind)
    genomes = _population(cfg)
    plain = rollout(TupleMass(), make_controller(genomes, cfg, TupleMass(), kind), episodes=3, seed=4)
    stacked = rollout(PointMass(), make_controller(genomes, cfg, PointMass(), kind), episodes=3, seed=4)
    assert torch.equal(plain.returns, stacked.returns) and torch.equal(plain.steps, stacked.steps)


def test_nan_in_a_tuple_start_is_caught_at_reset_counting_starts():
    cfg = _config("sigmoid")
    task = TupleMass(bad_start=1)
    with pytest.raises(TaskError, match=r"reset\(\) returned state holding NaN or inf at 1 of 3 start\(s\), first: episode 1"):
        rollout(task, make_controller(_population(cfg), cfg, task, "sigmoid"), episodes=3)
