"""``nn.Module`` shells over ``snn_torch.functional.lif``: LIF and leaky-integrator (LI) cells and layers.

Same shape as the Izhikevich modules: ``forward(x, state=None) -> (output, state)``, explicit
state, parameters registered as ``nn.Parameter`` s named like the fields (``tau_mem_ms``,
``v_leak``, ...; ``requires_grad`` for those in ``learn_params``). ``LI`` is the usual
non-spiking readout: its output is the membrane potential (mV).
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from snn_torch.functional.izhikevich import check_dt
from snn_torch.functional.lif import (
    RESETS,
    LIFParams,
    LIFState,
    LIParams,
    LIState,
    li_init,
    li_step,
    lif_init,
    lif_step,
)
from snn_torch.functional.threshold import SpikeFn, fast_sigmoid
from snn_torch.modules._layer import TimeLayer
from snn_torch.modules._validate import check_state, neuron_parameters, params_for_step

__all__ = ["LIFCell", "LIF", "LICell", "LI"]

Learn = bool | tuple[str, ...] | list[str]
LIF_DEFAULT, LI_DEFAULT = LIFParams(), LIParams()


def _check_positive_tau(module: nn.Module) -> None:
    if not bool((module.tau_mem_ms > 0).all()):
        raise ValueError(f"tau_mem_ms must be positive (ms), got {module.tau_mem_ms.tolist()}")


class _LIFBase(nn.Module):
    def _init_neurons(self, p: LIFParams, *, dt_ms: float, spike_fn: SpikeFn | None, reset: str, learn_params: Learn,
                      validate: bool, device, dtype) -> None:
        if not isinstance(p, LIFParams):
            raise TypeError(f"p must be a snn_torch.LIFParams, got {type(p).__name__}")
        if reset not in RESETS:
            raise ValueError(f"reset must be one of {RESETS}, got {reset!r}")
        neuron_parameters(self, p, learn_params, device=device, dtype=dtype)
        _check_positive_tau(self)
        self.dt_ms = check_dt(dt_ms)
        self.spike_fn = spike_fn if spike_fn is not None else fast_sigmoid(slope=10.0)
        self.reset = reset
        self.validate = bool(validate)

    @property
    def p(self) -> LIFParams:
        return LIFParams(*(getattr(self, f) for f in LIFParams._fields))

    def step_params(self, dtype: torch.dtype) -> LIFParams:
        return params_for_step(self.p, dtype)

    def initial_state(self, like: Tensor) -> LIFState:
        """Rest state (``v = v_leak``) shaped, typed and placed like ``like``."""
        return lif_init(like.shape, self.step_params(like.dtype), device=like.device, dtype=like.dtype)

    def step(self, i_t: Tensor, state: LIFState, p: LIFParams) -> tuple[Tensor, LIFState]:
        return lif_step(i_t, state, p, dt_ms=self.dt_ms, spike_fn=self.spike_fn, reset=self.reset)

    def extra_repr(self) -> str:
        values = ", ".join(f"{k}={v.item():g}" if v.dim() == 0 else f"{k}=[{v.numel()}]"
                           for k, v in self.p._asdict().items())
        return f"{values}, dt_ms={self.dt_ms}, reset={self.reset!r}"


class LIFCell(_LIFBase):
    """One step of LIF neurons: ``forward(i_in, state) -> (z, state)``.

    Args:
        p: ``LIFParams`` (default: tau_mem 10 ms, v_leak 0 mV, v_th 1 mV, v_reset 0 mV, r 1).
        dt_ms: step length (ms).
        spike_fn: spike function of ``v - v_th`` (mV); default ``fast_sigmoid(slope=10)``.
        reset: ``"zero"`` (to ``v_reset``) or ``"subtract"`` (``v_th - v_reset``).
        learn_params: ``True``, ``False`` or the field names to learn.
        validate: check the input and the state on each call.
    """

    def __init__(self, p: LIFParams = LIF_DEFAULT, *, dt_ms: float = 1.0, spike_fn: SpikeFn | None = None,
                 reset: str = "zero", learn_params: Learn = False, validate: bool = True, device=None,
                 dtype=None) -> None:
        super().__init__()
        self._init_neurons(p, dt_ms=dt_ms, spike_fn=spike_fn, reset=reset, learn_params=learn_params,
                           validate=validate, device=device, dtype=dtype)

    def forward(self, i_in: Tensor, state: LIFState | None = None) -> tuple[Tensor, LIFState]:
        if self.validate and not isinstance(i_in, Tensor):
            raise ValueError(f"i_in must be a torch.Tensor, got {type(i_in).__name__}")
        if state is None:
            state = self.initial_state(i_in)
        elif self.validate:
            check_state(state, LIFState, i_in.shape, i_in)
        return self.step(i_in, state, self.step_params(i_in.dtype))


class LIF(TimeLayer, _LIFBase):
    """A layer of LIF neurons over time behind dense input weights.

    ``forward(x, state)``: ``x [T, ..., in_features]`` (``[B, T, ...]`` with ``batch_first``) ->
    ``(spikes [T, ..., out_features], final LIFState)``; with ``record_states`` the state is
    every step's, ``[T, ..., out_features]``. Others as ``LIFCell``.
    """

    state_cls = LIFState

    def __init__(self, in_features: int, out_features: int, p: LIFParams = LIF_DEFAULT, *, bias: bool = True,
                 dt_ms: float = 1.0, spike_fn: SpikeFn | None = None, reset: str = "zero",
                 learn_params: Learn = False, batch_first: bool = False, record_states: bool = False,
                 validate: bool = True, device=None, dtype=None) -> None:
        super().__init__()
        self._init_neurons(p, dt_ms=dt_ms, spike_fn=spike_fn, reset=reset, learn_params=learn_params,
                           validate=validate, device=device, dtype=dtype)
        self._init_layer(in_features, out_features, bias=bias, batch_first=batch_first,
                         record_states=record_states, validate=validate, device=device, dtype=dtype)


class _LIBase(nn.Module):
    def _init_neurons(self, p: LIParams, *, dt_ms: float, learn_params: Learn, validate: bool, device,
                      dtype) -> None:
        if not isinstance(p, LIParams):
            raise TypeError(f"p must be a snn_torch.LIParams, got {type(p).__name__}")
        neuron_parameters(self, p, learn_params, device=device, dtype=dtype)
        _check_positive_tau(self)
        self.dt_ms = check_dt(dt_ms)
        self.validate = bool(validate)

    @property
    def p(self) -> LIParams:
        return LIParams(*(getattr(self, f) for f in LIParams._fields))

    def step_params(self, dtype: torch.dtype) -> LIParams:
        return params_for_step(self.p, dtype)

    def initial_state(self, like: Tensor) -> LIState:
        """Rest state (``v = v_leak``) shaped, typed and placed like ``like``."""
        return li_init(like.shape, self.step_params(like.dtype), device=like.device, dtype=like.dtype)

    def step(self, i_t: Tensor, state: LIState, p: LIParams) -> tuple[Tensor, LIState]:
        return li_step(i_t, state, p, dt_ms=self.dt_ms)

    def extra_repr(self) -> str:
        values = ", ".join(f"{k}={v.item():g}" if v.dim() == 0 else f"{k}=[{v.numel()}]"
                           for k, v in self.p._asdict().items())
        return f"{values}, dt_ms={self.dt_ms}"


class LICell(_LIBase):
    """One step of leaky integrators: ``forward(i_in, state) -> (v, state)``, ``v`` in mV.

    Args:
        p: ``LIParams`` (default: tau_mem 10 ms, v_leak 0 mV, r 1).
        dt_ms: step length (ms).
        learn_params: ``True``, ``False`` or the field names to learn.
        validate: check the input and the state on each call.
    """

    def __init__(self, p: LIParams = LI_DEFAULT, *, dt_ms: float = 1.0, learn_params: Learn = False,
                 validate: bool = True, device=None, dtype=None) -> None:
        super().__init__()
        self._init_neurons(p, dt_ms=dt_ms, learn_params=learn_params, validate=validate, device=device,
                           dtype=dtype)

    def forward(self, i_in: Tensor, state: LIState | None = None) -> tuple[Tensor, LIState]:
        if self.validate and not isinstance(i_in, Tensor):
            raise ValueError(f"i_in must be a torch.Tensor, got {type(i_in).__name__}")
        if state is None:
            state = self.initial_state(i_in)
        elif self.validate:
            check_state(state, LIState, i_in.shape, i_in)
        return self.step(i_in, state, self.step_params(i_in.dtype))


class LI(TimeLayer, _LIBase):
    """A non-spiking readout: dense weights into leaky integrators, ``(v [T, ..., out_features], state)``.

    Decode with ``v[-1]`` or ``v.max(0).values``. Others as ``LICell`` and ``LIF``.
    """

    state_cls = LIState

    def __init__(self, in_features: int, out_features: int, p: LIParams = LI_DEFAULT, *, bias: bool = True,
                 dt_ms: float = 1.0, learn_params: Learn = False, batch_first: bool = False,
                 record_states: bool = False, validate: bool = True, device=None, dtype=None) -> None:
        super().__init__()
        self._init_neurons(p, dt_ms=dt_ms, learn_params=learn_params, validate=validate, device=device,
                           dtype=dtype)
        self._init_layer(in_features, out_features, bias=bias, batch_first=batch_first,
                         record_states=record_states, validate=validate, device=device, dtype=dtype)
