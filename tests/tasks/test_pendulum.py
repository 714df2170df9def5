"""The Pendulum-v1 port: step by step against gymnasium's own environment, and natively."""

import math

import numpy as np
import pytest
import torch

from evolution import SigmoidSpec, SpikingSpec, make_controller, random_genomes, rollout, task_config
from evolution.kernels.episodes import native_rollout
from evolution.kernels.native_plant import native_plant
from tasks.pendulum import PendulumTask, angle_normalize

gym = pytest.importorskip("gymnasium")


def _gym_episode(start: np.ndarray, actions: np.ndarray):
    """gymnasium's observations (after reset and each step), rewards and flags from ``start``."""
    env = gym.make("Pendulum-v1")
    env.reset(seed=0)
    env.unwrapped.state = start.astype(np.float64).copy()
    obs = [env.unwrapped._get_obs()]
    rewards, terminated, truncated = [], [], []
    for a in actions:
        o, r, term, trunc, _ = env.step(np.array([a], dtype=np.float32))
        obs.append(o)
        rewards.append(r)
        terminated.append(term)
        truncated.append(trunc)
    env.close()
    return np.array(obs), np.array(rewards), np.array(terminated), np.array(truncated)


def _port_episode(task: PendulumTask, start: np.ndarray, actions: np.ndarray):
    state = torch.tensor(start, dtype=torch.float64).view(1, 2)
    obs, rewards, terminated = [task.observe(state)[0]], [], []
    for a in actions:
        state, r, term = task.step(state, torch.tensor([[float(np.float32(a))]], dtype=torch.float64))
        obs.append(task.observe(state)[0])
        rewards.append(float(r[0]))
        terminated.append(bool(term[0]))
    return torch.stack(obs).numpy(), np.array(rewards), np.array(terminated)


@pytest.mark.parametrize("seed", range(6))
def test_whole_episodes_agree_with_gymnasium_from_its_starts_under_random_torques(seed):
    rng = np.random.default_rng(seed)
    task = PendulumTask()
    env = gym.make("Pendulum-v1")
    env.reset(seed=seed)
    start = env.unwrapped.state.copy()  # gymnasium's own start state
    env.close()
    actions = rng.uniform(-2.5, 2.5, size=200)  # beyond the torque limit too: both clip
    g_obs, g_rew, g_term, g_trunc = _gym_episode(start, actions)
    p_obs, p_rew, p_term = _port_episode(task, start, actions)
    assert not g_term.any() and not p_term.any()
    assert g_trunc[-1] and not g_trunc[:-1].any()  # truncated at 200 steps = task.max_steps
    assert task.max_steps == 200
    np.testing.assert_allclose(p_obs, g_obs, rtol=0, atol=1e-5)  # gymnasium's observations are float32
    np.testing.assert_allclose(p_rew, g_rew, rtol=1e-9, atol=1e-9)


def test_an_evolved_style_controller_agrees_with_gymnasium():
    """Actions from a network reading the port's own observations (closed loop, as evolution
    runs it), replayed open loop in gymnasium: the same trajectory."""
    task = PendulumTask()
    cfg = task_config(task, "sigmoid", pop_size=4, weight_init_stdev=3.0)
    genomes = random_genomes(cfg, hidden=3, density=0.8, seed=4)
    genomes = type(genomes)(**{k: v.to(torch.float64) if v.is_floating_point() else v
                               for k, v in genomes.tensors().items()})
    result = rollout(task, make_controller(genomes, cfg, task, SigmoidSpec()), episodes=2, seed=9, record=True)
    actions = result.trace["action"][:, :, 0]  # [T, rows]
    states = result.trace["state"]
    starts = task.reset(2, torch.Generator().manual_seed(9), dtype=torch.float64)
    for row in range(8):
        start = starts[row % 2].numpy()
        g_obs, g_rew, _, _ = _gym_episode(start, actions[:, row].numpy())
        np.testing.assert_allclose(result.trace["reward"][:, row].numpy(), g_rew, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(states[-1, row, 1].item(), g_obs[-1, 2], atol=1e-5)
    assert float(actions.abs().max()) > 0.5  # the controllers did push


def test_the_angle_wraps_as_gymnasium_wraps_it():
    theta = torch.tensor([-7.0, -math.pi, -1.0, 0.0, 1.0, math.pi, 3 * math.pi, 20.0], dtype=torch.float64)
    wrapped = ((theta.numpy() + np.pi) % (2 * np.pi)) - np.pi
    np.testing.assert_array_equal(angle_normalize(theta).numpy(), wrapped)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("observe_velocity", [True, False])
def test_the_native_step_is_the_torch_step_and_runs_whole_episodes(dtype, observe_velocity):
    task = PendulumTask(observe_velocity=observe_velocity)
    assert task.observation_size == (3 if observe_velocity else 2)
    plant = native_plant(task, dtype)  # built, and checked bit for bit against the torch step
    if plant is None:
        pytest.skip("no C compiler")
    state = task.reset(256, torch.Generator().manual_seed(1), dtype=dtype) * 3.0  # angles past +-pi too
    action = torch.linspace(-3.0, 3.0, 256, dtype=torch.float64).view(-1, 1)
    for _ in range(50):
        a = plant.step(state, action)
        b = task.step(state, action.to(dtype))
        assert all(torch.equal(x, y) for x, y in zip(a, b, strict=True))
        assert torch.equal(plant.observe(state), task.observe(state).to(torch.float64))
        state = b[0]
    cfg = task_config(task, "snn", pop_size=6)
    genomes = random_genomes(cfg, runs=2, hidden=2, density=0.6, seed=3)
    genomes = type(genomes)(**{k: v.to(dtype) if v.is_floating_point() else v for k, v in genomes.tensors().items()})
    native = rollout(task, make_controller(genomes, cfg, task, SpikingSpec()), episodes=3, seed=2)
    python = rollout(task, make_controller(genomes, cfg, task, SpikingSpec()), episodes=3, seed=2, native=False)
    assert native_rollout(task, make_controller(genomes, cfg, task, SpikingSpec()),
                          task.reset(3, torch.Generator().manual_seed(2), dtype=dtype), episodes=3,
                          max_steps=200) is not None
    assert torch.equal(native.returns, python.returns) and bool((native.steps == 200).all())


def test_bad_gravity_is_an_error_naming_it():
    with pytest.raises(ValueError, match="PendulumTask.g must be a positive finite number"):
        PendulumTask(g=float("nan"))
