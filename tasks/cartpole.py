"""The cart-pole of Qiu et al. (2019), eqs. (6)-(8), after Barto et al. (1983), batched.

State ``[..., 4]`` = (x (m), x_dot (m/s), theta (rad), theta_dot (rad/s)) for any batch
shape, float32 or float64, any device. Frictionless, explicit Euler exactly as the paper
writes it (every update uses the old state), force ``F`` in N.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["CartPoleParams", "DEFAULT_PLANT", "PlantError", "cartpole_step", "cartpole_failed", "check_state", "X", "X_DOT",
           "THETA", "THETA_DOT"]

X, X_DOT, THETA, THETA_DOT = 0, 1, 2, 3


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
    """One explicit-Euler step of ``tau`` seconds under ``force`` (N, shape ``state.shape[:-1]``)."""
    x, x_dot, theta, theta_dot = state.unbind(-1)
    total = p.cart_mass + p.pole_mass
    sin, cos = torch.sin(theta), torch.cos(theta)
    temp = (-force - p.pole_mass * p.half_length * theta_dot * theta_dot * sin) / total
    theta_acc = (p.gravity * sin + cos * temp) / (p.half_length * (4.0 / 3.0 - p.pole_mass * cos * cos / total))
    x_acc = (force + p.pole_mass * p.half_length * (theta_dot * theta_dot * sin - theta_acc * cos)) / total
    return torch.stack([x + tau * x_dot, x_dot + tau * x_acc, theta + tau * theta_dot, theta_dot + tau * theta_acc], -1)


def cartpole_failed(state: Tensor, p: CartPoleParams = DEFAULT_PLANT) -> Tensor:
    """True where the cart left the track or the pole fell past the limit."""
    return (state[..., X].abs() > p.x_limit) | (state[..., THETA].abs() > p.theta_limit)


def check_state(state: Tensor, where: str = "cart-pole state") -> None:
    """Raise ``PlantError`` listing batch indices whose state holds NaN or inf."""
    bad = ~torch.isfinite(state).all(-1)
    if bool(bad.any()):
        idx = torch.nonzero(bad)[:10].tolist()
        raise PlantError(f"{where} holds NaN or inf at {int(bad.sum())} batch index/indices, first: {idx}")
