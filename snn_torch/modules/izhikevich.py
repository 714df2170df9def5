"""``nn.Module`` shells over ``snn_torch.functional.izhikevich``.

State is explicit: every ``forward`` takes an optional state and returns ``(spikes, state)``.
No buffers hold state, so modules are reentrant and a state can be detached, saved or
reset by the caller.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from snn_torch.functional.izhikevich import (
    DEFAULT_DT_MS,
    DEFAULT_METHOD,
    DEFAULT_V0_MV,
    QIU2019,
    IzhikevichParams,
    IzhikevichState,
    check_dt,
    check_method,
    check_params,
    izhikevich_init,
    izhikevich_run,
    izhikevich_step,
)
from snn_torch.functional.threshold import SpikeFn, fast_sigmoid

__all__ = ["IzhikevichCell", "Izhikevich"]


class _IzhikevichBase(nn.Module):
    def __init__(
        self,
        p: IzhikevichParams,
        *,
        dt_ms: float,
        method: str,
        spike_fn: SpikeFn | None,
        substep_reset: bool,
        v0_mv: float,
    ) -> None:
        super().__init__()
        self.p = check_params(p)
        self.dt_ms = check_dt(dt_ms)
        self.method = method
        self.spike_fn = spike_fn if spike_fn is not None else fast_sigmoid()
        self.substep_reset = substep_reset
        self.v0_mv = float(v0_mv)
        check_method(method)  # fail at construction, not at the first forward

    def initial_state(self, like: Tensor) -> IzhikevichState:
        """Start state shaped, typed and placed like ``like`` (``v = v0_mv``, ``u = b v``)."""
        return izhikevich_init(like.shape, self.p, v0_mv=self.v0_mv, device=like.device, dtype=like.dtype)

    def _kwargs(self) -> dict:
        return dict(dt_ms=self.dt_ms, method=self.method, spike_fn=self.spike_fn,
                    substep_reset=self.substep_reset)

    def extra_repr(self) -> str:
        return f"p={tuple(self.p)}, dt_ms={self.dt_ms}, method={self.method!r}, spike_fn={self.spike_fn.__name__}"


class IzhikevichCell(_IzhikevichBase):
    """One integration step of Izhikevich neurons: ``forward(i_in, state) -> (z, state)``.

    Args:
        p: neuron parameters (default: Qiu et al.'s, a=0.02 b=0.2 c=-50 mV d=2).
        dt_ms: step length (ms).
        method: ``"heun"`` or ``"euler"``.
        spike_fn: spike function; default ``fast_sigmoid()`` so gradients flow.
        substep_reset: reset at the interpolated crossing inside the step.
        v0_mv: initial membrane potential when no state is given (mV).
        validate: check every input (shape, dtype, finite) on each call.

    Example::

        cell = IzhikevichCell()
        state = None
        for t in range(100):
            z, state = cell(current[t], state)
    """

    def __init__(
        self,
        p: IzhikevichParams = QIU2019,
        *,
        dt_ms: float = DEFAULT_DT_MS,
        method: str = DEFAULT_METHOD,
        spike_fn: SpikeFn | None = None,
        substep_reset: bool = True,
        v0_mv: float = DEFAULT_V0_MV,
        validate: bool = True,
    ) -> None:
        super().__init__(p, dt_ms=dt_ms, method=method, spike_fn=spike_fn,
                         substep_reset=substep_reset, v0_mv=v0_mv)
        self.validate = validate

    def forward(self, i_in: Tensor, state: IzhikevichState | None = None) -> tuple[Tensor, IzhikevichState]:
        if state is None:
            state = self.initial_state(i_in)
        return izhikevich_step(i_in, state, self.p, validate=self.validate, **self._kwargs())


class Izhikevich(_IzhikevichBase):
    """A layer of Izhikevich neurons over time, driven through dense input weights.

    ``forward(x, state)`` takes ``x`` of shape ``[T, ..., in_features]`` (time first), feeds
    ``current = linear(x)`` (mV/ms) to ``out_features`` neurons for ``T`` steps of
    ``dt_ms``, and returns ``(spikes [T, ..., out_features], final_state)``. ``T`` steps in one
    call equal ``T`` one-step calls carrying the state, bit for bit.

    Args:
        in_features, out_features: sizes of the input and of the neuron layer.
        bias: whether the input projection has a bias (a learned background current).
        Others as ``IzhikevichCell``.
    """

    def __init__(
        self,
        in_features: int,
        out_features: int,
        p: IzhikevichParams = QIU2019,
        *,
        bias: bool = True,
        dt_ms: float = DEFAULT_DT_MS,
        method: str = DEFAULT_METHOD,
        spike_fn: SpikeFn | None = None,
        substep_reset: bool = True,
        v0_mv: float = DEFAULT_V0_MV,
        device: torch.device | str | None = None,
        dtype: torch.dtype | None = None,
    ) -> None:
        super().__init__(p, dt_ms=dt_ms, method=method, spike_fn=spike_fn,
                         substep_reset=substep_reset, v0_mv=v0_mv)
        self.linear = nn.Linear(in_features, out_features, bias=bias, device=device, dtype=dtype)

    def forward(self, x: Tensor, state: IzhikevichState | None = None) -> tuple[Tensor, IzhikevichState]:
        if not isinstance(x, Tensor) or x.dim() < 2 or x.shape[-1] != self.linear.in_features:
            shape = tuple(x.shape) if isinstance(x, Tensor) else type(x).__name__
            raise ValueError(f"x must be [T, ..., {self.linear.in_features}] (time first), got {shape}")
        if not bool(torch.isfinite(x).all()):
            raise ValueError("x holds NaN or inf")
        current = self.linear(x)
        if state is None:
            state = self.initial_state(current[0])
        return izhikevich_run(current, state, self.p, validate=True, **self._kwargs())
