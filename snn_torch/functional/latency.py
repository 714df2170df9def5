"""Latency (time-to-first-spike) coding: a larger value spikes earlier, once."""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["latency_encode"]


def latency_encode(x: Tensor, num_steps: int, *, threshold: float = 0.0) -> Tensor:
    """One spike per value at step ``round((1 - x) (num_steps - 1))``: ``[num_steps, *x.shape]``.

    ``x`` must lie in ``[0, 1]`` (see ``normalize``): 1 spikes at step 0, values at or below
    ``threshold`` never spike. Multiply the step by ``dt_ms`` for the spike time in ms.
    """
    if isinstance(num_steps, bool) or not isinstance(num_steps, int) or num_steps < 1:
        raise ValueError(f"num_steps must be a positive int, got {num_steps!r}")
    if not isinstance(x, Tensor) or not x.is_floating_point():
        raise ValueError(f"x must be a floating-point tensor, got {type(x).__name__}")
    if not torch.compiler.is_compiling() and not bool(((x >= 0) & (x <= 1)).all()):  # data check: eager only
        raise ValueError("x must be normalised to [0, 1] (and not be NaN); see snn_torch.functional.normalize")
    step = torch.round((1.0 - x) * (num_steps - 1)).to(torch.long)
    t = torch.arange(num_steps, device=x.device).view(num_steps, *([1] * x.dim()))
    return ((t == step) & (x > threshold)).to(x.dtype)
