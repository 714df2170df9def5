"""Population-batched recurrent Izhikevich layer: ``P`` networks in one forward pass."""

from __future__ import annotations

from torch import Tensor, nn

from snn_torch.functional.izhikevich import (
    DEFAULT_DT_MS,
    DEFAULT_METHOD,
    DEFAULT_V0_MV,
    QIU2019,
    IzhikevichParams,
    check_dt,
    check_params,
)
from snn_torch.functional.recurrent import (
    RecurrentState,
    masked_weights,
    recurrent_init,
    recurrent_izhikevich_run,
)
from snn_torch.functional.threshold import SpikeFn, heaviside

__all__ = ["PopulationRecurrentIzhikevich"]


class PopulationRecurrentIzhikevich(nn.Module):
    """``P`` recurrent networks of ``N`` Izhikevich neurons, run as one batch.

    ``weight[p, i, j]`` is the synapse from neuron ``i`` to neuron ``j`` of network ``p``;
    ``mask[p, i, j]`` says whether that connection exists. Masked-out entries have no
    effect whatever their value. Each step costs one batched matmul for the population.

    Args:
        weight: ``[P, N, N]`` float weights (pre x post).
        mask: ``[P, N, N]`` bool connection mask.
        p: neuron parameters; fields may be tensors broadcasting to ``[P, ..., N]``.
        i_background: constant current added to every neuron (mV/ms, the paper's nA).
        trainable: register ``weight`` as an ``nn.Parameter`` (else a buffer).
        spike_fn: spike function; default ``heaviside`` (evolution needs no gradient).
        Others as ``IzhikevichCell``.

    ``forward(i_ext, state=None)`` takes ``i_ext`` ``[T, P, ..., N]`` (mV/ms) and returns
    ``(spikes [T, P, ..., N], state)``.
    """

    def __init__(
        self,
        weight: Tensor,
        mask: Tensor,
        p: IzhikevichParams = QIU2019,
        *,
        i_background: float = 0.0,
        trainable: bool = False,
        dt_ms: float = DEFAULT_DT_MS,
        method: str = DEFAULT_METHOD,
        spike_fn: SpikeFn | None = None,
        substep_reset: bool = True,
        v0_mv: float = DEFAULT_V0_MV,
    ) -> None:
        super().__init__()
        masked_weights(weight, mask)  # validates shapes and dtypes
        if trainable:
            self.weight = nn.Parameter(weight.detach().clone())
        else:
            self.register_buffer("weight", weight.detach().clone())
        self.register_buffer("mask", mask.clone())
        self.p = check_params(p)
        self.i_background = float(i_background)
        self.dt_ms = check_dt(dt_ms)
        self.method = method
        self.spike_fn = spike_fn if spike_fn is not None else heaviside
        self.substep_reset = substep_reset
        self.v0_mv = float(v0_mv)

    @property
    def num_networks(self) -> int:
        return self.weight.shape[0]

    @property
    def num_neurons(self) -> int:
        return self.weight.shape[-1]

    def initial_state(self, like: Tensor) -> RecurrentState:
        """Rest state shaped ``like`` (``[P, ..., N]``), in ``like``'s dtype and device."""
        return recurrent_init(like.shape, self.p, v0_mv=self.v0_mv, device=like.device, dtype=like.dtype)

    def forward(self, i_ext: Tensor, state: RecurrentState | None = None) -> tuple[Tensor, RecurrentState]:
        if not isinstance(i_ext, Tensor) or i_ext.dim() < 3:
            shape = tuple(i_ext.shape) if isinstance(i_ext, Tensor) else type(i_ext).__name__
            raise ValueError(f"i_ext must be [T, P, ..., N], got {shape}")
        if i_ext.shape[1] != self.num_networks or i_ext.shape[-1] != self.num_neurons:
            raise ValueError(
                f"i_ext must be [T, {self.num_networks}, ..., {self.num_neurons}], got {tuple(i_ext.shape)}"
            )
        w_eff = masked_weights(self.weight, self.mask).to(i_ext.dtype)
        if self.i_background:
            i_ext = i_ext + self.i_background
        if state is None:
            state = self.initial_state(i_ext[0])
        return recurrent_izhikevich_run(
            i_ext, state, w_eff, self.p, dt_ms=self.dt_ms, method=self.method,
            spike_fn=self.spike_fn, substep_reset=self.substep_reset, validate=True,
        )

    def extra_repr(self) -> str:
        return (f"P={self.num_networks}, N={self.num_neurons}, p={tuple(self.p)}, dt_ms={self.dt_ms}, "
                f"i_background={self.i_background}")
