"""Layer-style encoders: a static input ``x [B, ...]`` to a sequence ``[T, B, ...]`` for the layers.

(``snn_torch.modules.coding`` holds the closed-loop encoders a controller uses each step.)
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from snn_torch.functional.encode import rate_encode
from snn_torch.functional.latency import latency_encode

__all__ = ["RateEncoder", "LatencyEncoder", "ConstantCurrentEncoder"]


def _steps(num_steps: int) -> int:
    if isinstance(num_steps, bool) or not isinstance(num_steps, int) or num_steps < 1:
        raise ValueError(f"num_steps must be a positive int, got {num_steps!r}")
    return num_steps


class RateEncoder(nn.Module):
    """Bernoulli (Poisson-like) spikes at ``x * f_max_hz`` Hz for ``x`` in ``[0, 1]``: ``[T, *x.shape]``.

    Args:
        num_steps: sequence length ``T``.
        f_max_hz: rate for ``x = 1`` (Hz); ``f_max_hz * dt_ms / 1000`` must be at most 1.
        dt_ms: step length (ms), the layers' ``dt_ms``.
        generator: a ``torch.Generator`` for reproducible draws.
    """

    def __init__(self, num_steps: int, *, f_max_hz: float = 100.0, dt_ms: float = 1.0,
                 generator: torch.Generator | None = None) -> None:
        super().__init__()
        self.num_steps, self.f_max_hz, self.dt_ms, self.generator = _steps(num_steps), f_max_hz, dt_ms, generator
        rate_encode(torch.zeros(1), 1, f_max_hz=f_max_hz, dt_ms=dt_ms)  # fail here on bad rates

    def forward(self, x: Tensor) -> Tensor:
        if not torch.compiler.is_compiling():
            return rate_encode(x, self.num_steps, f_max_hz=self.f_max_hz, dt_ms=self.dt_ms, generator=self.generator)
        # Compiled: the same draws without rate_encode's data checks (a graph break each).
        p = x * (self.f_max_hz * self.dt_ms / 1000.0)
        return (torch.rand((self.num_steps, *x.shape), dtype=x.dtype, device=x.device) < p).to(x.dtype)

    def extra_repr(self) -> str:
        return f"num_steps={self.num_steps}, f_max_hz={self.f_max_hz:g}, dt_ms={self.dt_ms:g}"


class LatencyEncoder(nn.Module):
    """One spike per value, earlier for larger ``x`` in ``[0, 1]`` (``latency_encode``): ``[T, *x.shape]``."""

    def __init__(self, num_steps: int, *, threshold: float = 0.0) -> None:
        super().__init__()
        self.num_steps, self.threshold = _steps(num_steps), float(threshold)

    def forward(self, x: Tensor) -> Tensor:
        return latency_encode(x, self.num_steps, threshold=self.threshold)

    def extra_repr(self) -> str:
        return f"num_steps={self.num_steps}, threshold={self.threshold:g}"


class ConstantCurrentEncoder(nn.Module):
    """The current ``gain * x + offset`` (mV/ms for Izhikevich layers) held for ``T`` steps: ``[T, *x.shape]``.

    A view (``expand``), so it costs no memory and gradients reach ``x``.
    """

    def __init__(self, num_steps: int, *, gain: float = 1.0, offset: float = 0.0) -> None:
        super().__init__()
        self.num_steps, self.gain, self.offset = _steps(num_steps), float(gain), float(offset)

    def forward(self, x: Tensor) -> Tensor:
        return (x * self.gain + self.offset).expand(self.num_steps, *x.shape)

    def extra_repr(self) -> str:
        return f"num_steps={self.num_steps}, gain={self.gain:g}, offset={self.offset:g}"
