"""Decoders: spikes to rates and to forces."""

from __future__ import annotations

import math

import torch
from torch import Tensor

from snn_torch.functional.portable_math import sigmoid as portable_sigmoid
from snn_torch.functional.scalars import scalars

__all__ = ["firing_rate", "weighted_rate_force", "sigmoid_force", "bang_bang_force", "ordered_sum", "ordered_matvec",
           "ordered_sigmoid"]

_CUMSUM_MAX = 32768  # elements up to which one cumsum beats a loop over the slots (measured, this CPU)


def firing_rate(spikes: Tensor, *, dt_ms: float, dim: int = 0) -> Tensor:
    """Mean firing rate (Hz) of ``spikes`` (0/1 per step of ``dt_ms`` ms) along ``dim``.

    An empty window has no defined rate and raises ``ValueError``.
    """
    if not (math.isfinite(dt_ms) and dt_ms > 0):
        raise ValueError(f"dt_ms must be a positive finite number of milliseconds, got {dt_ms!r}")
    steps = spikes.shape[dim]
    if steps == 0:
        raise ValueError(f"spikes has no time steps along dim {dim}")
    return spikes.sum(dim) * (1000.0 / (steps * dt_ms))


def ordered_sum(x: Tensor, dim: int = -1) -> Tensor:
    """Sum along ``dim`` in index order with a float64 accumulator, rounded once to ``x``'s dtype.

    ``x.sum()`` reduces in blocks whose shape depends on the tensor's size and layout, so a
    row's sum could change with the batch it is in or with the number of (zero) slots beyond
    its last term. Here the order is fixed: ``((0 + x_0) + x_1) + ...`` in float64, so exact
    zeros anywhere change nothing. On the CPU this is ``cumsum`` (a sequential loop that
    accumulates float32 in double); elsewhere an explicit loop over the slots.
    """
    if x.device.type == "cpu" and x.numel() <= _CUMSUM_MAX:  # beyond, cumsum's ~100 ns an element loses
        return torch.cumsum(x, dim, dtype=torch.float64).select(dim, -1).to(x.dtype) if x.shape[dim] else \
            x.sum(dim)
    acc = torch.zeros_like(x.select(dim, 0), dtype=torch.float64)
    for k in range(x.shape[dim]):
        acc = acc + x.select(dim, k).to(torch.float64)
    return acc.to(x.dtype)


def ordered_matvec(y: Tensor, w: Tensor) -> Tensor:
    """``x[b, j] = sum_i y[b, i] w[b, i, j]``, each product rounded to the dtype, then ``ordered_sum``
    over ``i``: the same bits for a row in any batch and with any number of zero slots."""
    return ordered_sum(y.unsqueeze(-1) * w, dim=1)


def ordered_sigmoid(x: Tensor) -> Tensor:
    """``1 / (1 + exp(-x))`` as ``snn_torch.functional.portable_math.sigmoid`` computes it: the
    same bits at any batch position, on any path (the C kernels include its twin), with or
    without a C compiler. (torch.sigmoid's vectorised and scalar-tail paths differ in the last
    bit, and torch's exp differs from the C library's.)"""
    return portable_sigmoid(x)


def weighted_rate_force(
    rates: Tensor, weights: Tensor, sigma: Tensor | float, *, f_max: float = 10.0
) -> Tensor:
    """Qiu et al.'s force: ``F = f_max (2 sigmoid(sigma * sum_i w_i r_i) - 1)`` (N).

    Args:
        rates: firing rates ``r_i`` (Hz), shape ``[..., K]``.
        weights: connection weights ``w_i`` to the output, broadcastable to ``rates``.
        sigma: decoder gain (1/Hz per unit weight), broadcastable to ``rates.shape[:-1]``.
        f_max: force magnitude bound (N); the paper uses 10 N.

    Returns:
        Force in ``(-f_max, f_max)``, shape ``rates.shape[:-1]``.
    """
    drive = ordered_sum(rates * weights, dim=-1)  # slot order: independent of batch and slot count
    return sigmoid_force(drive, sigma, f_max=f_max)


def sigmoid_force(drive: Tensor, sigma: Tensor | float = 1.0, *, f_max: float = 10.0) -> Tensor:
    """``F = f_max (2 sigmoid(sigma * drive) - 1)`` (N), in ``(-f_max, f_max)`` ([Qiu19] eq. 10), in
    the drive's dtype: the decoder of ``modules.SigmoidForce`` and of the C kernels."""
    y = ordered_sigmoid(sigma * drive)
    f, two, one = scalars((f_max, 2.0, 1.0), y)
    return f * (two * y - one)


def bang_bang_force(drive: Tensor, *, threshold: float | Tensor = 0.0, f_max: float = 10.0) -> Tensor:
    """Binary force: ``+f_max`` (N) where ``drive > threshold``, else ``-f_max``, in the drive's
    dtype. The one threshold rule of every bang-bang decoder here (``modules.BangBang``, the
    sigmoid controller's on its output > 0.5, and the C kernels'): a drive exactly at the
    threshold pushes negative. Qiu et al.'s Markov task pushes with +-10 N this way."""
    plus, minus = scalars((f_max, -f_max), drive)  # +-f_max rounded to the drive's dtype
    return torch.where(drive > threshold, plus, minus)
