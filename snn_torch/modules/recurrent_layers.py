"""Trainable recurrent spiking layers: dense input weights and dense recurrent weights.

``current_t = W_in x_t + b + W_rec z_{t-1}`` drives the neurons at step ``t``; spikes feed back
with a one-step delay, through their surrogate gradient (backpropagation through time).
The population-batched, evolved networks are ``PopulationRecurrentIzhikevich`` (modules/recurrent.py).
"""

from __future__ import annotations

from torch import Tensor, nn

from snn_torch.functional.izhikevich import (
    DEFAULT_DT_MS,
    DEFAULT_METHOD,
    DEFAULT_V0_MV,
    QIU2019,
    IzhikevichParams,
)
from snn_torch.functional.izhikevich import IzhikevichState as _IzhState
from snn_torch.functional.lif import LIFParams, LIFRecurrentState, LIFState
from snn_torch.functional.recurrent import RecurrentState
from snn_torch.functional.threshold import SpikeFn
from snn_torch.modules._layer import TimeLayer
from snn_torch.modules.izhikevich import _IzhikevichBase
from snn_torch.modules.lif import LIF_DEFAULT, Learn, _LIFBase

__all__ = ["LIFRecurrent", "IzhikevichRecurrent"]


class LIFRecurrent(TimeLayer, _LIFBase):
    """LIF neurons with input weights (``linear``) and recurrent weights (``recurrent``, no bias).

    ``forward(x [T, ..., in_features], state: LIFRecurrentState | None) -> (spikes [T, ..., hidden], state)``.
    Arguments as ``LIF``.
    """

    state_cls = LIFRecurrentState

    def __init__(self, in_features: int, hidden_features: int, p: LIFParams = LIF_DEFAULT, *, bias: bool = True,
                 dt_ms: float = 1.0, spike_fn: SpikeFn | None = None, reset: str = "zero",
                 learn_params: Learn = False, batch_first: bool = False, record_states: bool = False,
                 validate: bool = True, device=None, dtype=None) -> None:
        super().__init__()
        self._init_neurons(p, dt_ms=dt_ms, spike_fn=spike_fn, reset=reset, learn_params=learn_params,
                           validate=validate, device=device, dtype=dtype)
        self._init_layer(in_features, hidden_features, bias=bias, batch_first=batch_first,
                         record_states=record_states, validate=validate, device=device, dtype=dtype)
        self.recurrent = nn.Linear(hidden_features, hidden_features, bias=False, device=device, dtype=dtype)

    def initial_state(self, like: Tensor) -> LIFRecurrentState:
        (v,) = _LIFBase.initial_state(self, like)
        return LIFRecurrentState(v, like.new_zeros(like.shape))

    def step(self, i_t: Tensor, state: LIFRecurrentState, p: LIFParams) -> tuple[Tensor, LIFRecurrentState]:
        z, (v,) = _LIFBase.step(self, i_t + self.recurrent(state.z), LIFState(state.v), p)
        return z, LIFRecurrentState(v, z)


class IzhikevichRecurrent(TimeLayer, _IzhikevichBase):
    """Izhikevich neurons with input and recurrent weights; state ``RecurrentState(v, u, z)``.

    Arguments as ``Izhikevich``; ``hidden_features`` neurons.
    """

    state_cls = RecurrentState

    def __init__(self, in_features: int, hidden_features: int, p: IzhikevichParams = QIU2019, *, bias: bool = True,
                 dt_ms: float = DEFAULT_DT_MS, method: str = DEFAULT_METHOD, spike_fn: SpikeFn | None = None,
                 substep_reset: bool = True, v0_mv: float = DEFAULT_V0_MV, learn_params: Learn = False,
                 batch_first: bool = False, record_states: bool = False, validate: bool = True, fused: bool = True,
                 device=None, dtype=None) -> None:
        super().__init__(p, dt_ms=dt_ms, method=method, spike_fn=spike_fn, substep_reset=substep_reset,
                         v0_mv=v0_mv, learn_params=learn_params, validate=validate, fused=fused,
                         device=device, dtype=dtype)
        self._init_layer(in_features, hidden_features, bias=bias, batch_first=batch_first,
                         record_states=record_states, validate=validate, device=device, dtype=dtype)
        self.recurrent = nn.Linear(hidden_features, hidden_features, bias=False, device=device, dtype=dtype)

    def initial_state(self, like: Tensor) -> RecurrentState:
        v, u = _IzhikevichBase.initial_state(self, like)
        return RecurrentState(v, u, like.new_zeros(like.shape))

    def step_params(self, dtype) -> IzhikevichParams:
        return self.params_as(dtype)

    def step(self, i_t: Tensor, state: RecurrentState, p: IzhikevichParams) -> tuple[Tensor, RecurrentState]:
        z, (v, u) = self._step_fn()(i_t + self.recurrent(state.z), _IzhState(state.v, state.u), p, validate=False,
                                    **self._kwargs())
        return z, RecurrentState(v, u, z)
