"""Encoders: plant signals to input currents or spikes.

Qiu et al. encode a sensor value in two stages: normalise it to [0, 1] with stated bounds,
then map it linearly to a current (non-Markov task) or use it as a per-step spike
probability (Markov task). A constant background current keeps neurons firing when their
input is silent, so rates stay decodable.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

__all__ = ["normalize", "current_encode", "bernoulli_encode", "rate_encode", "background_current"]


def _check_bounds(low: float | Tensor, high: float | Tensor) -> None:
    low_t, high_t = torch.as_tensor(low), torch.as_tensor(high)
    if not bool(torch.isfinite(low_t).all() and torch.isfinite(high_t).all()):
        raise ValueError(f"low and high must be finite, got low={low!r}, high={high!r}")
    if not bool((high_t > low_t).all()):
        raise ValueError(f"high must be greater than low, got low={low!r}, high={high!r}")


def normalize(x: Tensor, low: float | Tensor, high: float | Tensor, *, clamp: bool = True) -> Tensor:
    """Map ``x`` from ``[low, high]`` (the signal's own units) to ``[0, 1]``.

    ``low`` and ``high`` broadcast against ``x`` (per-channel bounds). With ``clamp`` (the
    default), values outside the bounds saturate at 0 or 1.
    """
    _check_bounds(low, high)
    y = (x - low) / (high - low)
    return y.clamp(0.0, 1.0) if clamp else y


def current_encode(
    x: Tensor,
    low: float | Tensor,
    high: float | Tensor,
    *,
    i_max: float | Tensor,
    i_min: float | Tensor = 0.0,
) -> Tensor:
    """Normalise ``x`` to ``[0, 1]`` then map linearly to a current in ``[i_min, i_max]``.

    Currents are in the Izhikevich model's units (mV/ms; the paper's nA).
    """
    return i_min + normalize(x, low, high) * (i_max - i_min)


def bernoulli_encode(
    prob: Tensor, num_steps: int, *, generator: torch.Generator | None = None
) -> Tensor:
    """Independent Bernoulli spikes: ``[num_steps, *prob.shape]``, 1.0 with probability ``prob``.

    ``prob`` must lie in ``[0, 1]``. Pass a ``torch.Generator`` (on ``prob``'s device) for
    reproducible draws.
    """
    if isinstance(num_steps, bool) or not isinstance(num_steps, int) or num_steps < 0:
        raise ValueError(f"num_steps must be a non-negative int, got {num_steps!r}")
    if not bool(((prob >= 0) & (prob <= 1)).all()):
        raise ValueError("prob must lie in [0, 1] (and not be NaN)")
    draws = torch.rand((num_steps, *prob.shape), generator=generator, device=prob.device, dtype=prob.dtype)
    return (draws < prob).to(prob.dtype)


def rate_encode(
    x: Tensor,
    num_steps: int,
    *,
    f_max_hz: float,
    dt_ms: float,
    generator: torch.Generator | None = None,
) -> Tensor:
    """Rate-code ``x`` in ``[0, 1]`` as Bernoulli spikes firing at ``x * f_max_hz`` Hz.

    The per-step probability is ``x * f_max_hz * dt_ms / 1000``, which must not exceed 1.
    Qiu et al.'s Markov task uses the normalised value itself as the per-step probability:
    that is ``f_max_hz = 1000 / dt_ms``.
    """
    if not (math.isfinite(dt_ms) and dt_ms > 0):
        raise ValueError(f"dt_ms must be a positive finite number of milliseconds, got {dt_ms!r}")
    p_max = f_max_hz * dt_ms / 1000.0
    if not (math.isfinite(p_max) and 0 <= p_max <= 1):
        raise ValueError(
            f"f_max_hz * dt_ms / 1000 must lie in [0, 1] (one spike per step at most), "
            f"got f_max_hz={f_max_hz!r}, dt_ms={dt_ms!r}"
        )
    if not bool(((x >= 0) & (x <= 1)).all()):
        raise ValueError("x must be normalised to [0, 1] (see normalize)")
    return bernoulli_encode(x * p_max, num_steps, generator=generator)


def background_current(
    shape: tuple[int, ...] | torch.Size,
    mean: float,
    *,
    std: float = 0.0,
    generator: torch.Generator | None = None,
    device: torch.device | str | None = None,
    dtype: torch.dtype = torch.float32,
) -> Tensor:
    """Background current (mV/ms, the paper's nA): ``mean``, plus Gaussian noise of ``std``.

    Qiu et al. add a constant background current so that neurons keep firing without
    stimulus. ``std > 0`` models synaptic background noise (Fellous et al. 2003).
    """
    if not math.isfinite(mean):
        raise ValueError(f"mean must be finite, got {mean!r}")
    if not (math.isfinite(std) and std >= 0):
        raise ValueError(f"std must be a non-negative finite number, got {std!r}")
    out = torch.full(tuple(shape), float(mean), device=device, dtype=dtype)
    if std > 0:
        out = out + std * torch.randn(tuple(shape), generator=generator, device=device, dtype=dtype)
    return out
