"""Spike thresholds: a Heaviside step forward, a surrogate derivative backward.

A spike is ``x >= 0`` where ``x = v - v_peak`` (mV). The step has zero derivative almost
everywhere, so training by backpropagation replaces it in the backward pass with the
derivative of a smooth primitive (Neftci, Mostafa & Zenke 2019). Each surrogate here is a
pair: a smooth primitive (a pure, differentiable function, so ``gradcheck`` applies to it)
and an ``autograd.Function`` whose forward is the step and whose backward is exactly the
primitive's derivative.

Spike functions are built by factories in the snnTorch style, so a user can pass any
``Callable[[Tensor], Tensor]``::

    spike_fn = fast_sigmoid(slope=5.0)
    z = spike_fn(v - 30.0)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from torch import Tensor

SpikeFn = Callable[[Tensor], Tensor]

__all__ = [
    "SpikeFn",
    "heaviside",
    "fast_sigmoid",
    "superspike",
    "fast_sigmoid_primitive",
    "triangle",
    "triangle_primitive",
    "FastSigmoidSpike",
    "TriangleSpike",
]


def heaviside(x: Tensor) -> Tensor:
    """Spike where ``x >= 0``, in ``x``'s dtype; no gradient flows through it."""
    return (x >= 0).to(x.dtype)


def fast_sigmoid_primitive(x: Tensor, slope: float) -> Tensor:
    """Smooth primitive of the SuperSpike / fast-sigmoid surrogate.

    ``s(x) = x / (1 + slope |x|)``, so ``s'(x) = 1 / (1 + slope |x|)^2``, the derivative
    SuperSpike (Zenke & Ganguli 2018) uses. ``slope`` is in 1/mV when ``x`` is in mV.
    """
    return x / (1.0 + slope * x.abs())


class FastSigmoidSpike(torch.autograd.Function):
    """Heaviside forward, ``1 / (1 + slope |x|)^2`` backward."""

    @staticmethod
    def forward(x: Tensor, slope: float) -> Tensor:  # type: ignore[override]
        return heaviside(x)

    @staticmethod
    def setup_context(ctx: Any, inputs: tuple, output: Tensor) -> None:
        x, slope = inputs
        ctx.save_for_backward(x)
        ctx.slope = slope

    @staticmethod
    def backward(ctx: Any, grad_output: Tensor) -> tuple[Tensor, None]:  # type: ignore[override]
        (x,) = ctx.saved_tensors
        return grad_output / (1.0 + ctx.slope * x.abs()) ** 2, None


def triangle_primitive(x: Tensor, width: float) -> Tensor:
    """Smooth-almost-everywhere primitive of the triangle surrogate.

    Its derivative is ``max(0, 1 - |x| / width) / width`` (a unit-area triangle of half-width
    ``width`` mV around the threshold; Bellec et al. 2018 use its unnormalised form).
    """
    y = x.clamp(-width, width)
    return (y - y * y.abs() / (2.0 * width)) / width


class TriangleSpike(torch.autograd.Function):
    """Heaviside forward, ``max(0, 1 - |x| / width) / width`` backward."""

    @staticmethod
    def forward(x: Tensor, width: float) -> Tensor:  # type: ignore[override]
        return heaviside(x)

    @staticmethod
    def setup_context(ctx: Any, inputs: tuple, output: Tensor) -> None:
        x, width = inputs
        ctx.save_for_backward(x)
        ctx.width = width

    @staticmethod
    def backward(ctx: Any, grad_output: Tensor) -> tuple[Tensor, None]:  # type: ignore[override]
        (x,) = ctx.saved_tensors
        w = ctx.width
        return grad_output * (1.0 - x.abs() / w).clamp_min(0.0) / w, None


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not value > 0.0 or value == float("inf"):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return value


def fast_sigmoid(slope: float = 5.0) -> SpikeFn:
    """SuperSpike / fast-sigmoid spike function.

    Args:
        slope: steepness of the surrogate in 1/mV (applied to ``v - v_peak`` in mV). The
            default 5/mV keeps a usable gradient a few mV below the 30 mV peak, where an
            Izhikevich neuron's upstroke spends a sub-step before crossing.
    """
    slope = _positive("slope", slope)

    def spike(x: Tensor) -> Tensor:
        return FastSigmoidSpike.apply(x, slope)

    spike.__name__ = f"fast_sigmoid(slope={slope:g})"
    return spike


superspike = fast_sigmoid  # Norse's and Zenke & Ganguli's name for the same surrogate


def triangle(width: float = 10.0) -> SpikeFn:
    """Triangle spike function with half-width ``width`` (mV)."""
    width = _positive("width", width)

    def spike(x: Tensor) -> Tensor:
        return TriangleSpike.apply(x, width)

    spike.__name__ = f"triangle(width={width:g})"
    return spike
