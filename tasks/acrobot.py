"""gymnasium's ``Acrobot-v1`` as a batched task of the seam, with a native step.

State ``[B, 4]`` = (theta1, theta2 (rad; theta1 0 hanging down, theta2 relative to the first
link), dtheta1, dtheta2 (rad/s)), float32 or float64. gymnasium's ``AcrobotEnv.step``
(``gymnasium/envs/classic_control/acrobot.py``, the book's dynamics, its default): two links of
1 m and 1 kg (centres of mass at 0.5 m, moments of inertia 1 kg m^2), g = 9.8 m/s^2, a torque
of -1, 0 or +1 N m on the joint between them, integrated by gymnasium's ``rk4`` over dt = 0.2 s;
then the angles are wrapped into [-pi, pi] by gymnasium's ``wrap`` (the same subtractions of
2 pi) and the velocities bounded to +-4 pi and +-9 pi rad/s. The episode terminates when the
free end is a link's length above the pivot, ``-cos(theta1) - cos(theta2 + theta1) > 1``; the
reward is -1 per step and 0 on the terminating step; episodes are truncated at ``max_steps``
(gymnasium's ``TimeLimit``, 500). Episodes start from each variable uniform in [-0.1, 0.1),
rounded to float32 as gymnasium's start state is (its first step then promotes to float64).

The discrete action comes from the controller's output in [-1, 1] in three equal bins
(``tasks.gym_adapter.discrete_action``, ``GymTask``'s bins), in torch and in C alike. The
observation is gymnasium's: cos theta1, sin theta1, cos theta2, sin theta2, dtheta1, dtheta2,
rounded to float32 as ``AcrobotEnv`` returns them (gymnasium computes the start's in float32, from
its float32 start; the port computes every one in float64, so that one can be a float32 ulp
off); its bounds are gymnasium's observation space's (the velocity bounds as its float32
values). Squares are products (``x * x``) where
gymnasium's scalar ``x**2`` calls the C library's ``pow``, and sin and cos are
``portable_math``'s: each can differ from numpy's by an ulp, which the chaotic swing can grow
over an episode (``tests/tasks/test_classic_control.py`` says how closely the port follows
gymnasium's own environment).
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

__all__ = ["AcrobotTask", "acrobot_step", "acrobot_dsdt", "wrap", "WRAP_TURNS"]

_CSRC = Path(__file__).resolve().parent / "csrc"
DT_S = 0.2  # s, gymnasium's AcrobotEnv.dt
M1 = M2 = 1.0  # kg
L1 = 1.0  # m
LC1 = LC2 = 0.5  # m, centres of mass
I1 = I2 = 1.0  # kg m^2
G = 9.8  # m/s^2
MAX_VEL_1, MAX_VEL_2 = 4 * math.pi, 9 * math.pi  # rad/s
# _dsdt's constant factors, combined as Python evaluates its expressions (left to right)
_DSDT = (
    M1 * LC1**2,  # d1: m1 lc1^2 + m2 (l1^2 + lc2^2 + 2 l1 lc2 cos theta2) + I1 + I2
    M2, L1**2 + LC2**2, 2 * L1 * LC2, I1, I2,
    LC2**2, L1 * LC2,  # d2: m2 (lc2^2 + l1 lc2 cos theta2) + I2
    M2 * LC2 * G, math.pi / 2.0,  # phi2: m2 lc2 g cos(theta1 + theta2 - pi/2)
    -M2 * L1 * LC2, 2 * M2 * L1 * LC2, (M1 * LC1 + M2 * L1) * G,  # phi1's three terms
    M2 * L1 * LC2, M2 * LC2**2 + I2,  # ddtheta2 (the book's)
)
# observation bounds: gymnasium's space (float32, so 4 pi and 9 pi as their float32 values)
_F32 = torch.tensor([MAX_VEL_1, MAX_VEL_2], dtype=torch.float32).tolist()
DEFAULT_BOUNDS = ((-1.0, -1.0, -1.0, -1.0, -_F32[0], -_F32[1]), (1.0, 1.0, 1.0, 1.0, _F32[0], _F32[1]))
# gymnasium's wrap loops until the angle is in range; the port takes at most this many turns each
# way (|x| up to about 129 pi; one step from a state inside the velocity bounds reaches under
# 10 pi, sampled), so a runaway value cannot loop for ever
WRAP_TURNS = 64


def wrap(x: Tensor, low: Tensor, high: Tensor) -> Tensor:
    """gymnasium's ``wrap``: subtract ``high - low`` while ``x > high``, then add it while
    ``x < low``, each value the same roundings as its loop (at most ``WRAP_TURNS`` turns each;
    each turn asks whether any value is still out of range, a host sync on CUDA)."""
    diff = high - low
    for _ in range(WRAP_TURNS):
        above = x > high
        if not bool(above.any()):
            break
        x = torch.where(above, x - diff, x)
    for _ in range(WRAP_TURNS):
        below = x < low
        if not bool(below.any()):
            break
        x = torch.where(below, x + diff, x)
    return x


def acrobot_dsdt(y: Tensor, torque: Tensor) -> Tensor:
    """``AcrobotEnv._dsdt`` (book dynamics) of states ``y`` ``[B, 4]`` under ``torque`` (N m,
    ``[B]``): ``[B, 4]`` = (dtheta1, dtheta2, ddtheta1, ddtheta2), gymnasium's operations in
    its order (constant factors folded as Python folds them)."""
    theta1, theta2, dtheta1, dtheta2 = y.unbind(-1)
    (m1_lc1_sq, m2, l1_sq_lc2_sq, two_l1_lc2, i1, i2, lc2_sq, l1_lc2, m2_lc2_g, half_pi, c_phi1_a, c_phi1_b,
     c_phi1_c, c_dd2, c_den) = scalars(_DSDT, y)
    # sin and cos of the three angles _dsdt uses, in one call
    sin, cos = sin_cos(torch.stack([theta2, theta1 + theta2 - half_pi, theta1 - half_pi], -1))
    sin2, cos2, cos_phi2, cos_phi1 = sin[:, 0], cos[:, 0], cos[:, 1], cos[:, 2]
    d1 = m1_lc1_sq + m2 * (l1_sq_lc2_sq + two_l1_lc2 * cos2) + i1 + i2
    d2 = m2 * (lc2_sq + l1_lc2 * cos2) + i2
    phi2 = m2_lc2_g * cos_phi2
    phi1 = (c_phi1_a * (dtheta2 * dtheta2) * sin2 - c_phi1_b * dtheta2 * dtheta1 * sin2
            + c_phi1_c * cos_phi1 + phi2)
    ddtheta2 = (torque + d2 / d1 * phi1 - c_dd2 * (dtheta1 * dtheta1) * sin2 - phi2) / (c_den - d2 * d2 / d1)
    ddtheta1 = -(d2 * ddtheta2 + phi1) / d1
    return torch.stack([dtheta1, dtheta2, ddtheta1, ddtheta2], -1)


def acrobot_step(state: Tensor, torque: Tensor) -> tuple[Tensor, Tensor]:
    """``(next_state [B, 4], terminated [B])`` after one step of 0.2 s under ``torque`` (N m,
    ``[B]``): gymnasium's ``rk4`` (``y0 + dt / 6 (k1 + 2 k2 + 2 k3 + k4)``), ``wrap`` and
    ``bound``, then its terminal test on the new state."""
    dt, dt2, dt6, two, pi, neg_pi, one, v1, neg_v1, v2, neg_v2 = scalars(
        (DT_S, DT_S / 2.0, DT_S / 6.0, 2.0, math.pi, -math.pi, 1.0, MAX_VEL_1, -MAX_VEL_1, MAX_VEL_2, -MAX_VEL_2), state)
    k1 = acrobot_dsdt(state, torque)
    k2 = acrobot_dsdt(state + dt2 * k1, torque)
    k3 = acrobot_dsdt(state + dt2 * k2, torque)
    k4 = acrobot_dsdt(state + dt * k3, torque)
    moved = state + dt6 * (k1 + two * k2 + two * k3 + k4)
    angles = wrap(moved[:, :2], neg_pi, pi)
    # bound: min(max(x, m), M)
    speed1 = torch.minimum(torch.maximum(moved[:, 2], neg_v1), v1)
    speed2 = torch.minimum(torch.maximum(moved[:, 3], neg_v2), v2)
    _, cos = sin_cos(torch.stack([angles[:, 0], angles[:, 1] + angles[:, 0]], -1))
    terminated = -cos[:, 0] - cos[:, 1] > one
    return torch.stack([angles[:, 0], angles[:, 1], speed1, speed2], -1), terminated


class AcrobotTask(Task):
    """``Acrobot-v1``: swing the free end of a two-link chain above a line (module docstring).

    Args:
        observation_bounds: ``(low, high)`` of the six observed values replacing gymnasium's
            (+-1 for the four cosines and sines, +-4 pi and +-9 pi rad/s).
        max_steps: episode length (control steps of 0.2 s; gymnasium's time limit: 500).
        control_period_s: network time per control step (s; spiking controllers run
            ``control_period_s / dt`` substeps); default gymnasium's dt, 0.2 s. The plant always
            advances 0.2 s.
    """

    name = "Acrobot-v1"
    action_size = 1
    action_max = 1.0  # one output in [-1, 1], binned into gymnasium's three torques
    discrete = 3  # gymnasium's Discrete(3), as GymTask's attribute
    fitness = "return"

    def __init__(self, *, observation_bounds: Bounds | None = None, max_steps: int = 500,
                 control_period_s: float = DT_S) -> None:
        self.observation_low, self.observation_high, self.max_steps, self.control_period_s = port_options(
            type(self).__name__, observation_bounds, DEFAULT_BOUNDS, max_steps, control_period_s)
        # the same step in C (tasks/csrc/acrobot.c), for whole episodes in one native call
        self.native = NativeStep(_CSRC / "acrobot.c", "acrobot", 4, params=(
            DT_S, DT_S / 2.0, DT_S / 6.0, math.pi, MAX_VEL_1, MAX_VEL_2, float(WRAP_TURNS), *_DSDT))
        self.validate()

    def reset(self, batch: int, generator: torch.Generator, *, device: torch.device | str = "cpu",
              dtype: torch.dtype = torch.float32) -> Tensor:
        # numpy's uniform(-0.1, 0.1) (low + (high - low) U[0, 1)), then gymnasium's astype(float32)
        u = torch.rand(batch, 4, generator=generator, dtype=torch.float64)
        return (-0.1 + 0.2 * u).to(torch.float32).to(device=device, dtype=dtype)

    def step(self, state: Tensor, action: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        torque = discrete_action(action, 3).to(state.dtype) - scalars((1.0,), state)[0]  # -1, 0 or +1 N m
        moved, terminated = acrobot_step(state, torque)
        reward = torch.where(terminated, scalars((0.0,), state)[0], scalars((-1.0,), state)[0])
        return moved, reward, terminated

    def observe(self, state: Tensor) -> Tensor:
        sin, cos = sin_cos(state[:, :2])
        obs = torch.stack([cos[:, 0], sin[:, 0], cos[:, 1], sin[:, 1], state[:, 2], state[:, 3]], -1)
        return obs.to(torch.float32).to(state.dtype)  # gymnasium's observation is float32
