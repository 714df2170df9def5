"""gymnasium environments as tasks of the seam (``pip install "snn-neat[gym]"``).

``GymTask(env_id)`` is the entry point. For the classic-control environments with a batched
torch port, ``CartPole-v1`` (``tasks.gym_cartpole``), ``Acrobot-v1`` (``tasks.acrobot``),
``MountainCar-v0`` and ``MountainCarContinuous-v0`` (``tasks.mountain_car``) and ``Pendulum-v1``
(``tasks.pendulum``), it returns the port: the same environment as batched tensor operations
with a native step (checked against gymnasium's own environment, ``tests/tasks/
test_classic_control.py``), so a rollout costs what the network costs. ``observation_bounds``,
``max_steps`` and ``control_period_s`` pass through (unset: the port's defaults, except the
observation bounds, which are the observation space's as for the adapter, so both paths code
observations alike); a ``make_kwargs`` the port does not model (anything but Pendulum's ``g``:
``render_mode``, ``max_episode_steps``, ...) falls back to the adapter. ``GymTask(env_id,
adapter=True)`` forces the adapter. The returned port is an instance of its own class
(``PendulumTask``, ``AcrobotTask``, ...), not of ``GymTask``; it carries the adapter's
``discrete`` (``n`` of a ``Discrete(n)`` action space, 0 for a ``Box``) and ``discrete_actions``
(``"bins"`` where it is discrete: the ports' actions are ordered pushes).

Any other environment runs through the adapter, which makes one gymnasium environment per
rollout row and steps them from the seam: NEAT, weight search, plots and checkpoints then work
on it like on a torch plant. Gymnasium environments are Python objects stepped one at a time,
so this path costs what the environment costs (``benchmarks/gym_speed.py`` prints it beside the
ports); write the plant in torch (``evolution.Task``) when speed matters.

How the adapter maps onto the seam's functional protocol:

- The state of a row is ``[B, 3 + n_obs]`` float64: the episode's seed, the row's environment
  (-1 until the first step makes it), whether it is done, and the last observation.
  ``reset(E, generator)`` draws ``E`` seeds and the start observations (each episode's
  environment reset with its seed); the rollout copies each episode's state to every genome,
  so every genome faces the same starts, and the first ``step`` gives each row its own
  environment, reset with the same seed, so it starts where ``reset`` said.
- Observations are normalised by the seam over the observation space's bounds. A space that is
  not a flat ``Box`` is flattened as gymnasium flattens it (``Discrete(n)``: n one-hot values;
  ``Tuple`` and ``Dict``: their parts side by side). Where a variable is unbounded (CartPole's
  velocities) and no ``observation_bounds`` are given, a port uses its own bounds and the adapter
  estimates them from 8 episodes of random actions (``estimate_bounds``). A space with a
  ``Discrete``, ``MultiDiscrete`` or ``MultiBinary`` part sets the task's
  ``discrete_observations``: its observations are categories that jump from step to step, and
  the defaults read them one step at a time (``evolution.defaults.default_spec``).
- Actions (``discrete_actions``): a ``Discrete(n)`` space with ``n >= 3`` takes one output per
  action and steps the largest (``"argmax"``; the first on a tie), since nothing says its
  actions are ordered (FrozenLake's left, down, right, up are not); ``n = 2``, or
  ``discrete_actions="bins"``, takes one continuous output in ``[-1, 1]`` split into ``n`` equal
  bins (``n = 2``: push left below 0, right above; ``discrete_action``, which the ports use
  too, whose actions are ordered pushes). A ``Box`` space takes its shape's outputs, scaled to
  its symmetric bound.
- ``terminated or truncated`` ends an episode; fitness is the return.

This module also holds what the ports share: ``discrete_action`` and ``port_options`` (their
constructor options, checked).
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from evolution.task import Task, TaskError
from snn_torch.functional.scalars import scalars

__all__ = ["GymTask", "PORTS", "DISCRETE_ACTIONS", "discrete_action", "port_options"]

_SEED, _ENV, _DONE, _OBS = 0, 1, 2, 3  # state columns
Bounds = tuple[Sequence[float], Sequence[float]]

# gymnasium id -> (module, class, the make_kwargs the port models): what GymTask returns
PORTS: dict[str, tuple[str, str, tuple[str, ...]]] = {
    "CartPole-v1": ("tasks.gym_cartpole", "GymCartPoleTask", ()),
    "Acrobot-v1": ("tasks.acrobot", "AcrobotTask", ()),
    "MountainCar-v0": ("tasks.mountain_car", "MountainCarTask", ()),
    "MountainCarContinuous-v0": ("tasks.mountain_car", "MountainCarContinuousTask", ()),
    "Pendulum-v1": ("tasks.pendulum", "PendulumTask", ("g",)),
}


# how a Discrete(n) action comes from the controller's outputs (module docstring)
DISCRETE_ACTIONS = ("bins", "argmax")


def _gymnasium():
    try:
        import gymnasium
    except ImportError:
        raise ImportError('GymTask needs gymnasium: pip install "snn-neat[gym]"') from None
    return gymnasium


def discrete_action(action: Tensor, n: int) -> Tensor:
    """gymnasium's ``Discrete(n)`` action of each row of ``action`` (``[B, 1]``, a continuous output
    in [-1, 1]): ``min(n - 1, max(0, floor((a + 1) / 2 * n)))`` as ``[B]`` float64 indices, computed
    in float64 from the action widened exactly (as ``GymTask`` bins it, and the ports' C steps)."""
    a = action[:, 0].to(torch.float64)
    one, two, bins = scalars((1.0, 2.0, float(n)), a)
    return torch.clamp(torch.floor((a + one) / two * bins), 0.0, float(n - 1))


def port_options(task: str, observation_bounds: Bounds | None, default: Bounds, max_steps: int,
                 control_period_s: float) -> tuple[tuple[float, ...], tuple[float, ...], int, float]:
    """A port's ``(observation_low, observation_high, max_steps, control_period_s)``, checked:
    ``ValueError`` naming ``task``'s field. ``observation_bounds``: ``(low, high)`` replacing
    ``default``, as many finite values each, ``high > low``."""
    try:
        low, high = default if observation_bounds is None else observation_bounds
        low, high = tuple(float(v) for v in low), tuple(float(v) for v in high)
    except (TypeError, ValueError):
        raise ValueError(f"{task}.observation_bounds must be (low, high) sequences of numbers, "
                         f"got {observation_bounds!r}") from None
    n = len(default[0])
    if len(low) != n or len(high) != n or not all(math.isfinite(v) for v in low + high) or \
            not all(h > lo for lo, h in zip(low, high, strict=True)):
        raise ValueError(f"{task}.observation_bounds must give {n} finite lows and highs with high > low, "
                         f"got {observation_bounds!r}")
    if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
        raise ValueError(f"{task}.max_steps must be a positive int (control steps), got {max_steps!r}")
    if isinstance(control_period_s, bool) or not isinstance(control_period_s, (int, float)) or \
            not (math.isfinite(control_period_s) and control_period_s > 0):
        raise ValueError(f"{task}.control_period_s must be a positive finite number (s), got {control_period_s!r}")
    return low, high, max_steps, float(control_period_s)


ESTIMATE_EPISODES = 8  # random-action episodes that estimate an unbounded variable's range
ESTIMATE_STEPS = 1000  # control steps of each at most
ESTIMATE_SEED = 0  # their seed: the same bounds every time


def flat_space(name: str, obs_space):
    """The flat ``Box`` the observations are coded over: ``obs_space`` itself where it is one,
    else gymnasium's ``flatten_space`` of it (a ``Discrete(n)`` becomes n one-hot variables in
    [0, 1]; ``Tuple``, ``Dict``, ``MultiDiscrete`` and ``MultiBinary`` concatenate theirs); a
    ``TaskError`` for a space gymnasium cannot flatten (``Text``, ``Graph``, ``Sequence``)."""
    gym = _gymnasium()
    if isinstance(obs_space, gym.spaces.Box) and len(obs_space.shape) == 1:
        return obs_space
    try:
        flat = gym.spaces.flatten_space(obs_space)
    except (NotImplementedError, TypeError, ValueError) as exc:
        raise TaskError(f"task {name!r}: cannot code the observation space {obs_space} as numbers ({exc})") from None
    if not (isinstance(flat, gym.spaces.Box) and len(flat.shape) == 1):
        raise TaskError(f"task {name!r}: the observation space {obs_space} does not flatten to one vector")
    return flat


def has_categories(space) -> bool:
    """Whether ``space`` (a gymnasium space) has a ``Discrete``, ``MultiDiscrete`` or
    ``MultiBinary`` part, in a ``Tuple`` or ``Dict`` too: observations that are categories."""
    spaces = _gymnasium().spaces
    if isinstance(space, (spaces.Discrete, spaces.MultiDiscrete, spaces.MultiBinary)):
        return True
    if isinstance(space, spaces.Tuple):
        return any(has_categories(part) for part in space.spaces)
    if isinstance(space, spaces.Dict):
        return any(has_categories(part) for part in space.spaces.values())
    return False


def estimate_bounds(make_env, flatten, low: np.ndarray, high: np.ndarray, max_steps: int) -> tuple[
        np.ndarray, np.ndarray]:
    """``(low, high)`` with each infinite bound replaced from what ``ESTIMATE_EPISODES`` episodes
    of uniformly random actions (seeded ``ESTIMATE_SEED``, at most ``min(max_steps,
    ESTIMATE_STEPS)`` steps each) observe: the middle of the 1st to 99th percentile of each
    variable, plus or minus twice their half-distance (a controller that acts well may go where
    random actions do not; beyond the bounds the coding saturates), at least 1 where a variable
    barely moved. ``make_env(seed)`` gives ``(env, its first observation as a vector)``;
    ``flatten(observation)`` makes a step's observation that vector."""
    seen = []
    for episode in range(ESTIMATE_EPISODES):
        env, obs = make_env(ESTIMATE_SEED + episode)
        env.action_space.seed(ESTIMATE_SEED + episode)
        seen.append(obs)
        for _ in range(min(max_steps, ESTIMATE_STEPS)):
            obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
            seen.append(flatten(obs))
            if terminated or truncated:
                break
        env.close()
    values = np.stack(seen)
    lo_q, hi_q = np.quantile(values, 0.01, axis=0), np.quantile(values, 0.99, axis=0)
    middle, spread = (lo_q + hi_q) / 2.0, hi_q - lo_q
    half = np.where(spread < 1.0e-3 * np.maximum(1.0, np.abs(middle)), 1.0, spread)  # twice the half-distance
    given_low, given_high = np.isfinite(low), np.isfinite(high)
    low, high = np.where(given_low, low, middle - half), np.where(given_high, high, middle + half)
    # one side given and the estimate of the other not past it: open the estimated side 2 half past it
    low = np.where(~given_low & (low >= high), high - 2.0 * half, low)
    high = np.where(~given_high & (high <= low), low + 2.0 * half, high)
    return low, high


def _given_bounds(name: str, flat, observation_bounds: Bounds | None) -> tuple[np.ndarray, np.ndarray]:
    """The bounds of ``flat`` (a flat Box), or ``observation_bounds`` in their place: a
    ``TaskError`` where the latter give the wrong number; infinite bounds are left as they are."""
    low, high = (np.asarray(b, dtype=np.float64) for b in (observation_bounds or (flat.low, flat.high)))
    if low.shape != flat.shape or high.shape != flat.shape:
        raise TaskError(f"task {name!r}: observation_bounds must give {flat.shape[0]} lows and highs")
    return low, high


class GymTask(Task):
    """A gymnasium environment (``env_id``, made with ``gymnasium.make(env_id, **make_kwargs)``):
    the torch port where there is one (``PORTS``; see the module docstring), else the adapter.

    Args:
        env_id: the registered id, e.g. ``"CartPole-v1"``, ``"Pendulum-v1"``.
        adapter: True to step gymnasium's own environments even where a port exists.
        discrete_actions: for a ``Discrete(n)`` action space, ``"argmax"`` (one output per action,
            the largest stepped) or ``"bins"`` (one output in [-1, 1], ``n`` ordered bins);
            default ``"argmax"`` for ``n >= 3``, ``"bins"`` for ``n = 2`` and on the ports.
        observation_bounds: ``(low, high)`` sequences replacing the observation space's bounds.
            Where the space leaves a variable unbounded and none are given, a port uses its own
            bounds for it and the adapter estimates them (``estimate_bounds``; the variables in
            ``estimated_bounds``).
        max_steps: episode length (default: the environment's ``max_episode_steps``, else 1000).
        control_period_s: network time per step (s; spiking controllers run
            ``control_period_s / dt`` substeps); default: the port's (its environment's step
            where it has one), 0.02 for the adapter.
    """

    fitness = "return"

    def __new__(cls, env_id: str | None = None, *, adapter: bool = False, discrete_actions: str | None = None,
                observation_bounds: Bounds | None = None, max_steps: int | None = None,
                control_period_s: float | None = None, **make_kwargs):
        # env_id None: unpickling or copying an adapter (object.__reduce_ex__ calls cls.__new__(cls))
        port = PORTS.get(env_id) if cls is GymTask and not adapter and isinstance(env_id, str) else None
        if port is None or not set(make_kwargs) <= set(port[2]):
            return super().__new__(cls)
        module, class_name, _ = port
        port_class = getattr(importlib.import_module(module), class_name)
        if discrete_actions is not None and not (discrete_actions == "bins" and getattr(port_class, "discrete", 0)):
            return super().__new__(cls)  # a coding the port does not have: the adapter (which checks it)
        probe = _gymnasium().make(env_id, **make_kwargs)
        space = probe.observation_space
        probe.close()
        # the space's bounds (as the adapter's, so both paths code alike); the port's where infinite
        low, high = _given_bounds(f"gym:{env_id}", flat_space(f"gym:{env_id}", space), observation_bounds)
        if not (np.isfinite(low).all() and np.isfinite(high).all()):
            own = port_class()
            low = np.where(np.isfinite(low), low, np.asarray(own.observation_low, dtype=np.float64))
            high = np.where(np.isfinite(high), high, np.asarray(own.observation_high, dtype=np.float64))
        options = {"observation_bounds": (tuple(low.tolist()), tuple(high.tolist())), **make_kwargs}
        if max_steps is not None:
            options["max_steps"] = max_steps
        if control_period_s is not None:
            options["control_period_s"] = control_period_s
        task = port_class(**options)
        if not hasattr(task, "discrete"):  # the adapter's attributes, on every task GymTask returns
            task.discrete = 0
        task.discrete_actions = "bins" if task.discrete else None
        return task

    def __init__(self, env_id: str, *, adapter: bool = False, discrete_actions: str | None = None,
                 observation_bounds: Bounds | None = None, max_steps: int | None = None,
                 control_period_s: float | None = None, **make_kwargs) -> None:
        gym = _gymnasium()
        self.env_id, self.make_kwargs, self.name = env_id, make_kwargs, f"gym:{env_id}"
        probe = gym.make(env_id, **make_kwargs)
        obs_space, act_space = probe.observation_space, probe.action_space
        spec_steps = probe.spec.max_episode_steps if probe.spec is not None else None
        probe.close()
        flat = flat_space(self.name, obs_space)
        self._space = None if flat is obs_space else obs_space  # None: observations are vectors already
        self.discrete_observations = has_categories(obs_space)
        low, high = _given_bounds(self.name, flat, observation_bounds)
        if discrete_actions is not None and (discrete_actions not in DISCRETE_ACTIONS or
                                             not isinstance(act_space, gym.spaces.Discrete)):
            raise TaskError(f"task {self.name!r}: discrete_actions must be one of {DISCRETE_ACTIONS} for a Discrete "
                            f"action space (this one is {act_space}), got {discrete_actions!r}")
        self.discrete_actions = None
        if isinstance(act_space, gym.spaces.Discrete):
            self.discrete, self._action_start = int(act_space.n), int(act_space.start)
            self.discrete_actions = discrete_actions or ("argmax" if self.discrete >= 3 else "bins")
            self.action_size = self.discrete if self.discrete_actions == "argmax" else 1
            self.action_max = 1.0
        elif isinstance(act_space, gym.spaces.Box) and len(act_space.shape) == 1 and \
                np.allclose(act_space.low, -act_space.high) and np.all(np.isfinite(act_space.high)):
            self.discrete, self.action_size = 0, int(act_space.shape[0])
            self.action_max = float(np.max(act_space.high))
            self._action_scale = act_space.high.astype(np.float64) / self.action_max
        else:
            raise TaskError(f"task {self.name!r}: needs a Discrete or symmetric, finite Box action space, "
                            f"got {act_space}")
        self.max_steps = int(max_steps if max_steps is not None else spec_steps or 1000)
        self.control_period_s = float(0.02 if control_period_s is None else control_period_s)
        self._envs: list = []  # the rollout's environments, one per row that has stepped
        self._pool: list = []  # environments free for the next rows
        # variables the space leaves unbounded: their range as random actions see it
        self.estimated_bounds = np.flatnonzero(~(np.isfinite(low) & np.isfinite(high))).tolist()
        if self.estimated_bounds:
            low, high = estimate_bounds(self._make, self._vector, low, high, self.max_steps)
        self.observation_low, self.observation_high = tuple(low.tolist()), tuple(high.tolist())
        self.validate()

    def _vector(self, obs) -> np.ndarray:
        """An observation as the float64 vector the controllers see (flattened where the space is
        not a flat Box)."""
        space = self._space
        if isinstance(space, _gymnasium().spaces.Discrete):  # gymnasium's flatten, without its dispatch
            onehot = np.zeros(int(space.n), dtype=np.float64)
            onehot[int(obs) - int(space.start)] = 1.0
            return onehot
        if space is not None:
            obs = _gymnasium().spaces.flatten(space, obs)
        return np.asarray(obs, dtype=np.float64)

    def _make(self, seed: int):
        """An environment reset with ``seed``, and its first observation as a vector: one of the
        last rollout's where there is one (``reset(seed=...)`` starts a new episode, as gymnasium's
        vector environments reuse theirs), else a new one."""
        env = self._pool.pop() if self._pool else _gymnasium().make(self.env_id, **self.make_kwargs)
        obs, _ = env.reset(seed=seed)
        return env, self._vector(obs)

    def __getstate__(self) -> dict:
        # environments stay with the process that made them (a copy or another worker makes its own)
        return {**self.__dict__, "_envs": [], "_pool": []}

    def reset(self, batch: int, generator: torch.Generator | None = None, *, device: torch.device | str = "cpu",
              dtype: torch.dtype = torch.float32) -> Tensor:
        """``batch`` episodes: seeds drawn from ``generator`` (below 2**31), start observations."""
        self._pool.extend(self._envs)  # a new rollout: the last one's environments are free again
        self._envs = []
        seeds = torch.randint(0, 2**31 - 1, (batch,), generator=generator, dtype=torch.int64)
        state = torch.zeros(batch, 3 + self.observation_size, dtype=torch.float64)
        state[:, _SEED], state[:, _ENV] = seeds.to(torch.float64), -1.0
        rows = state.numpy()
        for k, seed in enumerate(seeds.tolist()):
            env, rows[k, _OBS:] = self._make(seed)
            self._pool.append(env)
        return state.to(device)

    def _actions(self, action: Tensor) -> list:
        """Each row's gymnasium action from the controllers' ``action`` ``[B, action_size]``."""
        if self.discrete_actions == "argmax":  # the largest output's action (torch: the first on a tie)
            return (torch.argmax(action, dim=1) + self._action_start).tolist()
        if self.discrete:  # [-1, 1] in n equal bins, as the ports bin it
            return (discrete_action(action, self.discrete).to(torch.int64) + self._action_start).tolist()
        return list((action.to(torch.float64).numpy() * self._action_scale).astype(np.float32))

    def step(self, state: Tensor, action: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        new = state.detach().cpu().clone()
        rows = new.numpy()  # the same memory: numpy's element access is what a per-row loop can afford
        actions = self._actions(action.detach().cpu())
        reward = np.zeros(rows.shape[0], dtype=np.float64)
        for r in np.flatnonzero(rows[:, _DONE] == 0).tolist():  # gymnasium steps one environment at a time
            if rows[r, _ENV] < 0:  # the row's first step: its own environment, from the episode's seed
                env, _ = self._make(int(rows[r, _SEED]))
                self._envs.append(env)
                rows[r, _ENV] = len(self._envs) - 1
            obs, rew, terminated, truncated, _ = self._envs[int(rows[r, _ENV])].step(actions[r])
            rows[r, _OBS:] = self._vector(obs)
            reward[r] = float(rew)
            if terminated or truncated:
                rows[r, _DONE] = 1.0
        done = new[:, _DONE] != 0
        return new.to(state.device), torch.from_numpy(reward).to(state.device), done.to(state.device)

    def observe(self, state: Tensor) -> Tensor:
        return state[:, _OBS:]
