"""What every time-stepped layer shares: the input boundary (validation, ``batch_first``, the
dense input projection) and the loop over time with ``record_states``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from torch import Tensor, nn

from snn_torch.modules._validate import check_input, check_state

__all__ = ["TimeLayer", "stack_states"]


def stack_states(states: list, cls: type) -> Any:
    """``[state_0, ..., state_{T-1}]`` -> one ``cls`` whose fields are ``[T, ...]`` tensors."""
    return cls(*(torch.stack(field) for field in zip(*states, strict=True)))


class TimeLayer(nn.Module):
    """Base of the layers: ``x [T, ..., in_features]`` -> ``linear(x)`` -> a step per time index.

    Put it first among the bases; the neuron base after it provides ``state_cls``,
    ``initial_state(like)``, ``step_params(dtype)`` and ``step(i_t, state, p)``.
    """

    state_cls: type = tuple

    def _init_layer(self, in_features: int, out_features: int, *, bias: bool, batch_first: bool,
                    record_states: bool, validate: bool, device: Any, dtype: Any) -> None:
        self.linear = nn.Linear(in_features, out_features, bias=bias, device=device, dtype=dtype)
        self.batch_first = bool(batch_first)
        self.record_states = bool(record_states)
        self.validate = bool(validate)

    def forward(self, x: Tensor, state: Any = None) -> tuple[Tensor, Any]:
        if self.validate:
            n = self.linear.in_features
            layout = f"[B, T, ..., {n}] (batch first)" if self.batch_first else f"[T, ..., {n}] (time first)"
            check_input("x", x, min_dim=2, features=n, dtype=self.linear.weight.dtype, layout=layout)
        if self.batch_first:
            x = x.transpose(0, 1)
        current = self.linear(x)
        if state is None:
            state = self.initial_state(current[0])
        elif self.validate:
            check_state(state, self.state_cls, current.shape[1:], current)
        out, state = run_over_time(self.step, current, state, self.step_params(current.dtype),
                                   self.record_states, self.state_cls)
        return (out.transpose(0, 1) if self.batch_first else out), state


def run_over_time(step: Callable[[Tensor, Any, Any], tuple[Tensor, Any]], current: Tensor, state: Any, p: Any,
                  record: bool, state_cls: type) -> tuple[Tensor, Any]:
    """Apply ``step`` along dim 0 of ``current``; ``(stacked outputs, final or recorded state)``."""
    outs, states = [], []
    # unbind: one backward node for all steps (T selects would each zero-fill a [T, ...] gradient)
    for i_t in current.unbind(0):
        out, state = step(i_t, state, p)
        outs.append(out)
        if record:
            states.append(state)
    empty = current.new_zeros(current.shape)
    out = torch.stack(outs) if outs else empty
    if record:
        return out, (stack_states(states, state_cls) if states else state_cls(*(empty for _ in state_cls._fields)))
    return out, state
