"""``Stateful``: a layer that keeps its own state between calls, to sit in ``nn.Sequential``.

The layers return ``(output, state)`` and keep nothing; ``nn.Sequential`` passes one tensor.
``Stateful(layer)`` returns only the output and keeps the state on the wrapper (a plain
attribute, never a buffer, so it is not saved with ``state_dict``). Call ``reset_states(model)``
before each new sequence (batch) and ``detach_states(model)`` to truncate backpropagation
through time between chunks of one long sequence.
"""

from __future__ import annotations

from typing import Any

from torch import Tensor, nn

__all__ = ["Stateful", "reset_states", "detach_states"]


class Stateful(nn.Module):
    """Wrap ``layer`` (``forward(x, state) -> (out, state)``) as ``forward(x) -> out``.

    ``state`` holds the layer's last state (``None`` after ``reset_state``). When the layer has
    ``record_states=True``, ``recorded`` holds every step's state and ``state`` the last one.
    """

    def __init__(self, layer: nn.Module) -> None:
        super().__init__()
        self.layer = layer
        self.state: Any = None
        self.recorded: Any = None

    def forward(self, x: Tensor) -> Tensor:
        out, state = self.layer(x, self.state)
        if getattr(self.layer, "record_states", False):
            self.recorded = state  # [T, ...] per field (time first, also with batch_first)
            state = type(state)(*(t[-1] for t in state)) if state[0].shape[0] else self.state
        self.state = state
        return out

    def reset_state(self) -> None:
        """Forget the state: the next call starts from rest."""
        self.state = None
        self.recorded = None

    def detach_state(self) -> None:
        """Keep the state's values but cut its autograd history (truncated BPTT)."""
        if self.state is not None:
            self.state = type(self.state)(*(t.detach() for t in self.state))
        if self.recorded is not None:
            self.recorded = type(self.recorded)(*(t.detach() for t in self.recorded))


def reset_states(module: nn.Module) -> None:
    """``reset_state()`` on every ``Stateful`` inside ``module``."""
    for m in module.modules():
        if isinstance(m, Stateful):
            m.reset_state()


def detach_states(module: nn.Module) -> None:
    """``detach_state()`` on every ``Stateful`` inside ``module``."""
    for m in module.modules():
        if isinstance(m, Stateful):
            m.detach_state()
