"""Encoders and decoders as modules: what sits between a plant and a population network.

A controller is ``encoder -> network -> decoder``. Encoders take observations already
normalised to [0, 1] (``snn_torch.functional.normalize``) and give input currents or spikes;
decoders take spike counts or node values and give actions. All work on a batch of rows
``[B, ...]`` (one row per episode); state, where there is any, goes in and out (``RateWindow``
writes the new counts into the history it is given: a closed loop owns its state; clone it to
keep an old one).

Every sum runs in slot order (``snn_torch.functional.decode.ordered_sum``), so a row's action never depends on the batch
it is in or on how many node slots the batch simulates.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import Tensor, nn

from snn_torch.functional.counter_rng import BernoulliSources
from snn_torch.functional.decode import bang_bang_force, sigmoid_force
from snn_torch.functional.scalars import scalar

__all__ = ["CurrentEncoder", "BernoulliEncoder", "RateWindow", "RateWindowState", "SigmoidForce", "UnitForce", "BangBang",
           "LinearReadout"]


def _finite(name: str, value: float, *, positive: bool = False, nonnegative: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    if positive and value <= 0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    if nonnegative and value < 0:
        raise ValueError(f"{name} must be >= 0, got {value!r}")
    return float(value)


class CurrentEncoder(nn.Module):
    """Normalised inputs ``x`` in [0, 1] to currents ``i_min + x (i_max - i_min)`` (mV/ms, the paper's nA).

    The background current every neuron gets is the network's (``i_background``), not the
    encoder's: the encoder adds only what the observation drives.
    """

    def __init__(self, i_max: float, i_min: float = 0.0) -> None:
        super().__init__()
        self.i_max, self.i_min = _finite("i_max", i_max), _finite("i_min", i_min)

    def forward(self, x: Tensor) -> Tensor:
        if self.i_min == 0.0:
            return self.i_max * x
        return self.i_min + x * (self.i_max - self.i_min)

    def extra_repr(self) -> str:
        return f"i_min={self.i_min}, i_max={self.i_max} (mV/ms)"


class BernoulliEncoder(nn.Module):
    """Normalised inputs ``x`` in [0, 1] to Bernoulli spike trains at up to ``rate_max_hz``.

    In every substep of ``dt_ms`` input ``k`` spikes with probability ``x_k * rate_max_hz *
    dt_ms / 1000``. Draws come from a counter-based stream (``snn_torch.functional.counter_rng``):
    draw ``k`` of substep ``q`` of control step ``t`` of a row is counter
    ``(t * substeps + q) * K + k`` of the row's key, so a row's spikes depend on its key and
    its own history alone (keys: e.g. a hash of the genome, ``fnv1a_keys``).

    ``forward(x [B, K], keys [B], step)`` returns the step's ``BernoulliSources``: the network's
    C kernel draws them itself, ``.spikes(substeps, dtype)`` draws them in torch (the same bits).
    """

    def __init__(self, rate_max_hz: float, *, dt_ms: float, substeps: int) -> None:
        super().__init__()
        self.rate_max_hz = _finite("rate_max_hz", rate_max_hz, nonnegative=True)
        self.dt_ms = _finite("dt_ms", dt_ms, positive=True)
        if isinstance(substeps, bool) or not isinstance(substeps, int) or substeps < 1:
            raise ValueError(f"substeps must be a positive int, got {substeps!r}")
        self.substeps = substeps
        self.p_max = self.rate_max_hz * self.dt_ms / 1000.0
        if self.p_max > 1.0 + 1e-12:
            raise ValueError(f"rate_max_hz * dt_ms / 1000 must be at most 1 (one spike per substep), got "
                             f"{self.p_max:g}")

    def forward(self, x: Tensor, keys: Tensor, step: int) -> BernoulliSources:
        prob = (x * scalar(self.p_max, x)).to(torch.float64)
        return BernoulliSources(prob, keys, step * self.substeps * x.shape[1])

    def extra_repr(self) -> str:
        return f"rate_max_hz={self.rate_max_hz}, dt_ms={self.dt_ms}, substeps={self.substeps}"


class RateWindowState(NamedTuple):
    """Spike counts of the last control steps (``history[k]``: slot ``k = t % window``,
    ``[window, B, N]``) and ``steps``, the control steps recorded so far."""

    history: Tensor
    steps: int


class RateWindow(nn.Module):
    """Firing rates (Hz) over the last ``window`` control steps of ``period_s`` seconds each.

    ``forward(counts [B, N], state) -> (rates [B, N], state)``; the window is shorter until
    ``window`` steps have been recorded. Rows are summed slot by slot in slot order.
    """

    def __init__(self, window: int, period_s: float) -> None:
        super().__init__()
        if isinstance(window, bool) or not isinstance(window, int) or window < 1:
            raise ValueError(f"window must be a positive int (control steps), got {window!r}")
        self.window, self.period_s = window, _finite("period_s", period_s, positive=True)

    def initial_state(self, like: Tensor) -> RateWindowState:
        return RateWindowState(like.new_zeros((self.window, *like.shape)), 0)

    def forward(self, counts: Tensor, state: RateWindowState) -> tuple[Tensor, RateWindowState]:
        history = state.history
        history[state.steps % self.window] = counts
        steps = state.steps + 1
        # Counts are whole numbers, so their sum is exact in any order: the same as slot by slot.
        total = history[0] if self.window == 1 else history.sum(0)
        return total / scalar(min(steps, self.window) * self.period_s, counts), RateWindowState(history, steps)

    def extra_repr(self) -> str:
        return f"window={self.window}, period_s={self.period_s}"


class SigmoidForce(nn.Module):
    """Qiu et al.'s force ``F = f_max (2 sigmoid(sigma * drive) - 1)`` (N), in ``(-f_max, f_max)``."""

    def __init__(self, f_max: float = 10.0) -> None:
        super().__init__()
        self.f_max = _finite("f_max", f_max, positive=True)

    def forward(self, drive: Tensor, sigma: Tensor | float = 1.0) -> Tensor:
        return sigmoid_force(drive, sigma, f_max=self.f_max)

    def extra_repr(self) -> str:
        return f"f_max={self.f_max} (N)"


class UnitForce(nn.Module):
    """A unit output ``y`` in [0, 1] as a force ``F = f_max (2 y - 1)`` (N): sigmoid NEAT's readout."""

    def __init__(self, f_max: float = 10.0) -> None:
        super().__init__()
        self.f_max = _finite("f_max", f_max, positive=True)

    def forward(self, y: Tensor) -> Tensor:
        return self.f_max * (2.0 * y - 1.0)

    def extra_repr(self) -> str:
        return f"f_max={self.f_max} (N)"


class BangBang(nn.Module):
    """``+f_max`` where ``drive > threshold``, else ``-f_max`` (N)."""

    def __init__(self, f_max: float = 10.0, threshold: float = 0.0) -> None:
        super().__init__()
        self.f_max = _finite("f_max", f_max, positive=True)
        self.threshold = _finite("threshold", threshold)

    def forward(self, drive: Tensor) -> Tensor:
        return bang_bang_force(drive, threshold=self.threshold, f_max=self.f_max)

    def extra_repr(self) -> str:
        return f"f_max={self.f_max} (N), threshold={self.threshold}"


class LinearReadout(nn.Module):
    """``a = scale * drive + offset``, clamped to ``[low, high]`` when given: a continuous action
    read linearly from a weighted rate (or any drive)."""

    def __init__(self, scale: float = 1.0, offset: float = 0.0, *, low: float | None = None,
                 high: float | None = None) -> None:
        super().__init__()
        self.scale, self.offset = _finite("scale", scale), _finite("offset", offset)
        self.low = None if low is None else _finite("low", low)
        self.high = None if high is None else _finite("high", high)
        if self.low is not None and self.high is not None and not self.low < self.high:
            raise ValueError(f"low must be below high, got {low!r} and {high!r}")

    def forward(self, drive: Tensor) -> Tensor:
        a = self.scale * drive + self.offset
        if self.low is not None or self.high is not None:
            a = a.clamp(self.low, self.high)
        return a

    def extra_repr(self) -> str:
        return f"scale={self.scale}, offset={self.offset}, low={self.low}, high={self.high}"
