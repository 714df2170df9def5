"""gymnasium's ``Pendulum-v1`` swing-up as a batched task of the seam, with a native step.

State ``[B, 2]`` = (theta (rad, 0 upright), theta_dot (rad/s)). Every control step of
``dt = 0.05`` s applies a torque ``u`` in [-2, 2] N m and costs ``normalize(theta)^2 + 0.1
theta_dot^2 + 0.001 u^2``; the reward is minus the cost, so a return of 0 is the best. The update
is gymnasium's (``gymnasium/envs/classic_control/pendulum.py``, g = 10 m/s^2, m = l = 1):
``theta_dot' = clip(theta_dot + (3 g / (2 l) sin(theta) + 3 / (m l^2) u) dt, -8, 8)``, ``theta' =
theta + theta_dot' dt``. Episodes start from theta uniform in [-pi, pi) and theta_dot in [-1, 1)
and never terminate: they are truncated at ``max_steps`` (gymnasium's ``TimeLimit``, 200).

Observations: cos(theta), sin(theta) and, unless ``observe_velocity=False``, theta_dot
(gymnasium's three). Without the velocity the controller must infer it from how the angle moves
(a memory task). ``tests/tasks/test_pendulum.py`` checks the port step by step against
gymnasium's own environment.
"""

from __future__ import annotations

import math
from pathlib import Path

import torch
from torch import Tensor

from evolution.task import NativeStep, Task
from snn_torch.functional.portable_math import sin_cos
from snn_torch.functional.scalars import scalars
from tasks.gym_adapter import Bounds, port_options

__all__ = ["PendulumTask", "PendulumNoVelocityTask", "pendulum_step", "angle_normalize"]

_CSRC = Path(__file__).resolve().parent / "csrc"
MAX_SPEED = 8.0  # rad/s
MAX_TORQUE = 2.0  # N m
DT_S = 0.05  # s


def angle_normalize(theta: Tensor) -> Tensor:
    """``theta`` (rad) wrapped into [-pi, pi): ``((theta + pi) mod 2 pi) - pi``, as gymnasium."""
    pi, two_pi = scalars((math.pi, 2.0 * math.pi), theta)
    return torch.remainder(theta + pi, two_pi) - pi


def pendulum_step(state: Tensor, torque: Tensor, *, g: float = 10.0) -> tuple[Tensor, Tensor]:
    """``(next_state [B, 2], reward [B])`` after one step of ``DT_S`` under ``torque`` (N m, ``[B]``,
    clipped to +-2): gymnasium's ``PendulumEnv.step`` in its order of operations and precision
    (the torque, and its terms ``3 u`` and ``0.001 u^2``, in float32 as gymnasium's action is)."""
    theta, theta_dot = state.unbind(-1)
    gain, dt, speed, c_speed = scalars((3.0 * g / 2.0, DT_S, MAX_SPEED, 0.1), state)
    # gymnasium's action is float32, and numpy keeps the torque's terms (3 u, 0.001 u^2) in it
    torque_max, inertia, c_torque = scalars((MAX_TORQUE, 3.0, 0.001), torque.to(torch.float32))
    u = torch.clamp(torque.to(torch.float32), -torque_max, torque_max)
    push, effort = (inertia * u).to(state.dtype), (c_torque * (u * u)).to(state.dtype)
    wrapped = angle_normalize(theta)
    cost = wrapped * wrapped + c_speed * (theta_dot * theta_dot) + effort
    sin, _ = sin_cos(theta)
    new_dot = torch.clamp(theta_dot + (gain * sin + push) * dt, -speed, speed)
    return torch.stack([theta + new_dot * dt, new_dot], -1), -cost


class PendulumTask(Task):
    """``Pendulum-v1``: swing a pendulum up from any angle and hold it (module docstring).

    Args:
        observe_velocity: observe theta_dot (gymnasium's observation) or only cos and sin.
        max_steps: episode length (control steps of 0.05 s; gymnasium's time limit: 200).
        g: gravity (m/s^2; gymnasium's default 10).
        control_period_s: network time per control step (s; spiking controllers run
            ``control_period_s / dt`` substeps); default gymnasium's dt, 0.05 s. The plant always
            advances 0.05 s.
        observation_bounds: ``(low, high)`` of the observed values replacing gymnasium's (+-1 for
            cos and sin, +-8 rad/s for theta_dot).
    """

    action_size = 1
    action_max = MAX_TORQUE
    fitness = "return"

    def __init__(self, *, observe_velocity: bool = True, max_steps: int = 200, g: float = 10.0,
                 control_period_s: float = DT_S, observation_bounds: Bounds | None = None) -> None:
        if not (isinstance(g, (int, float)) and math.isfinite(g) and g > 0) or isinstance(g, bool):
            raise ValueError(f"PendulumTask.g must be a positive finite number (m/s^2), got {g!r}")
        n_obs = 3 if observe_velocity else 2
        default = ((-1.0, -1.0, -MAX_SPEED)[:n_obs], (1.0, 1.0, MAX_SPEED)[:n_obs])
        self.observation_low, self.observation_high, self.max_steps, self.control_period_s = port_options(
            "PendulumTask", observation_bounds, default, max_steps, control_period_s)
        self.observe_velocity, self.g = bool(observe_velocity), float(g)
        self.name = "pendulum" if observe_velocity else "pendulum-no-velocity"
        # the same step in C (tasks/csrc/pendulum.c), for whole episodes in one native call
        self.native = NativeStep(_CSRC / "pendulum.c", "pendulum", 2, params=(
            3.0 * self.g / 2.0, 3.0, DT_S, MAX_SPEED, MAX_TORQUE, 0.1, 0.001, math.pi, 2.0 * math.pi,
            float(self.observe_velocity)))
        self.validate()

    def reset(self, batch: int, generator: torch.Generator, *, device: torch.device | str = "cpu",
              dtype: torch.dtype = torch.float32) -> Tensor:
        high = torch.tensor([math.pi, 1.0], dtype=torch.float64)
        state = (torch.rand(batch, 2, generator=generator, dtype=torch.float64) * 2.0 - 1.0) * high
        return state.to(device=device, dtype=dtype)

    def step(self, state: Tensor, action: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        moved, reward = pendulum_step(state, action[:, 0], g=self.g)
        return moved, reward, torch.zeros(state.shape[0], dtype=torch.bool, device=state.device)

    def observe(self, state: Tensor) -> Tensor:
        sin, cos = sin_cos(state[:, 0])
        parts = [cos, sin, state[:, 1]] if self.observe_velocity else [cos, sin]
        return torch.stack(parts, -1)


class PendulumNoVelocityTask(PendulumTask):
    """``Pendulum-v1`` observing only cos(theta) and sin(theta): the controller must infer the
    velocity from how the angle moves (a memory task). Constructible with no arguments, so
    ``snn-neat evolve tasks.pendulum:PendulumNoVelocityTask`` runs it; its threshold is -400 (a
    mean return over 100 episodes; with the velocity observed, gymnasium's criterion is -200)."""

    reward_threshold = -400.0

    def __init__(self, *, max_steps: int = 200, g: float = 10.0, control_period_s: float = DT_S,
                 observation_bounds: Bounds | None = None) -> None:
        super().__init__(observe_velocity=False, max_steps=max_steps, g=g, control_period_s=control_period_s,
                         observation_bounds=observation_bounds)
