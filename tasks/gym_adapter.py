"""Any gymnasium environment as a task of the seam (``pip install "snn-neat[gym]"``).

``GymTask("CartPole-v1")`` makes one gymnasium environment per rollout row and steps them from
the seam: NEAT, weight search, plots and checkpoints then work on it like on a torch plant.
Gymnasium environments are Python objects stepped one at a time, so this path costs what the
environment costs (``benchmarks/gym_speed.py`` prints it beside a torch port through the seam);
write the plant in torch (``evolution.Task``) when speed matters.

How it maps onto the seam's functional protocol:

- The state of a row is ``[B, 3 + n_obs]`` float64: the episode's seed, the row's environment
  (-1 until the first step makes it), whether it is done, and the last observation.
  ``reset(E, generator)`` draws ``E`` seeds and the start observations (each episode's
  environment reset with its seed); the rollout copies each episode's state to every genome,
  so every genome faces the same starts, and the first ``step`` gives each row its own
  environment, reset with the same seed, so it starts where ``reset`` said.
- Observations are normalised by the seam over the observation space's bounds; infinite bounds
  (CartPole's velocities) must be given as ``observation_bounds``.
- Actions: a ``Discrete(n)`` space takes one continuous output in ``[-1, 1]`` split into ``n``
  equal bins (``n = 2``: push left below 0, right above); a ``Box`` space takes its shape's
  outputs, scaled to its symmetric bound.
- ``terminated or truncated`` ends an episode; fitness is the return.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from evolution.task import Task, TaskError

__all__ = ["GymTask"]

_SEED, _ENV, _DONE, _OBS = 0, 1, 2, 3  # state columns


def _gymnasium():
    try:
        import gymnasium
    except ImportError:
        raise ImportError('GymTask needs gymnasium: pip install "snn-neat[gym]"') from None
    return gymnasium


class GymTask(Task):
    """A gymnasium environment (``env_id``, made with ``gymnasium.make(env_id, **make_kwargs)``).

    Args:
        env_id: the registered id, e.g. ``"CartPole-v1"``, ``"Pendulum-v1"``.
        observation_bounds: ``(low, high)`` sequences replacing the observation space's bounds
            (needed where those are infinite).
        max_steps: episode length (default: the environment's ``max_episode_steps``, else 1000).
        control_period_s: network time per step (s; spiking controllers run
            ``control_period_s / dt`` substeps), default 0.02.
    """

    fitness = "return"

    def __init__(self, env_id: str, *, observation_bounds: tuple[Sequence[float], Sequence[float]] | None = None,
                 max_steps: int | None = None, control_period_s: float = 0.02, **make_kwargs) -> None:
        gym = _gymnasium()
        self.env_id, self.make_kwargs, self.name = env_id, make_kwargs, f"gym:{env_id}"
        probe = gym.make(env_id, **make_kwargs)
        obs_space, act_space = probe.observation_space, probe.action_space
        spec_steps = probe.spec.max_episode_steps if probe.spec is not None else None
        probe.close()
        if not isinstance(obs_space, gym.spaces.Box) or len(obs_space.shape) != 1:
            raise TaskError(f"task {self.name!r}: needs a flat Box observation space, got {obs_space}")
        low, high = (np.asarray(b, dtype=np.float64) for b in (observation_bounds or (obs_space.low, obs_space.high)))
        if low.shape != obs_space.shape or high.shape != obs_space.shape:
            raise TaskError(f"task {self.name!r}: observation_bounds must give {obs_space.shape[0]} lows and highs")
        infinite = [k for k in range(low.shape[0]) if not (math.isfinite(low[k]) and math.isfinite(high[k]))]
        if infinite:
            raise TaskError(f"task {self.name!r}: observation variables {infinite} have infinite bounds in "
                            f"{obs_space}; pass observation_bounds=(low, high)")
        self.observation_low, self.observation_high = tuple(low.tolist()), tuple(high.tolist())
        if isinstance(act_space, gym.spaces.Discrete):
            self.discrete, self.action_size, self.action_max = int(act_space.n), 1, 1.0
        elif isinstance(act_space, gym.spaces.Box) and len(act_space.shape) == 1 and \
                np.allclose(act_space.low, -act_space.high) and np.all(np.isfinite(act_space.high)):
            self.discrete, self.action_size = 0, int(act_space.shape[0])
            self.action_max = float(np.max(act_space.high))
            self._action_scale = act_space.high.astype(np.float64) / self.action_max
        else:
            raise TaskError(f"task {self.name!r}: needs a Discrete or symmetric, finite Box action space, "
                            f"got {act_space}")
        self.max_steps = int(max_steps if max_steps is not None else spec_steps or 1000)
        self.control_period_s = float(control_period_s)
        self._envs: list = []
        self.validate()

    def _make(self, seed: int):
        env = _gymnasium().make(self.env_id, **self.make_kwargs)
        obs, _ = env.reset(seed=seed)
        return env, np.asarray(obs, dtype=np.float64)

    def reset(self, batch: int, generator: torch.Generator | None = None, *, device: torch.device | str = "cpu",
              dtype: torch.dtype = torch.float32) -> Tensor:
        """``batch`` episodes: seeds drawn from ``generator`` (below 2**31), start observations."""
        for env in self._envs:  # a new rollout: the last one's environments are done with
            env.close()
        self._envs = []
        seeds = torch.randint(0, 2**31 - 1, (batch,), generator=generator, dtype=torch.int64)
        state = torch.zeros(batch, 3 + self.observation_size, dtype=torch.float64)
        state[:, _SEED], state[:, _ENV] = seeds.to(torch.float64), -1.0
        for k, seed in enumerate(seeds.tolist()):
            env, obs = self._make(seed)
            env.close()
            state[k, _OBS:] = torch.from_numpy(obs)
        return state.to(device)

    def _action(self, a: np.ndarray):
        if self.discrete:  # [-1, 1] in n equal bins
            return int(min(self.discrete - 1, max(0, math.floor((a[0] + 1.0) / 2.0 * self.discrete))))
        return (a * self._action_scale).astype(np.float32)

    def step(self, state: Tensor, action: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        new = state.detach().cpu().clone()
        actions = action.detach().cpu().to(torch.float64).numpy()
        reward = torch.zeros(new.shape[0], dtype=torch.float64)
        for r in range(new.shape[0]):  # gymnasium steps one environment at a time
            if new[r, _DONE] != 0:
                continue
            if new[r, _ENV] < 0:  # the row's first step: its own environment, from the episode's seed
                env, _ = self._make(int(new[r, _SEED]))
                self._envs.append(env)
                new[r, _ENV] = len(self._envs) - 1
            obs, rew, terminated, truncated, _ = self._envs[int(new[r, _ENV])].step(self._action(actions[r]))
            new[r, _OBS:] = torch.from_numpy(np.asarray(obs, dtype=np.float64))
            reward[r] = float(rew)
            if terminated or truncated:
                new[r, _DONE] = 1.0
        done = new[:, _DONE] != 0
        return new.to(state.device), reward.to(state.device), done.to(state.device)

    def observe(self, state: Tensor) -> Tensor:
        return state[:, _OBS:]
