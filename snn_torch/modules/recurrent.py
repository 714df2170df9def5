"""Population-batched recurrent networks over weights and masks: ``P`` networks in one forward pass.

``PopulationRecurrentIzhikevich`` (spiking) and ``PopulationRecurrentSigmoid`` (its sigmoid
twin) hold ``weight[p, i, j]`` (synapse from node ``i`` to node ``j`` of network ``p``) and
``mask[p, i, j]`` (whether it exists). They are the phenotype of every NEAT genome in this
toolkit, and ordinary ``nn.Module`` layers too.

Two ways to run them:
- ``forward(i_ext [T, P, ..., N], state)``: one output per time step (a layer in a model).
- ``control_step(i_ext [B, N], state, substeps=...)``: a control step of a closed loop, the
  current held for ``substeps`` substeps, spikes counted. Rows map to networks by an index
  (``network=``), so several episodes share a network and finished episodes can be dropped
  without copying weights. On the CPU this runs the C kernel
  (``snn_torch.kernels.network``), on CUDA a compiled step
  (``snn_torch.kernels.compiled``), else the torch step; all three give the same results (the first
  two bit for bit against the torch step on the CPU, tested).
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from snn_torch.functional.counter_rng import BernoulliSources
from snn_torch.functional.decode import ordered_matvec, ordered_sigmoid
from snn_torch.functional.izhikevich import (
    DEFAULT_DT_MS,
    DEFAULT_METHOD,
    DEFAULT_V0_MV,
    QIU2019,
    IzhikevichParams,
    check_dt,
    check_method,
    check_params,
)
from snn_torch.functional.recurrent import (
    RecurrentState,
    masked_weights,
    recurrent_init,
    recurrent_izhikevich_run,
    recurrent_izhikevich_steps,
    synaptic_decay,
)
from snn_torch.functional.scalars import scalar
from snn_torch.functional.threshold import SpikeFn, heaviside
from snn_torch.kernels.compiled import CompiledSubstep
from snn_torch.kernels.network import check_network_index, kernel_supports, network_steps_kernel
from snn_torch.kernels.sigmoid import (
    SIGMOID_MAX_NODES,
    sigmoid_kernel_supports,
    sigmoid_update_kernel,
)

__all__ = ["PopulationRecurrentIzhikevich", "PopulationRecurrentSigmoid", "BACKENDS"]

BACKENDS = ("auto", "kernel", "compiled", "torch")


def _check_backend(backend: str) -> str:
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    return backend


def _rows_weights(w_eff: Tensor, network: Tensor | None, rows: int) -> Tensor:
    if network is None:
        if w_eff.shape[0] != rows:
            raise ValueError(f"the layer holds {w_eff.shape[0]} networks for {rows} rows; pass network= to map rows")
        return w_eff
    if network.shape != (rows,) or network.dtype != torch.int64:
        raise ValueError(f"network must be a [{rows}] int64 tensor, got {tuple(network.shape)} {network.dtype}")
    return w_eff.index_select(0, network)


class _PopulationNetwork(nn.Module):
    """Weights and masks of ``P`` networks, and the cached effective weights."""

    def __init__(self, weight: Tensor, mask: Tensor, trainable: bool, scale: float) -> None:
        super().__init__()
        masked_weights(weight, mask)  # validates shapes and dtypes
        if trainable:
            self.weight = nn.Parameter(weight.detach().clone())
        else:
            self.register_buffer("weight", weight.detach().clone())
        self.register_buffer("mask", mask.clone())
        self.scale = float(scale)
        self._w_eff: tuple[tuple, Tensor] | None = None
        self._gathered: tuple[Tensor, Tensor, Tensor] | None = None
        self._network_checked: Tensor | None = None  # the last row -> network index checked

    @property
    def num_networks(self) -> int:
        return self.weight.shape[0]

    @property
    def num_neurons(self) -> int:
        return self.weight.shape[-1]

    def effective_weight(self, dtype: torch.dtype | None = None) -> Tensor:
        """``weight`` where ``mask``, else 0, times the layer's scale, in ``dtype``: ``[P, N, N]``.

        Cached while the weights do not change (no gradient, same version counter)."""
        dtype = self.weight.dtype if dtype is None else dtype
        key = (self.weight._version, self.mask._version, self.weight.data_ptr(), self.weight.device, dtype)
        if self._w_eff is not None and self._w_eff[0] == key and not self.weight.requires_grad:
            return self._w_eff[1]
        w = masked_weights(self.weight, self.mask).to(dtype)
        if self.scale != 1.0:
            w = w * self.scale
        if not self.weight.requires_grad:
            self._w_eff = (key, w)
        return w

    def _row_weights(self, dtype: torch.dtype, network: Tensor | None, rows: int) -> Tensor:
        """Effective weights of each row's network ``[B, N, N]``; the gather is reused while the
        same ``network`` tensor comes back (a rollout between compactions)."""
        w = self.effective_weight(dtype)
        if network is None:
            return _rows_weights(w, None, rows)
        cached = self._gathered
        if cached is not None and cached[0] is network and cached[1] is w:
            return cached[2]
        gathered = _rows_weights(w, network, rows)
        self._gathered = (network, w, gathered)
        return gathered

    def check_network_once(self, network: Tensor | None, rows: int) -> None:
        """``check_network_index`` for the row -> network index ``network`` (None: nothing to
        check), once per index tensor: a closed loop passes the same one every step until it
        compacts, and the kernels read weights by it."""
        if network is not None and network is not self._network_checked:
            check_network_index(network, rows, self.num_networks)
            self._network_checked = network

    def _check_rows(self, x: Tensor, name: str, network: Tensor | None) -> None:
        if not isinstance(x, Tensor) or x.dim() != 2 or x.shape[-1] != self.num_neurons:
            shape = tuple(x.shape) if isinstance(x, Tensor) else type(x).__name__
            raise ValueError(f"{name} must be [B, {self.num_neurons}], got {shape}")
        if network is None and x.shape[0] != self.num_networks:
            raise ValueError(f"{name} has {x.shape[0]} rows for {self.num_networks} networks; pass network= "
                             "to map rows to networks")


class PopulationRecurrentIzhikevich(_PopulationNetwork):
    """``P`` recurrent networks of ``N`` Izhikevich neurons, run as one batch.

    Masked-out entries have no effect whatever their value.

    Args:
        weight: ``[P, N, N]`` float weights (pre x post).
        mask: ``[P, N, N]`` bool connection mask.
        p: neuron parameters; fields may be tensors broadcasting to ``[P, ..., N]``.
        i_background: constant current added to every neuron (mV/ms, the paper's nA).
        synapse_kick_mv: None: a spike of neuron ``i`` adds ``weight[i, j]`` (mV/ms) to neuron
            ``j``'s current for one step. A number: the weights are in units of this kick, a
            spike moves the target's membrane by ``weight * synapse_kick_mv`` mV whatever
            ``dt_ms`` (current ``weight * synapse_kick_mv / dt_ms`` for one step).
        synapse_tau_ms: time constant (ms) of exponential synapses: a spike's current decays as
            ``exp(-t / tau)`` and carries the same charge as with 0 (the default: it lasts one
            step). Above 0 the state is a ``SynapticState`` and ``control_step`` runs the torch
            step or the C kernel (the compiled step carries no synaptic current yet).
        trainable: register ``weight`` as an ``nn.Parameter`` (else a buffer).
        spike_fn: spike function; default ``heaviside`` (evolution needs no gradient).
        backend: how ``control_step`` runs: ``"auto"`` (C kernel on the CPU where it applies,
            compiled on CUDA, else torch), ``"kernel"``, ``"compiled"`` or ``"torch"``.
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
        synapse_kick_mv: float | None = None,
        synapse_tau_ms: float = 0.0,
        trainable: bool = False,
        dt_ms: float = DEFAULT_DT_MS,
        method: str = DEFAULT_METHOD,
        spike_fn: SpikeFn | None = None,
        substep_reset: bool = True,
        v0_mv: float = DEFAULT_V0_MV,
        backend: str = "auto",
    ) -> None:
        dt_ms = check_dt(dt_ms)
        if synapse_kick_mv is not None and not (isinstance(synapse_kick_mv, (int, float))
                                                and float(synapse_kick_mv) == float(synapse_kick_mv)):
            raise ValueError(f"synapse_kick_mv must be a number or None, got {synapse_kick_mv!r}")
        super().__init__(weight, mask, trainable, 1.0 if synapse_kick_mv is None else synapse_kick_mv / dt_ms)
        self.p = check_params(p)
        self.i_background = float(i_background)
        self.synapse_kick_mv = synapse_kick_mv
        self.dt_ms = dt_ms
        self.syn_decay = synaptic_decay(synapse_tau_ms, dt_ms)
        self.synapse_tau_ms = float(synapse_tau_ms)
        check_method(method)
        self.method = method
        self.spike_fn = spike_fn if spike_fn is not None else heaviside
        self.substep_reset = substep_reset
        self.v0_mv = float(v0_mv)
        self.backend = _check_backend(backend)
        self._compiled: CompiledSubstep | None = None
        self._supported: dict[tuple, bool] = {}

    def initial_state(self, like: Tensor | tuple[int, ...]) -> RecurrentState:
        """Rest state: ``v = v0_mv``, ``u = b v``, no spikes (a ``SynapticState`` with no current
        under a synaptic time constant). ``like``: a tensor (its shape, dtype and device) or a
        shape (the weights' dtype and device)."""
        synaptic = self.syn_decay is not None
        if isinstance(like, Tensor):
            return recurrent_init(like.shape, self.p, v0_mv=self.v0_mv, device=like.device, dtype=like.dtype,
                                  synaptic=synaptic)
        return recurrent_init(tuple(like), self.p, v0_mv=self.v0_mv, device=self.weight.device,
                              dtype=self.weight.dtype, synaptic=synaptic)

    def forward(self, i_ext: Tensor, state: RecurrentState | None = None) -> tuple[Tensor, RecurrentState]:
        if not isinstance(i_ext, Tensor) or i_ext.dim() < 3:
            shape = tuple(i_ext.shape) if isinstance(i_ext, Tensor) else type(i_ext).__name__
            raise ValueError(f"i_ext must be [T, P, ..., N], got {shape}")
        if i_ext.shape[1] != self.num_networks or i_ext.shape[-1] != self.num_neurons:
            raise ValueError(
                f"i_ext must be [T, {self.num_networks}, ..., {self.num_neurons}], got {tuple(i_ext.shape)}"
            )
        w_eff = self.effective_weight(i_ext.dtype)
        if self.i_background:
            i_ext = i_ext + self.i_background
        if state is None:
            state = self.initial_state(i_ext[0])
        return recurrent_izhikevich_run(
            i_ext, state, w_eff, self.p, dt_ms=self.dt_ms, method=self.method,
            spike_fn=self.spike_fn, substep_reset=self.substep_reset, validate=True, syn_decay=self.syn_decay,
        )

    def path(self, state: RecurrentState) -> str:
        """Which code ``control_step`` runs for ``state``: ``"kernel"``, ``"compiled"`` or ``"torch"``
        (the compiled step carries no synaptic current: with ``synapse_tau_ms`` > 0 not that one)."""
        plain = (self.method == "heun" and self.substep_reset and self.spike_fn is heaviside
                 and not self.weight.requires_grad)
        key = (state.v.device, state.v.dtype, state.v.dim(), state.v.shape[-1], plain)
        if self._supported.get(key) is None:
            self._supported[key] = plain and kernel_supports(state.v, self.p)
        if self.backend in ("auto", "kernel") and self._supported[key]:
            return "kernel"
        if self.backend == "kernel":
            raise ValueError("backend='kernel' needs CPU float32/64 state, N <= 64, scalar neuron parameters, "
                             "Heun with the sub-step reset, heaviside spikes, no gradient and a C compiler")
        if self.backend == "compiled" and self.syn_decay is not None:
            raise ValueError("backend='compiled' carries no synaptic current: use 'auto', 'kernel' or 'torch' "
                             "with synapse_tau_ms > 0")
        if plain and self.syn_decay is None and (self.backend == "compiled"
                                                 or (self.backend == "auto" and state.v.device.type == "cuda")):
            return "compiled"
        return "torch"

    def control_step(self, i_ext: Tensor, state: RecurrentState | None = None, *, substeps: int,
                     network: Tensor | None = None, source_spikes: Tensor | None = None,
                     inplace: bool = False) -> tuple[Tensor, RecurrentState]:
        """One control step: ``i_ext`` (mV/ms, plus ``i_background``) held for ``substeps`` steps.

        Args:
            i_ext: ``[B, N]`` external current of each row.
            state: ``RecurrentState`` of ``[B, N]`` tensors; None: at rest.
            substeps: steps of ``dt_ms`` in the control step (a control period of
                ``substeps * dt_ms`` ms).
            network: ``[B]`` int64, the network of each row; None: row ``p`` is network ``p``.
            source_spikes: ``[B, substeps, S]`` spikes of spike-source nodes ``0 .. S-1`` (their
                ``v``, ``u`` held), or ``BernoulliSources`` (``BernoulliEncoder``'s: the kernel
                draws them in C, the torch paths in torch, the same spikes); None: none.
            inplace: the C kernel may update ``state``'s tensors in place (a closed loop that
                owns its state saves three copies per step); other paths never do.

        Returns:
            ``(counts [B, N], state)``: spikes per node over the control step, and the state.
        """
        self._check_rows(i_ext, "i_ext", network)
        if not isinstance(substeps, int) or substeps < 1:
            raise ValueError(f"substeps must be a positive int, got {substeps!r}")
        if state is None:
            state = self.initial_state(i_ext)
        if state.v.shape != i_ext.shape:
            raise ValueError(f"state must be [{i_ext.shape[0]}, {self.num_neurons}] like i_ext, got "
                             f"{tuple(state.v.shape)}")
        self.check_network_once(network, i_ext.shape[0])
        if self.i_background:
            i_ext = i_ext + self.i_background
        path = self.path(state)
        if path == "kernel":
            w_eff = self.effective_weight(state.v.dtype)
            if any(t.shape != i_ext.shape or t.dtype != i_ext.dtype for t in state):  # (v, u, z): no synapses
                raise ValueError(f"state tensors must all be [{i_ext.shape[0]}, {self.num_neurons}] of {i_ext.dtype}")
            return network_steps_kernel(i_ext, state, w_eff, self.p, dt_ms=self.dt_ms, substeps=substeps,
                                        network=network, source_spikes=source_spikes, inplace=inplace, trusted=True,
                                        syn_decay=self.syn_decay)
        if isinstance(source_spikes, BernoulliSources):  # the torch paths draw them here
            source_spikes = source_spikes.spikes(substeps, state.v.dtype)
        w = self._row_weights(state.v.dtype, network, i_ext.shape[0])
        if path == "compiled":
            if self._compiled is None:
                self._compiled = CompiledSubstep(self.p, dt_ms=self.dt_ms, method=self.method)
            counts = torch.zeros_like(state.v)
            for q in range(substeps):
                src = None if source_spikes is None else source_spikes[:, q].to(state.v.dtype)
                state, counts = self._compiled(i_ext, state, w, counts, src)
            return counts, state
        return recurrent_izhikevich_steps(i_ext, state, w, self.p, substeps=substeps, dt_ms=self.dt_ms,
                                          source_spikes=source_spikes, method=self.method, spike_fn=self.spike_fn,
                                          substep_reset=self.substep_reset, syn_decay=self.syn_decay)

    def extra_repr(self) -> str:
        return (f"P={self.num_networks}, N={self.num_neurons}, p={tuple(self.p)}, dt_ms={self.dt_ms}, "
                f"i_background={self.i_background}, synapse_kick_mv={self.synapse_kick_mv}, "
                f"synapse_tau_ms={self.synapse_tau_ms}, backend={self.backend!r}")


class PopulationRecurrentSigmoid(_PopulationNetwork):
    """``P`` recurrent sigmoid networks over weights and masks: the spiking layer's twin.

    Synchronous, one-step delay: each update sets every node to
    ``sigmoid(slope * sum_i y_i w[i, j])`` (``ordered_matvec``: summed over ``i`` ascending), then clamps the
    first ``num_clamped`` nodes to the inputs and the next ``num_bias`` to 1. NEAT's
    steepened sigmoid: ``slope = 4.9`` ([NEAT02]).

    ``control_step(inputs [B, num_clamped], values [B, N], updates=1, network=None)`` returns
    the node values after ``updates`` updates (values start at 0: ``initial_state``). ``backend``:
    ``"auto"`` runs the updates in C on the CPU where it can
    (``snn_torch.kernels.sigmoid``), ``"kernel"`` insists,
    ``"torch"`` never: the same bits either way.
    """

    def __init__(self, weight: Tensor, mask: Tensor, *, num_clamped: int, num_bias: int = 0,
                 slope: float = 4.9, trainable: bool = False, backend: str = "auto") -> None:
        super().__init__(weight, mask, trainable, 1.0)
        self.backend = _check_backend(backend)
        if self.backend == "compiled":
            raise ValueError("PopulationRecurrentSigmoid runs on backend 'auto', 'kernel' or 'torch'")
        N = self.num_neurons
        if not 0 <= num_clamped <= N or not 0 <= num_bias <= N - num_clamped:
            raise ValueError(f"num_clamped ({num_clamped}) and num_bias ({num_bias}) must fit in {N} nodes")
        self.num_clamped, self.num_bias, self.slope = int(num_clamped), int(num_bias), float(slope)

    def initial_state(self, rows: int) -> Tensor:
        """All node values 0, ``[rows, N]``."""
        return torch.zeros(rows, self.num_neurons, dtype=self.weight.dtype, device=self.weight.device)

    def _clamp(self, y: Tensor, inputs: Tensor) -> Tensor:
        k, b = self.num_clamped, self.num_bias
        parts = [inputs.to(y.dtype), torch.ones_like(y[:, k : k + b]), y[:, k + b :]]
        return torch.cat(parts, dim=1)

    def control_step(self, inputs: Tensor, values: Tensor | None = None, *, updates: int = 1,
                     network: Tensor | None = None) -> Tensor:
        """``updates`` synchronous updates with the inputs clamped; the node values ``[B, N]``."""
        if not isinstance(inputs, Tensor) or inputs.dim() != 2 or inputs.shape[-1] != self.num_clamped:
            shape = tuple(inputs.shape) if isinstance(inputs, Tensor) else type(inputs).__name__
            raise ValueError(f"inputs must be [B, {self.num_clamped}], got {shape}")
        if values is None:
            values = self.initial_state(inputs.shape[0])
        self._check_rows(values, "values", network)
        self.check_network_once(network, values.shape[0])
        y = values
        use_kernel = self.backend != "torch" and not self.weight.requires_grad and sigmoid_kernel_supports(values)
        if self.backend == "kernel" and not use_kernel:
            raise ValueError(f"backend='kernel' needs CPU float32/64 values, N <= {SIGMOID_MAX_NODES}, no gradient "
                             "and a C compiler")
        if use_kernel:
            # every update in C, the sigmoid portable_math's: the same bits, one call
            w_eff, inputs = self.effective_weight(values.dtype), inputs.to(values.dtype)
            return sigmoid_update_kernel(y, inputs, w_eff, network, num_bias=self.num_bias, slope=self.slope,
                                         updates=updates)
        w = self._row_weights(values.dtype, network, values.shape[0])
        for _ in range(updates):
            y = self._clamp(y, inputs)
            acc = ordered_matvec(y, w)
            y = self._clamp(ordered_sigmoid(scalar(self.slope, acc) * acc), inputs)
        return y

    def forward(self, inputs: Tensor, values: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """``inputs [T, P, num_clamped]``: one update per step; ``(values [T, P, N], last values)``."""
        outs = []
        for t in range(inputs.shape[0]):
            values = self.control_step(inputs[t], values)
            outs.append(values)
        return torch.stack(outs), values

    def extra_repr(self) -> str:
        return (f"P={self.num_networks}, N={self.num_neurons}, num_clamped={self.num_clamped}, "
                f"num_bias={self.num_bias}, slope={self.slope}")
