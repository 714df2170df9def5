"""The cart-pole of Qiu et al. (2019), eqs. (6)-(8), after Barto et al. (1983), batched.

State ``[..., 4]`` = (x (m), x_dot (m/s), theta (rad), theta_dot (rad/s)) for any batch
shape, float32 or float64, any device. Frictionless, explicit Euler exactly as the paper
writes it (every update uses the old state), force ``F`` in N.

``CartPoleTask`` is the plant as an ``evolution.task.Task``: the paper's two tasks are
``CartPoleTask.nonmarkov()`` (Table II: x and theta observed, tau 0.01 s, 5000 steps) and
``CartPoleTask.markov()`` (Table I: all four variables, tau 0.02 s, 100,000 steps). Fitness:
control steps balanced.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import Tensor

from evolution.task import NativeStep, Task
from snn_torch.functional.portable_math import sin_cos
from snn_torch.functional.scalars import scalars

__all__ = ["CartPoleParams", "DEFAULT_PLANT", "PlantError", "cartpole_step", "cartpole_failed", "check_state", "X", "X_DOT",
           "THETA", "THETA_DOT", "CartPoleTask", "X_DOT_LIMIT", "THETA_DOT_LIMIT", "THETA0_RAD"]

X, X_DOT, THETA, THETA_DOT = 0, 1, 2, 3
_CSRC = Path(__file__).resolve().parent / "csrc"


class PlantError(FloatingPointError):
    """The plant produced NaN or inf; the message lists the offending batch indices."""


@dataclass(frozen=True)
class CartPoleParams:
    """Physical constants and failure limits (SI units)."""

    gravity: float = 9.8  # m/s^2
    cart_mass: float = 1.0  # kg
    pole_mass: float = 0.1  # kg
    half_length: float = 0.5  # m, l in the paper
    x_limit: float = 2.4  # m, track half-length
    theta_limit: float = 12.0 * math.pi / 180.0  # rad

    def __post_init__(self) -> None:
        for name in ("gravity", "cart_mass", "pole_mass", "half_length", "x_limit", "theta_limit"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"CartPoleParams.{name} must be a positive finite number, got {value!r}")


DEFAULT_PLANT = CartPoleParams()


def cartpole_step(state: Tensor, force: Tensor, tau: float, p: CartPoleParams = DEFAULT_PLANT) -> Tensor:
    """One explicit-Euler step of ``tau`` seconds under ``force`` (N, shape ``state.shape[:-1]``).

    Eqs. (6)-(8) of [Qiu19], each new value from the old state: ``s' = s + tau * ds/dt``.
    """
    x, x_dot, theta, theta_dot = state.unbind(-1)
    total = p.cart_mass + p.pole_mass
    # The constants as cached 0-dim tensors: the same bits as Python floats (rounded to the
    # state's dtype either way), at half the cost per op on a small batch.
    mpl, neg_total, pos_total, gravity, half_length, four_thirds, mass_ratio, tau_t = scalars(
        (p.pole_mass * p.half_length, -total, total, p.gravity, p.half_length, 4.0 / 3.0, p.pole_mass / total,
         float(tau)), state)
    sin, cos = sin_cos(theta)  # one definition for torch and the native step (portable_math)
    w2_sin = theta_dot * theta_dot * sin
    temp = (force + mpl * w2_sin) / neg_total  # = (-F - m l w^2 sin) / (m_c + m)
    theta_acc = (gravity * sin + cos * temp) / (half_length * (four_thirds - mass_ratio * (cos * cos)))
    x_acc = (force + mpl * (w2_sin - theta_acc * cos)) / pos_total
    return state + torch.stack([x_dot, x_acc, theta_dot, theta_acc], -1) * tau_t


def cartpole_failed(state: Tensor, p: CartPoleParams = DEFAULT_PLANT) -> Tensor:
    """True where the cart left the track or the pole fell past the limit."""
    limits = _scalar_limits(p, state)
    return (state.abs() > limits).any(-1)


_LIMITS: dict[tuple, Tensor] = {}


def _scalar_limits(p: CartPoleParams, like: Tensor) -> Tensor:
    key = (p.x_limit, p.theta_limit, like.dtype, like.device)
    t = _LIMITS.get(key)
    if t is None:  # velocities are unlimited
        t = _LIMITS[key] = torch.tensor([p.x_limit, math.inf, p.theta_limit, math.inf], dtype=like.dtype,
                                        device=like.device)
    return t


def check_state(state: Tensor, where: str = "cart-pole state") -> None:
    """Raise ``PlantError`` listing batch indices whose state holds NaN or inf."""
    bad = ~torch.isfinite(state).all(-1)
    if bool(bad.any()):
        idx = torch.nonzero(bad)[:10].tolist()
        raise PlantError(f"{where} holds NaN or inf at {int(bad.sum())} batch index/indices, first: {idx}")


# Observation bounds of the velocities for the Markov task. The paper gives none; these cover
# what a balancing cart-pole reaches (values beyond saturate).
X_DOT_LIMIT = 1.5  # m/s
THETA_DOT_LIMIT = 2.0  # rad/s
THETA0_RAD = math.radians(3.0)  # [Qiu19] Table II's start angle (used for Table I too: the paper gives none)


class CartPoleTask(Task):
    """The cart-pole as a task: start at rest with theta = ``theta0_rad``, push with a force in
    ``[-10, 10]`` N every ``tau_s`` seconds, fail when ``|x| > x_limit`` or ``|theta| > theta_limit``.

    Args:
        observe: indices of the state variables the controller sees (``X, THETA``: non-Markov).
        tau_s: control period (s); max_steps: episode length (success).
        plant: physical constants and limits; theta0_rad: start angle (rad).
        name: the task's name in errors and reports.

    Reward 1 for every step that does not fail; fitness: steps balanced.
    """

    fitness = "steps"
    action_size = 1
    action_max = 10.0  # N, [Qiu19]

    def __init__(self, observe: tuple[int, ...] = (X, THETA), *, tau_s: float = 0.01, max_steps: int = 5000,
                 plant: CartPoleParams = DEFAULT_PLANT, theta0_rad: float = THETA0_RAD,
                 name: str = "cartpole") -> None:
        limits = {X: plant.x_limit, X_DOT: X_DOT_LIMIT, THETA: plant.theta_limit, THETA_DOT: THETA_DOT_LIMIT}
        if not observe or any(k not in limits for k in observe):
            raise ValueError(f"observe must list state indices in 0..3, got {observe!r}")
        self.observe_idx = tuple(observe)
        self.observation_low = tuple(-limits[k] for k in observe)
        self.observation_high = tuple(limits[k] for k in observe)
        self.control_period_s, self.max_steps, self.plant = float(tau_s), int(max_steps), plant
        self.theta0_rad, self.name = float(theta0_rad), name
        self._columns: dict[torch.device, Tensor] = {}
        # the same step in C (tasks/csrc/cartpole.c), for whole episodes in one native call
        self.native = NativeStep(_CSRC / "cartpole.c", "cartpole", 4, params=(
            plant.gravity, plant.cart_mass, plant.pole_mass, plant.half_length, plant.x_limit, plant.theta_limit,
            self.control_period_s, len(self.observe_idx), *self.observe_idx))
        self.validate()

    @classmethod
    def nonmarkov(cls, **kwargs) -> CartPoleTask:
        """[Qiu19] Table II: x and theta observed, tau 0.01 s, success at 5000 steps."""
        return cls((X, THETA), **{"tau_s": 0.01, "max_steps": 5000, "name": "cartpole-nonmarkov", **kwargs})

    @classmethod
    def markov(cls, **kwargs) -> CartPoleTask:
        """[Qiu19] Table I: all four variables observed, tau 0.02 s, success at 100,000 steps."""
        return cls((X, X_DOT, THETA, THETA_DOT), **{"tau_s": 0.02, "max_steps": 100_000, "name": "cartpole-markov",
                                                   **kwargs})

    def reset(self, batch: int, generator: torch.Generator | None = None, *, device: torch.device | str = "cpu",
              dtype: torch.dtype = torch.float32) -> Tensor:
        state = torch.zeros(batch, 4, device=device, dtype=dtype)
        state[:, THETA] = self.theta0_rad
        return state

    def step(self, state: Tensor, action: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        moved = cartpole_step(state, action[:, 0].to(state.dtype), self.control_period_s, self.plant)
        failed = cartpole_failed(moved, self.plant)
        return moved, (~failed).to(state.dtype), failed

    def observe(self, state: Tensor) -> Tensor:
        if self.observe_idx == (X, X_DOT, THETA, THETA_DOT):
            return state
        cols = self._columns.get(state.device)
        if cols is None:
            cols = self._columns[state.device] = torch.tensor(self.observe_idx, device=state.device)
        return state.index_select(-1, cols)
