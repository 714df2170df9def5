"""``nn.Module`` shells over ``snn_torch.functional.izhikevich``.

State is explicit: every ``forward`` takes an optional state and returns ``(spikes, state)``.
No buffers hold state, so modules are reentrant and a state can be detached, saved or
reset by the caller (``snn_torch.Stateful`` keeps it for ``nn.Sequential``).

Neuron parameters ``a, b, c, d, v_peak`` are registered ``nn.Parameter`` s of those names
(``requires_grad`` only for the fields in ``learn_params``), so ``.to()``, ``state_dict`` and
optimizers see them. They are cast to the input's dtype at each call.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor, nn

from snn_torch.functional.izhikevich import (
    DEFAULT_DT_MS,
    DEFAULT_METHOD,
    DEFAULT_V0_MV,
    QIU2019,
    IzhikevichParams,
    IzhikevichState,
    check_current,
    check_dt,
    check_method,
    check_params,
    izhikevich_init,
    izhikevich_step,
)
from snn_torch.functional.izhikevich_fused import izhikevich_step_fused
from snn_torch.functional.threshold import SpikeFn, fast_sigmoid
from snn_torch.modules._layer import TimeLayer
from snn_torch.modules._validate import check_state, neuron_parameters, params_for_step

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
        learn_params: bool | tuple[str, ...] | list[str],
        validate: bool,
        fused: bool,
        device: torch.device | str | None = None,
        dtype: torch.dtype | None = None,
    ) -> None:
        super().__init__()
        neuron_parameters(self, check_params(p), learn_params, device=device, dtype=dtype)
        self.dt_ms = check_dt(dt_ms)
        self.method = method
        self.spike_fn = spike_fn if spike_fn is not None else fast_sigmoid()
        self.substep_reset = substep_reset
        self.v0_mv = float(v0_mv)
        self.validate = bool(validate)
        self.fused = bool(fused)
        check_method(method)  # fail at construction, not at the first forward

    @property
    def p(self) -> IzhikevichParams:
        """The parameters as an ``IzhikevichParams`` of tensors (the registered ``nn.Parameter`` s)."""
        return IzhikevichParams(self.a, self.b, self.c, self.d, self.v_peak)

    def params_as(self, dtype: torch.dtype) -> IzhikevichParams:
        """The parameters for a step on ``dtype`` tensors (``params_for_step``)."""
        return params_for_step(self.p, dtype)

    def initial_state(self, like: Tensor) -> IzhikevichState:
        """Start state shaped, typed and placed like ``like`` (``v = v0_mv``, ``u = b v``)."""
        return izhikevich_init(like.shape, self.params_as(like.dtype), v0_mv=self.v0_mv, device=like.device,
                               dtype=like.dtype)

    def _step_fn(self) -> Callable[..., tuple[Tensor, IzhikevichState]]:
        return izhikevich_step_fused if self.fused else izhikevich_step

    def _kwargs(self) -> dict:
        return dict(dt_ms=self.dt_ms, method=self.method, spike_fn=self.spike_fn,
                    substep_reset=self.substep_reset)

    def extra_repr(self) -> str:
        values = ", ".join(f"{k}={v.item():g}" if v.dim() == 0 else f"{k}=[{v.numel()}]"
                           for k, v in self.p._asdict().items())
        return (f"{values}, dt_ms={self.dt_ms}, method={self.method!r}, "
                f"spike_fn={getattr(self.spike_fn, '__name__', self.spike_fn)}")


class IzhikevichCell(_IzhikevichBase):
    """One integration step of Izhikevich neurons: ``forward(i_in, state) -> (z, state)``.

    Args:
        p: neuron parameters (default: Qiu et al.'s, a=0.02/ms b=0.2/ms c=-50 mV d=2 mV/ms).
        dt_ms: step length (ms).
        method: ``"heun"`` or ``"euler"``.
        spike_fn: spike function; default ``fast_sigmoid()`` so gradients flow.
        substep_reset: reset at the interpolated crossing inside the step.
        v0_mv: initial membrane potential when no state is given (mV).
        learn_params: ``True``, ``False`` or the names of the fields (``"a"``, ...) to learn.
        validate: check every input (shape, dtype, finite) and the state on each call.
        fused: use ``izhikevich_step_fused`` (same results, one autograd node per step).

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
        learn_params: bool | tuple[str, ...] | list[str] = False,
        validate: bool = True,
        fused: bool = True,
        device: torch.device | str | None = None,
        dtype: torch.dtype | None = None,
    ) -> None:
        super().__init__(p, dt_ms=dt_ms, method=method, spike_fn=spike_fn, substep_reset=substep_reset,
                         v0_mv=v0_mv, learn_params=learn_params, validate=validate, fused=fused,
                         device=device, dtype=dtype)

    def forward(self, i_in: Tensor, state: IzhikevichState | None = None) -> tuple[Tensor, IzhikevichState]:
        if state is None:
            if self.validate and not isinstance(i_in, Tensor):
                raise ValueError(f"i_in must be a torch.Tensor, got {type(i_in).__name__}")
            state = self.initial_state(i_in)
        elif self.validate:
            check_state(state, IzhikevichState, None, i_in)
        if self.validate:
            check_current("i_in", i_in, state.v, check_finite=not torch.compiler.is_compiling())
        return self._step_fn()(i_in, state, self.params_as(state.v.dtype), validate=False, **self._kwargs())


class Izhikevich(TimeLayer, _IzhikevichBase):
    state_cls = IzhikevichState

    """A layer of Izhikevich neurons over time, driven through dense input weights.

    ``forward(x, state)`` takes ``x`` of shape ``[T, ..., in_features]`` (time first; with
    ``batch_first=True``, ``[B, T, ..., in_features]``), feeds ``current = linear(x)`` (mV/ms) to
    ``out_features`` neurons for ``T`` steps of ``dt_ms``, and returns
    ``(spikes [T, ..., out_features], final_state)``. ``T`` steps in one call equal ``T``
    one-step calls carrying the state, bit for bit.

    With ``record_states=True`` the second value is every step's state, an ``IzhikevichState``
    of ``[T, ..., out_features]`` tensors (the final state is its ``[-1]``).

    Args:
        in_features, out_features: sizes of the input and of the neuron layer.
        bias: whether the input projection has a bias (a learned background current).
        batch_first: ``x`` and the spikes are ``[B, T, ...]``; the state stays ``[B, ..., N]``.
        record_states: return every step's state instead of the final one.
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
        learn_params: bool | tuple[str, ...] | list[str] = False,
        batch_first: bool = False,
        record_states: bool = False,
        validate: bool = True,
        fused: bool = True,
        device: torch.device | str | None = None,
        dtype: torch.dtype | None = None,
    ) -> None:
        super().__init__(p, dt_ms=dt_ms, method=method, spike_fn=spike_fn, substep_reset=substep_reset,
                         v0_mv=v0_mv, learn_params=learn_params, validate=validate, fused=fused,
                         device=device, dtype=dtype)
        self._init_layer(in_features, out_features, bias=bias, batch_first=batch_first,
                         record_states=record_states, validate=validate, device=device, dtype=dtype)

    def step_params(self, dtype: torch.dtype) -> IzhikevichParams:
        return self.params_as(dtype)

    def step(self, i_t: Tensor, state: IzhikevichState, p: IzhikevichParams) -> tuple[Tensor, IzhikevichState]:
        return self._step_fn()(i_t, state, p, validate=False, **self._kwargs())
