"""The classic-control ports (CartPole-v1, Acrobot-v1, MountainCar-v0, MountainCarContinuous-v0)
against gymnasium's own environments, natively, and through ``GymTask``.

Tolerances: gymnasium's float64 states at 1e-9 (the ports repeat numpy's operations in its order;
what differs is sin and cos, ``portable_math``'s against numpy's, each within an ulp, and in the
acrobot numpy's scalar ``x**2``, which calls the C library's ``pow``, against ``x * x``);
observations, which gymnasium returns as float32, and the continuous mountain car's float32
state, to one float32 ulp (a float64 value an ulp off can round to the neighbouring float32);
rewards at 1e-9; terminated flags and episode lengths exactly. The acrobot is chaotic once it
swings hard: an ulp of sin or cos grows tenfold every ~20 steps there, so its energetic episodes
are compared whole against gymnasium's own code with numpy's sin and cos swapped for
``portable_math``'s (``portable_trig``), and step by step (from gymnasium's state every step)
against gymnasium unchanged.
"""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest
import torch

from evolution import (
    SigmoidSpec,
    SpikingSpec,
    make_controller,
    random_genomes,
    rollout,
    sigmoid_config,
    task_config,
)
from evolution.kernels.episodes import native_rollout
from evolution.kernels.native_plant import native_plant
from snn_torch.functional.portable_math import sin_cos
from tasks.acrobot import AcrobotTask
from tasks.gym_adapter import GymTask, discrete_action
from tasks.gym_cartpole import GymCartPoleTask
from tasks.mountain_car import MountainCarContinuousTask, MountainCarTask
from tasks.pendulum import PendulumTask

gym = pytest.importorskip("gymnasium")
gym_acrobot = pytest.importorskip("gymnasium.envs.classic_control.acrobot")

PORTS = {"CartPole-v1": GymCartPoleTask, "Acrobot-v1": AcrobotTask, "MountainCar-v0": MountainCarTask,
         "MountainCarContinuous-v0": MountainCarContinuousTask}
CARTPOLE_BOUNDS = ((-2.4, -3.0, -0.21, -3.5), (2.4, 3.0, 0.21, 3.5))
F32_ULP = 2.0**-23  # relative


def _bins(a: float, n: int) -> int:
    """gymnasium's discrete action from a continuous one, as ``GymTask._action`` computes it."""
    return int(min(n - 1, max(0, math.floor((a + 1.0) / 2.0 * n))))


def _gym_action(task, a: float):
    return _bins(a, task.discrete) if task.discrete else np.array([a], dtype=np.float32)


def _gym_state(env) -> np.ndarray:
    return np.asarray(env.unwrapped.state, dtype=np.float64)


def _port_row(task, gym_state: np.ndarray, first: bool) -> torch.Tensor:
    """A port state ``[1, width]`` (float64) from gymnasium's state (the continuous mountain car's
    third column: 1 before its first step)."""
    row = list(gym_state) + ([1.0 if first else 0.0] if task.native.state_width == 3 else [])
    return torch.tensor(row, dtype=torch.float64).view(1, -1)


@pytest.fixture
def portable_trig(monkeypatch):
    """gymnasium's acrobot with numpy's sin and cos replaced by ``portable_math``'s (the rest, its
    rk4, dynamics, wrap, bound and terminal test, its own)."""
    def sin(x):
        return np.float64(sin_cos(torch.tensor(float(x), dtype=torch.float64))[0].item())

    def cos(x):
        return np.float64(sin_cos(torch.tensor(float(x), dtype=torch.float64))[1].item())
    monkeypatch.setattr(gym_acrobot, "sin", sin)
    monkeypatch.setattr(gym_acrobot, "cos", cos)


def _side_by_side(env_id: str, seed: int, policy, *, resync: bool = False) -> dict:
    """Step gymnasium's ``env_id`` from its own start for ``seed`` and the port beside it, with
    the actions ``policy(gymnasium's observation)``; ``resync``: the port steps from gymnasium's
    state every step (one-step agreement) instead of from its own (whole episodes)."""
    task = PORTS[env_id]()
    env = gym.make(env_id)
    obs, _ = env.reset(seed=seed)
    state = _port_row(task, _gym_state(env), True)
    out = {k: [] for k in ("g_state", "p_state", "g_obs", "p_obs", "g_rew", "p_rew", "g_term", "p_term", "g_trunc")}
    # the start's observation (the acrobot's: numpy's float32 sin and cos of its float32 start)
    np.testing.assert_allclose(task.observe(state)[0].numpy(), obs, rtol=F32_ULP, atol=0)
    for t in range(task.max_steps):
        a = float(policy(obs))
        if resync:
            state = _port_row(task, _gym_state(env), t == 0)
        obs, reward, terminated, truncated, _ = env.step(_gym_action(task, a))
        state, p_reward, p_term = task.step(state, torch.tensor([[a]], dtype=torch.float64))
        for key, value in (("g_state", _gym_state(env)), ("p_state", state[0, :len(_gym_state(env))].numpy()),
                           ("g_obs", obs), ("p_obs", task.observe(state)[0].numpy()), ("g_rew", reward),
                           ("p_rew", float(p_reward[0])), ("g_term", terminated), ("p_term", bool(p_term[0])),
                           ("g_trunc", truncated)):
            out[key].append(value)
        if terminated or truncated:
            break
    env.close()
    out = {k: np.array(v) for k, v in out.items()}
    out["max_steps"] = task.max_steps
    return out


def _assert_agree(run: dict, *, float32_state: bool = False) -> None:
    if float32_state:  # the continuous mountain car's state is float32 in gymnasium
        np.testing.assert_allclose(run["p_state"], run["g_state"], rtol=F32_ULP, atol=0)
    else:
        np.testing.assert_allclose(run["p_state"], run["g_state"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(run["p_obs"], run["g_obs"], rtol=F32_ULP, atol=0)
    np.testing.assert_allclose(run["p_rew"], run["g_rew"], rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(run["p_term"], run["g_term"])  # the same step of termination
    steps = len(run["g_term"])
    # truncated by gymnasium's TimeLimit exactly at the port's max_steps, unless terminated first
    assert bool(run["g_trunc"][-1]) == (not run["g_term"][-1] and steps == run["max_steps"])
    assert steps == run["max_steps"] or run["g_term"][-1]


def _random(seed: int):
    rng = np.random.default_rng(seed)
    return lambda obs: rng.uniform(-1.2, 1.2)  # beyond [-1, 1] too: the continuous car clips


def _feedback(env_id: str, seed: int):
    """Policies that reach the end: balance the pole; pump the acrobot's and the car's energy."""
    magnitude = 0.5 + 0.1 * (seed % 5)  # past 1/3: a push in MountainCar-v0's bins too
    if env_id == "CartPole-v1":
        return lambda obs: magnitude if obs[2] + 0.5 * obs[3] > 0 else -magnitude
    if env_id == "Acrobot-v1":
        return lambda obs: 1.0 if obs[4] + 0.3 * obs[5] > 0 else -1.0
    return lambda obs: magnitude if obs[1] >= 0 else -magnitude


@pytest.mark.parametrize("env_id", list(PORTS))
@pytest.mark.parametrize("seed", range(4))
def test_whole_episodes_agree_with_gymnasium_from_its_starts_under_random_actions(env_id, seed):
    run = _side_by_side(env_id, seed, _random(seed))
    _assert_agree(run, float32_state=env_id == "MountainCarContinuous-v0")
    assert len(run["g_term"]) > 8  # an episode, not a step
    assert PORTS[env_id]().max_steps == gym.spec(env_id).max_episode_steps


@pytest.mark.parametrize("env_id", list(PORTS))
@pytest.mark.parametrize("seed", range(4))
def test_whole_episodes_agree_with_gymnasium_under_feedback_to_the_goal_or_the_limit(env_id, seed, request):
    if env_id == "Acrobot-v1":  # the swing-up is chaotic: gymnasium's code with the port's sin and cos
        request.getfixturevalue("portable_trig")
    run = _side_by_side(env_id, seed, _feedback(env_id, seed))
    _assert_agree(run, float32_state=env_id == "MountainCarContinuous-v0")
    if env_id == "CartPole-v1":
        assert len(run["g_term"]) == 500 and run["g_trunc"][-1]  # balanced to the time limit
    else:
        assert run["g_term"][-1]  # reached the goal


@pytest.mark.parametrize("seed", range(4))
def test_every_acrobot_step_agrees_with_unchanged_gymnasium_along_its_swing_up(seed):
    run = _side_by_side("Acrobot-v1", seed, _feedback("Acrobot-v1", seed), resync=True)
    np.testing.assert_allclose(run["p_state"], run["g_state"], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(run["p_term"], run["g_term"])
    np.testing.assert_array_equal(run["p_rew"], run["g_rew"])
    assert run["g_term"][-1] and np.abs(run["g_state"][:, 2:]).max() > 10.0  # a hard swing, to the goal


def test_the_first_continuous_mountain_car_step_is_numpys_float64_step():
    """gymnasium's first step runs in float64 (its start state is), the later ones in float32: the
    third state column tells the port which; from a float64 start, taking the float32 step instead
    differs from gymnasium."""
    task = MountainCarContinuousTask()
    env = gym.make("MountainCarContinuous-v0")
    differs = 0
    for seed in range(40):
        env.reset(seed=seed)
        start = _gym_state(env)
        a = np.float32(np.random.default_rng(seed).uniform(-1, 1))
        env.step(np.array([a]))
        action = torch.tensor([[float(a)]], dtype=torch.float64)
        first, _, _ = task.step(_port_row(task, start, True), action)
        later, _, _ = task.step(_port_row(task, start, False), action)
        assert np.array_equal(first[0, :2].numpy(), _gym_state(env))
        differs += not torch.equal(later, first)
    env.close()
    assert differs > 0


def _network_actions(task, starts: torch.Tensor, kind: str, seed: int):
    """A random network's closed-loop episodes on the port from ``starts`` (float64), up to 400
    steps (the continuous car's 999 in the Python loop would be slow; its limit is tested above)."""
    spec = SpikingSpec() if kind == "snn" else SigmoidSpec()
    cfg = task_config(task, kind, pop_size=3, weight_init_stdev=3.0)
    genomes = random_genomes(cfg, hidden=3, density=0.8, seed=seed, dtype=torch.float64)
    controller = make_controller(genomes, cfg, task, spec)
    return rollout(task, controller, episodes=starts.shape[0], starts=starts, record=True,
                   max_steps=min(task.max_steps, 400))


@pytest.mark.parametrize("env_id", list(PORTS))
@pytest.mark.parametrize("kind", ["sigmoid", "snn"])
def test_a_networks_episodes_agree_with_gymnasium(env_id, kind):
    """Actions from a random network reading the port's observations (closed loop, as evolution
    runs it) from gymnasium's starts, replayed open loop in gymnasium: the same rewards, states
    and step of termination."""
    task = PORTS[env_id]()
    env = gym.make(env_id)
    gym_starts = []
    for seed in range(2):
        env.reset(seed=100 + seed)
        gym_starts.append(_port_row(task, _gym_state(env), True)[0])
    result = _network_actions(task, torch.stack(gym_starts), kind, seed=0)
    actions, rewards, states = (result.trace[k] for k in ("action", "reward", "state"))
    pushed = set()
    for row in range(actions.shape[1]):
        env.reset(seed=100 + row % 2)
        g_rewards = []
        for t in range(actions.shape[0]):
            a = float(actions[t, row, 0])
            pushed.add(_bins(a, task.discrete) if task.discrete else a > 0)
            _, reward, terminated, truncated, _ = env.step(_gym_action(task, a))
            g_rewards.append(reward)
            width = len(_gym_state(env))
            np.testing.assert_allclose(states[t, row, :width].numpy(), _gym_state(env), rtol=F32_ULP, atol=1e-9)
            if terminated or truncated:
                break
        g, e = divmod(row, 2)
        assert bool(result.terminated[g, e]) == terminated and int(result.steps[g, e]) == t + (not terminated)
        np.testing.assert_allclose(rewards[: t + 1, row].numpy(), g_rewards, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(float(result.returns[g, e]), sum(g_rewards), rtol=1e-9, atol=1e-9)
    env.close()
    assert len(pushed) > 1  # the networks did act: more than one action


def _spread_states(task, rows: int, generator: torch.Generator) -> torch.Tensor:
    """States across (and past) each plant's range, float64: the native check's hard cases."""
    u = torch.rand(rows, task.native.state_width, generator=generator, dtype=torch.float64) * 2.0 - 1.0
    if isinstance(task, GymCartPoleTask):
        return u * torch.tensor([3.0, 3.0, 0.3, 3.0], dtype=torch.float64)  # past the limits too
    if isinstance(task, AcrobotTask):  # every angle, velocities to their bounds
        return u * torch.tensor([math.pi, math.pi, 4 * math.pi, 9 * math.pi], dtype=torch.float64)
    x = -0.3 + 0.9 * u[:, 0]
    x[:8] = torch.tensor([-1.2, 0.6, 0.5, 0.45, -1.19, 0.59, -0.5, 0.449], dtype=torch.float64)  # walls, goals
    columns = [x, 0.07 * u[:, 1]]
    if isinstance(task, MountainCarContinuousTask):
        columns.append((u[:, 2] > 0).to(torch.float64))  # first steps and later ones
    return torch.stack(columns, -1)


@pytest.mark.parametrize("env_id", list(PORTS))
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_native_step_is_the_torch_step_and_runs_whole_episodes(env_id, dtype):
    task = PORTS[env_id]()
    plant = native_plant(task, dtype)  # built, and checked bit for bit against the torch step
    if plant is None:
        pytest.skip("no C compiler")
    g = torch.Generator().manual_seed(1)
    state = _spread_states(task, 512, g).to(dtype)
    for t in range(60):
        action = torch.rand(512, 1, generator=g, dtype=torch.float64) * 3.0 - 1.5
        action[:9, 0] = torch.tensor([-1.0, -1 / 3, 0.0, 1 / 3, 1.0, -0.5, 0.5, -1.5, 1.5], dtype=torch.float64)
        action = action.to(dtype)  # the controller's dtype, as the rollout hands it over
        a = plant.step(state, action)
        b = task.step(state, action)
        assert all(torch.equal(x, y) for x, y in zip(a, b, strict=True)), t
        assert torch.equal(plant.observe(state), task.observe(state))
        state = b[0]
    assert torch.isfinite(state).all()
    cfg = task_config(task, "snn", pop_size=6)
    genomes = random_genomes(cfg, runs=2, hidden=2, density=0.6, seed=3, dtype=dtype)
    steps = min(task.max_steps, 300)
    native = rollout(task, make_controller(genomes, cfg, task, SpikingSpec()), episodes=3, seed=2, max_steps=steps)
    python = rollout(task, make_controller(genomes, cfg, task, SpikingSpec()), episodes=3, seed=2, max_steps=steps,
                     native=False)
    assert native_rollout(task, make_controller(genomes, cfg, task, SpikingSpec()),
                          task.reset(3, torch.Generator().manual_seed(2), dtype=dtype), episodes=3,
                          max_steps=steps) is not None
    assert torch.equal(native.returns, python.returns) and torch.equal(native.steps, python.steps)
    assert torch.equal(native.terminated, python.terminated)


def test_the_discrete_bins_are_gym_tasks():
    a = torch.tensor([-2.0, -1.0, -0.5, -1 / 3, -1e-9, 0.0, 1e-9, 1 / 3, 0.5, 0.999, 1.0, 2.0], dtype=torch.float64)
    for n in (2, 3):
        expected = [_bins(float(x), n) for x in a]
        assert discrete_action(a.view(-1, 1), n).tolist() == expected
        assert discrete_action(a.view(-1, 1).to(torch.float32), n).tolist() == \
            [_bins(float(x), n) for x in a.to(torch.float32)]


@pytest.mark.parametrize("cls", [*PORTS.values(), PendulumTask])
def test_bad_options_are_errors_naming_the_field(cls):
    name = cls.__name__
    n = len(cls().observation_low)
    for bounds in (((0.0,), (1.0,)), ((0.0,) * n, (float("inf"),) * n), ((1.0,) * n, (1.0,) * n), "low-high"):
        with pytest.raises(ValueError, match=rf"{name}\.observation_bounds"):
            cls(observation_bounds=bounds)
    for steps in (0, 1.5, True):
        with pytest.raises(ValueError, match=rf"{name}\.max_steps"):
            cls(max_steps=steps)
    for period in (0.0, -0.01, float("nan"), "0.02"):
        with pytest.raises(ValueError, match=rf"{name}\.control_period_s"):
            cls(control_period_s=period)
    task = cls(observation_bounds=((-5.0,) * n, (5.0,) * n), max_steps=7, control_period_s=0.01)
    assert (task.observation_low, task.observation_high, task.max_steps, task.control_period_s) == \
        ((-5.0,) * n, (5.0,) * n, 7, 0.01)


def test_default_periods_and_bounds():
    assert [PORTS[k]().control_period_s for k in PORTS] == [0.02, 0.2, 0.02, 0.02]
    assert PendulumTask().control_period_s == 0.05
    for env_id, cls in PORTS.items():  # gymnasium's space where finite (its float32 values)
        space = gym.make(env_id).observation_space
        finite = np.isfinite(space.high)
        assert np.array_equal(np.array(cls().observation_high)[finite], space.high[finite].astype(np.float64))
        assert np.array_equal(np.array(cls().observation_low)[finite], space.low[finite].astype(np.float64))
    assert GymCartPoleTask().observation_high[1::2] == (3.0, 3.5)  # the chosen velocity bounds


def _gym_resets(env_id: str, n: int) -> np.ndarray:
    env = gym.make(env_id)
    states = []
    for seed in range(n):
        env.reset(seed=seed)
        states.append(_gym_state(env))
    env.close()
    return np.array(states)


@pytest.mark.parametrize("env_id", list(PORTS))
def test_start_states_are_drawn_as_gymnasiums(env_id):
    task = PORTS[env_id]()
    starts = task.reset(20000, torch.Generator().manual_seed(0), dtype=torch.float64)
    assert starts.shape == (20000, task.native.state_width)
    assert task.reset(3, torch.Generator().manual_seed(0)).dtype == torch.float32
    reference = _gym_resets(env_id, 1000)
    width = reference.shape[1]
    ranges = {"CartPole-v1": (-0.05, 0.05), "Acrobot-v1": (-0.1, 0.1), "MountainCar-v0": (-0.6, -0.4),
              "MountainCarContinuous-v0": (-0.6, -0.4)}
    low, high = ranges[env_id]
    random_columns = width if width == 4 else 1  # the cars start at rest
    ours = starts[:, :random_columns].numpy()
    if env_id == "Acrobot-v1":  # rounded to float32 as gymnasium's, so the bounds are float32 values
        low, high = float(np.float32(low)), float(np.float32(high))
        assert np.array_equal(ours, ours.astype(np.float32))
    assert (ours >= low).all() and (ours <= high).all()
    assert (reference[:, :random_columns] >= low).all() and (reference[:, :random_columns] <= high).all()
    width_of_range = high - low
    for column in range(random_columns):  # uniform across the range, as gymnasium's: the deciles agree
        q = np.linspace(0.05, 0.95, 10)
        np.testing.assert_allclose(np.quantile(ours[:, column], q), low + q * width_of_range,
                                   atol=0.01 * width_of_range)
        np.testing.assert_allclose(np.quantile(reference[:, column], q), low + q * width_of_range,
                                   atol=0.06 * width_of_range)
    if width == 2:
        assert (starts[:, 1] == 0).all() and (reference[:, 1] == 0).all()
    if env_id == "MountainCarContinuous-v0":
        assert (starts[:, 2] == 1).all()  # before the first step


def test_gym_task_gives_the_port_and_the_adapter_on_request():
    for env_id, cls in [*PORTS.items(), ("Pendulum-v1", PendulumTask)]:
        bounds = {"observation_bounds": CARTPOLE_BOUNDS} if env_id == "CartPole-v1" else {}
        port = GymTask(env_id, **bounds)
        assert type(port) is cls and not isinstance(port, GymTask)
        coding = {"discrete_actions": "bins"} if port.discrete else {}  # the ports' ordered bins
        adapter = GymTask(env_id, adapter=True, **coding, **bounds)
        assert type(adapter) is GymTask and adapter.env_id == env_id
        # the same task either way: observations, bounds, actions, length (and the adapter's attributes)
        for field in ("observation_low", "observation_high", "action_size", "action_max", "max_steps", "discrete",
                      "discrete_actions", "discrete_observations"):
            assert getattr(port, field) == getattr(adapter, field), (env_id, field)
        again = pickle.loads(pickle.dumps(adapter))
        assert type(again) is GymTask and again.env_id == env_id and again.max_steps == adapter.max_steps
        assert type(pickle.loads(pickle.dumps(port))) is cls
    acrobot = GymTask("Acrobot-v1", max_steps=50, control_period_s=0.05, observation_bounds=((-2.0,) * 6, (2.0,) * 6))
    assert (acrobot.max_steps, acrobot.control_period_s, acrobot.observation_high) == (50, 0.05, (2.0,) * 6)
    assert GymTask("Acrobot-v1").control_period_s == 0.2 and GymTask("Acrobot-v1", adapter=True).control_period_s == 0.02
    assert GymTask("Pendulum-v1", g=9.81).g == 9.81  # a make_kwargs the port models
    assert type(GymTask("Pendulum-v1", render_mode="rgb_array")) is GymTask  # one it does not: the adapter
    assert GymTask("CartPole-v1").observation_high[1] == GymCartPoleTask().observation_high[1]  # unbounded: the port's
    # a coding the port does not have is the adapter's; the port's own keeps the port
    assert type(GymTask("Acrobot-v1", discrete_actions="argmax")) is GymTask
    assert type(GymTask("Acrobot-v1", discrete_actions="bins")) is AcrobotTask


@pytest.mark.parametrize("env_id", [*PORTS, "Pendulum-v1"])
def test_a_controllers_episodes_on_the_port_are_its_episodes_through_the_adapter(env_id):
    """The same network, closed loop, from the same starts (the adapter's seeds' resets): on the
    port it sees the observations, takes the actions and earns the returns it does through the
    adapter: observations to one float32 ulp, actions exactly, returns to 1e-9. Except Pendulum's:
    its port observes its state unrounded where the adapter observes gymnasium's float32 values
    (theta_dot's half ulp near 8 rad/s: 4.8e-7), so the network's actions differ by up to about
    1e-6 (N m) and the returns by about 1e-9 relative: 1e-6, 1e-5 and 1e-8 there."""
    if env_id == "Pendulum-v1":
        tol = {"observation": (0.0, 1e-6), "action": (0.0, 1e-5), "returns": (1e-8, 0.0)}
    else:
        tol = {"observation": (F32_ULP, 0.0), "action": (0.0, 0.0), "returns": (1e-9, 1e-9)}
    bounds = {"observation_bounds": CARTPOLE_BOUNDS} if env_id == "CartPole-v1" else {}
    port = GymTask(env_id, max_steps=150, **bounds)
    coding = {"discrete_actions": "bins"} if port.discrete else {}  # the ports' ordered bins
    adapter = GymTask(env_id, adapter=True, max_steps=150, **coding, **bounds)
    adapter_starts = adapter.reset(2, torch.Generator().manual_seed(7), dtype=torch.float64)
    env = gym.make(env_id)
    port_starts = []
    for seed in adapter_starts[:, 0].tolist():
        env.reset(seed=int(seed))
        port_starts.append(_port_row(port, _gym_state(env), True)[0])
    env.close()
    # NEAT's own config (not the library's task defaults): the networks these tolerances were measured on
    cfg = sigmoid_config(port.observation_size, port.action_size, pop_size=4, weight_init_stdev=3.0)
    genomes = random_genomes(cfg, hidden=3, density=0.8, seed=0, dtype=torch.float64)
    on_port = rollout(port, make_controller(genomes, cfg, port, SigmoidSpec()), episodes=2,
                      starts=torch.stack(port_starts), record=True)
    on_adapter = rollout(adapter, make_controller(genomes, cfg, adapter, SigmoidSpec()), episodes=2,
                         starts=adapter_starts, record=True)
    assert torch.equal(on_port.steps, on_adapter.steps) and torch.equal(on_port.terminated, on_adapter.terminated)
    for key in ("observation", "action"):
        rtol, atol = tol[key]
        torch.testing.assert_close(on_port.trace[key], on_adapter.trace[key], rtol=rtol, atol=atol)
    rtol, atol = tol["returns"]
    torch.testing.assert_close(on_port.returns, on_adapter.returns, rtol=rtol, atol=atol)
    actions = on_port.trace["action"].flatten().tolist()
    assert len({_bins(a, port.discrete) if port.discrete else a > 0 for a in actions}) > 1  # the networks act
