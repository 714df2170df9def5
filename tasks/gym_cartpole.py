"""gymnasium's ``CartPole-v1`` as a batched task of the seam, with a native step.

State ``[B, 4]`` = (x (m), x_dot (m/s), theta (rad, 0 upright), theta_dot (rad/s)), float32 or
float64. gymnasium's ``CartPoleEnv.step`` (``gymnasium/envs/classic_control/cartpole.py``; Barto,
Sutton & Anderson's cart-pole, g = 9.8 m/s^2, cart 1 kg, pole 0.1 kg, half length 0.5 m):
a force of -10 N (action 0) or +10 N (action 1), the accelerations from the old state, then one
explicit Euler step of tau = 0.02 s (every update from the old state). The episode terminates
when ``|x| > 2.4`` m or ``|theta| > 12`` degrees; the reward is 1 for every step, the
terminating one included; episodes are truncated at ``max_steps`` (gymnasium's ``TimeLimit``,
500). Episodes start from each variable uniform in [-0.05, 0.05).

Unlike ``tasks.cartpole.CartPoleTask`` (Qiu et al.'s plant: a continuous force, fitness in
steps) this is gymnasium's environment exactly: the discrete action comes from the controller's
output in [-1, 1] binned as ``GymTask`` bins it (``tasks.gym_adapter.discrete_action``: push
left below 0, right from 0), in torch and in C alike; the observation is gymnasium's (the state
rounded to float32, as ``CartPoleEnv`` returns it); fitness is the return.

Observation bounds (for the controller's input coding): x and theta as gymnasium's space gives
them (+-4.8 m, +-24 degrees: twice the termination limits, as float32 values); the velocities, infinite in
gymnasium's space, +-3.0 m/s and +-3.5 rad/s by default (what a balancing cart-pole stays in;
values beyond saturate), as ``benchmarks/gym_speed.py`` and ``experiments/gym_evolve.py`` give
``GymTask``. ``tests/tasks/test_classic_control.py`` checks the port against gymnasium's own
environment.
"""

from __future__ import annotations

import math
from pathlib import Path

import torch
from torch import Tensor

from evolution.task import NativeStep, Task
from snn_torch.functional.portable_math import sin_cos
from snn_torch.functional.scalars import scalars
from tasks.gym_adapter import Bounds, discrete_action, port_options

__all__ = ["GymCartPoleTask", "gym_cartpole_step"]

_CSRC = Path(__file__).resolve().parent / "csrc"
# gymnasium's CartPoleEnv constants, combined as its step combines them (Python floats)
GRAVITY, MASS_CART, MASS_POLE, HALF_LENGTH = 9.8, 1.0, 0.1, 0.5  # m/s^2, kg, kg, m
TOTAL_MASS = MASS_POLE + MASS_CART  # kg
POLEMASS_LENGTH = MASS_POLE * HALF_LENGTH  # kg m
FORCE_MAG, TAU_S = 10.0, 0.02  # N, s
X_LIMIT = 2.4  # m
THETA_LIMIT = 12 * 2 * math.pi / 360  # rad, as gymnasium writes it
# observation bounds: gymnasium's space for x and theta (its float32 values), chosen ones for the velocities
_F32 = torch.tensor([2 * X_LIMIT, 2 * THETA_LIMIT], dtype=torch.float32).tolist()
DEFAULT_BOUNDS = ((-_F32[0], -3.0, -_F32[1], -3.5), (_F32[0], 3.0, _F32[1], 3.5))


def gym_cartpole_step(state: Tensor, push_right: Tensor) -> tuple[Tensor, Tensor]:
    """``(next_state [B, 4], terminated [B])`` after one step under ``push_right`` (``[B]`` bool:
    +10 N, else -10 N): ``CartPoleEnv.step`` in its order of operations (numpy's float64 when the
    state is float64; sin and cos from ``portable_math``)."""
    x, x_dot, theta, theta_dot = state.unbind(-1)
    f_mag, f_neg, pml, total, gravity, length, four_thirds, m_pole, tau, x_lim, th_lim = scalars(
        (FORCE_MAG, -FORCE_MAG, POLEMASS_LENGTH, TOTAL_MASS, GRAVITY, HALF_LENGTH, 4.0 / 3.0, MASS_POLE, TAU_S,
         X_LIMIT, THETA_LIMIT), state)
    force = torch.where(push_right, f_mag, f_neg)
    sin, cos = sin_cos(theta)
    temp = (force + pml * (theta_dot * theta_dot) * sin) / total
    theta_acc = (gravity * sin - cos * temp) / (length * (four_thirds - m_pole * (cos * cos) / total))
    x_acc = temp - pml * theta_acc * cos / total
    # explicit Euler: every update from the old state
    moved = torch.stack([x + tau * x_dot, x_dot + tau * x_acc, theta + tau * theta_dot, theta_dot + tau * theta_acc], -1)
    x, theta = moved[:, 0], moved[:, 2]
    terminated = (x < -x_lim) | (x > x_lim) | (theta < -th_lim) | (theta > th_lim)
    return moved, terminated


class GymCartPoleTask(Task):
    """``CartPole-v1``: balance the pole by pushing the cart left or right (module docstring).

    Args:
        observation_bounds: ``(low, high)`` of (x, x_dot, theta, theta_dot) replacing the
            defaults (+-4.8 m, +-3.0 m/s, +-24 degrees, +-3.5 rad/s).
        max_steps: episode length (control steps of 0.02 s; gymnasium's time limit: 500).
        control_period_s: network time per control step (s; spiking controllers run
            ``control_period_s / dt`` substeps); default gymnasium's tau, 0.02 s. The plant always
            advances 0.02 s.
    """

    name = "CartPole-v1"
    action_size = 1
    action_max = 1.0  # one output in [-1, 1], binned into gymnasium's two actions
    discrete = 2  # gymnasium's Discrete(2), as GymTask's attribute
    fitness = "return"

    def __init__(self, *, observation_bounds: Bounds | None = None, max_steps: int = 500,
                 control_period_s: float = TAU_S) -> None:
        self.observation_low, self.observation_high, self.max_steps, self.control_period_s = port_options(
            type(self).__name__, observation_bounds, DEFAULT_BOUNDS, max_steps, control_period_s)
        # the same step in C (tasks/csrc/gym_cartpole.c), for whole episodes in one native call
        self.native = NativeStep(_CSRC / "gym_cartpole.c", "gym_cartpole", 4, params=(
            FORCE_MAG, POLEMASS_LENGTH, TOTAL_MASS, GRAVITY, HALF_LENGTH, MASS_POLE, TAU_S, X_LIMIT, THETA_LIMIT))
        self.validate()

    def reset(self, batch: int, generator: torch.Generator, *, device: torch.device | str = "cpu",
              dtype: torch.dtype = torch.float32) -> Tensor:
        # numpy's uniform(low, high) is low + (high - low) * U[0, 1)
        u = torch.rand(batch, 4, generator=generator, dtype=torch.float64)
        return (-0.05 + 0.1 * u).to(device=device, dtype=dtype)

    def step(self, state: Tensor, action: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        moved, terminated = gym_cartpole_step(state, discrete_action(action, 2) == 1.0)
        return moved, torch.ones_like(state[:, 0]), terminated  # 1 per step, the terminating one too

    def observe(self, state: Tensor) -> Tensor:
        return state.to(torch.float32).to(state.dtype)  # gymnasium returns the state as float32
