"""The C kernel of ``PopulationRecurrentIzhikevich`` on the CPU: control steps of many networks.

``recurrent_izhikevich_steps`` costs ~50 small tensor ops per substep, and for the small
networks NEAT evolves (N ~ 8) per-op overhead, not arithmetic, sets its speed. The kernel
(``snn_torch/kernels/csrc/recurrent_izhikevich.c``) runs all the substeps of a control step in C, 8
networks side by side per thread, at a compile-time constant size for the usual sizes; one
call per control step. It is generic: any number of nodes up to ``MAX_NODES``, any inputs
(constant currents, and spike-source nodes for rate-coded inputs), rows mapped to networks by
an index (several episodes per network, finished episodes compacted away without copying
weights).

``RateControlKernel`` wraps it in a whole control step of a rate-coded controller
(encoder, network, rate window, weighted readout: ``evolution.SpikingController`` on the CPU),
so a closed loop pays one C call per step instead of a dozen small tensor ops.

It repeats the torch step's operations in order with no contraction, so the two agree bit for
bit (``tests/snn_torch/test_network_kernel.py``): results do not depend on whether a C compiler
is present. Rows are independent: a row's result does not depend on its batch or the thread
count.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import Tensor

from snn_torch.functional.counter_rng import BernoulliSources
from snn_torch.functional.izhikevich import IzhikevichParams
from snn_torch.functional.recurrent import RecurrentState, SynapticState
from snn_torch.kernels.build import library_loader

__all__ = ["MAX_NODES", "kernel_available", "kernel_supports", "network_steps_kernel", "check_network_index",
           "RateControlKernel"]

MAX_NODES = 64  # lane buffers live on the stack
_CSRC = Path(__file__).resolve().parent / "csrc"


# What the fallback costs (benchmarks/seam_speed.py --torch-path, this 2-core CPU, one thread).
TORCH_PATH_NOTE = ("snn-neat: spiking networks run on the torch path (no C network kernel): the same results, "
                   "but closed loops of small networks run about 25x (150 networks) to 10x (9000) slower "
                   "on the CPU; install a C compiler (cc/gcc) for the kernel")
_library = library_loader("recurrent_izhikevich", _CSRC / "recurrent_izhikevich.c", _CSRC / "recurrent_izhikevich.h",
                          TORCH_PATH_NOTE)


def kernel_available() -> bool:
    """True if the kernel compiled (once per machine) and ``SNN_NEAT_C_KERNELS`` is not ``0``."""
    return _library() is not None


def kernel_supports(v: Tensor, p: IzhikevichParams) -> bool:
    """Whether the kernel can run this case: CPU float32/64 ``[B, N]`` state, N <= 64, scalar
    neuron parameters, and a built kernel."""
    scalars = all(isinstance(x, (int, float)) for x in p)
    return (scalars and v.device.type == "cpu" and v.dtype in (torch.float32, torch.float64) and v.dim() == 2
            and 1 <= v.shape[-1] <= MAX_NODES and kernel_available())


def check_network_index(network: Tensor, rows: int, networks: int) -> None:
    """``network`` must be a ``[rows]`` int64 tensor of indices in ``[0, networks)`` (``ValueError``)."""
    if not isinstance(network, Tensor) or network.shape != (rows,) or network.dtype != torch.int64:
        shape = (tuple(network.shape), network.dtype) if isinstance(network, Tensor) else type(network).__name__
        raise ValueError(f"network must be a [{rows}] int64 tensor, got {shape}")
    if rows:
        lo, hi = (int(x) for x in torch.aminmax(network))
        if lo < 0 or hi >= networks:
            raise ValueError(f"network indices must lie in [0, {networks}), got {lo} .. {hi}")


def _check(i_ext: Tensor, state: RecurrentState, w_eff: Tensor, p: IzhikevichParams, network: Tensor | None) -> None:
    if not kernel_supports(state.v, p):
        raise ValueError("the C network kernel needs CPU float32/float64 [B, N] state, N <= 64, scalar neuron "
                         "parameters and a working C compiler; check kernel_supports() first")
    dtype, (B, N) = state.v.dtype, state.v.shape
    if any(t.shape != (B, N) or t.dtype != dtype for t in state):
        raise ValueError(f"state tensors must all be [{B}, {N}] of {dtype}")
    if w_eff.dim() != 3 or w_eff.shape[1:] != (N, N) or w_eff.dtype != dtype:
        raise ValueError(f"w_eff must be [G, {N}, {N}] of {dtype}, got {tuple(w_eff.shape)} {w_eff.dtype}")
    if i_ext.shape != (B, N) or i_ext.dtype != dtype:
        raise ValueError(f"i_ext must be [{B}, {N}] of {dtype}, got {tuple(i_ext.shape)} {i_ext.dtype}")
    if network is None:
        if w_eff.shape[0] != B:
            raise ValueError(f"w_eff holds {w_eff.shape[0]} networks for {B} rows; pass network= to map rows")
    else:
        check_network_index(network, B, w_eff.shape[0])


def network_steps_kernel(
    i_ext: Tensor, state: RecurrentState, w_eff: Tensor, p: IzhikevichParams, *, dt_ms: float, substeps: int,
    network: Tensor | None = None, source_spikes: Tensor | BernoulliSources | None = None, inplace: bool = False,
    trusted: bool = False, syn_decay: float | None = None,
) -> tuple[Tensor, RecurrentState]:
    """``recurrent_izhikevich_steps`` in C (Heun, sub-step reset, Heaviside spikes).

    Args:
        i_ext: external current (mV/ms) ``[B, N]``, constant over the substeps.
        state: ``RecurrentState`` of ``[B, N]`` tensors (not modified).
        w_eff: effective weights ``[G, N, N]`` (pre x post, mV/ms per spike), already masked.
        network: ``[B]`` int64, the network (index into ``w_eff``) of each row; None: row ``r``
            runs network ``r`` (then ``G == B``).
        source_spikes: ``[B, substeps, S]`` spikes of spike-source nodes ``0 .. S-1``, or
            ``BernoulliSources`` (drawn here, in C), or None.
        inplace: update ``state``'s tensors in place (they must be contiguous) instead of copies.
        trusted: skip the checks of shapes, dtypes and network indices (a caller that made them
            already, once per batch: ``PopulationRecurrentIzhikevich.control_step``). An index
            outside ``w_eff`` would read outside its memory.
        syn_decay: exponential synapses' per-step decay (``state`` a ``SynapticState``), or None.

    Returns:
        ``(counts, new_state)``: spikes per node over the substeps ``[B, N]``, and the state.
    """
    dtype, (B, N) = state.v.dtype, state.v.shape
    if not trusted:
        _check(i_ext, state, w_eff, p, network)
    if (syn_decay is not None) != isinstance(state, SynapticState):
        raise ValueError("syn_decay and a SynapticState go together (exponential synapses), or neither")
    net_ptr = None if network is None else network.contiguous().data_ptr()
    n_src, src_ptr, prob_ptr, keys_ptr, base = 0, None, None, None, 0
    if isinstance(source_spikes, BernoulliSources):
        prob, keys = source_spikes.prob, source_spikes.keys
        if prob.dim() != 2 or prob.shape[0] != B or prob.shape[1] > N or prob.dtype != torch.float64:
            raise ValueError(f"BernoulliSources.prob must be [{B}, S] float64 with S <= {N}, got "
                             f"{tuple(prob.shape)} {prob.dtype}")
        if keys.shape != (B,) or keys.dtype != torch.int64:
            raise ValueError(f"BernoulliSources.keys must be a [{B}] int64 tensor, got {tuple(keys.shape)} {keys.dtype}")
        prob, keys = prob.contiguous(), keys.contiguous()
        n_src, prob_ptr, keys_ptr, base = prob.shape[1], prob.data_ptr(), keys.data_ptr(), int(source_spikes.base)
    elif source_spikes is not None:
        if source_spikes.dim() != 3 or source_spikes.shape[:2] != (B, substeps) or source_spikes.shape[2] > N:
            raise ValueError(f"source_spikes must be [{B}, {substeps}, S] with S <= {N}, got "
                             f"{tuple(source_spikes.shape)}")
        source_spikes = source_spikes.to(dtype).contiguous()
        n_src, src_ptr = source_spikes.shape[2], source_spikes.data_ptr()
    if inplace and all(t.is_contiguous() for t in state):
        tensors = tuple(state)
    else:
        tensors = tuple(t.contiguous().clone() for t in state)  # the kernel updates these in place
    v, u, z = tensors[:3]
    syn = tensors[3] if syn_decay is not None else None
    w = w_eff.contiguous()
    i = i_ext.contiguous()
    counts = torch.empty_like(v)
    lib = _library()
    fn = lib.izh_network_steps_f32 if dtype == torch.float32 else lib.izh_network_steps_f64
    fn(v.data_ptr(), u.data_ptr(), z.data_ptr(), counts.data_ptr(), w.data_ptr(), net_ptr, i.data_ptr(), src_ptr,
       prob_ptr, keys_ptr, base, B, N, n_src, int(substeps), float(dt_ms), float(p.a), float(p.b), float(p.c), float(p.d), float(p.v_peak),
       None if syn is None else syn.data_ptr(), 0.0 if syn_decay is None else float(syn_decay), torch.get_num_threads())
    return counts, RecurrentState(v, u, z) if syn is None else SynapticState(v, u, z, syn)


class RateControlKernel:
    """One control step of a rate-coded controller in one C call: encoder -> network steps ->
    rate window -> weighted readout (``evolution.SpikingController.act`` on the CPU; its torch
    modules are the definition, and this repeats their operations in order: the same bits,
    tested). The constants are bound once, so a step costs one C call and two allocations.

    Args:
        w_eff: effective weights ``[G, N, N]`` (masked, kick-scaled; mV/ms per spike).
        p: scalar neuron parameters; dt_ms: substep (ms); substeps: substeps per control step.
        gain: current encoder (``bernoulli`` False): input ``k`` gets ``gain * x_k + iconst[k]``
            (mV/ms); Bernoulli encoder: input ``k`` spikes with probability ``x_k * gain`` per
            substep (drawn from each row's stream, ``BernoulliSources``' counters).
        iconst: ``[N]`` constant current of every node (background, bias nodes), mV/ms.
        w_out: ``[G, N, K]`` readout weights; rest: ``[N]`` rates subtracted first (Hz), or None.
        syn_decay: exponential synapses' per-step decay (states are then ``SynapticState``s), or None.

    Every tensor must be contiguous, on the CPU, of one dtype (float32 or float64), N <= 64.
    """

    def __init__(self, w_eff: Tensor, p: IzhikevichParams, *, dt_ms: float, substeps: int, gain: float,
                 bernoulli: bool, iconst: Tensor, w_out: Tensor, rest: Tensor | None,
                 syn_decay: float | None = None) -> None:
        G, N, _ = w_eff.shape
        tensors = {"w_eff": w_eff, "iconst": iconst, "w_out": w_out, **({} if rest is None else {"rest": rest})}
        for name, t in tensors.items():
            if t.dtype != w_eff.dtype or t.device.type != "cpu" or not t.is_contiguous():
                raise ValueError(f"{name} must be a contiguous CPU tensor of {w_eff.dtype}")
        if w_eff.dtype not in (torch.float32, torch.float64) or not 1 <= N <= MAX_NODES:
            raise ValueError(f"w_eff must be [G, N, N] float32/float64 with N <= {MAX_NODES}, got "
                             f"{tuple(w_eff.shape)} {w_eff.dtype}")
        if iconst.shape != (N,) or w_out.dim() != 3 or w_out.shape[:2] != (G, N) or \
                (rest is not None and rest.shape != (N,)):
            raise ValueError(f"iconst and rest must be [{N}], w_out [{G}, {N}, K]")
        lib = _library()
        if lib is None:
            raise ValueError("the C network kernel is not available (no C compiler, or SNN_NEAT_C_KERNELS=0)")
        self._fn = lib.izh_rate_control_step_f32 if w_eff.dtype == torch.float32 else lib.izh_rate_control_step_f64
        self._keep = (w_eff, iconst, w_out, rest)  # the pointers below stay valid while these live
        self.num_networks, self.num_neurons, self.num_outputs = G, N, w_out.shape[2]
        self._consts = (float(gain), iconst.data_ptr(), w_eff.data_ptr(), w_out.data_ptr(),
                        None if rest is None else rest.data_ptr(), int(substeps), float(dt_ms),
                        *(float(x) for x in (p.a, p.b, p.c, p.d, p.v_peak)))
        self.bernoulli = bool(bernoulli)
        self.syn_decay = syn_decay

    def __call__(self, x: Tensor, state: RecurrentState, network: Tensor, keys: Tensor | None, base: int,
                 history: Tensor, slot: int, rate_div: float) -> tuple[Tensor, Tensor]:
        """``(drive [B, K], counts [B, N])`` for observations ``x [B, S]`` in [0, 1].

        Trusted: the caller checked shapes, dtypes, contiguity and the network indices (an index
        outside ``w_eff`` would read outside its memory). ``state`` (``[B, N]`` tensors) and the
        rate window ``history [W, B, N]`` are updated in place (``slot``: this step's place in it);
        rates are spikes / ``rate_div`` (s); ``keys [B]`` and ``base``: the Bernoulli draws'
        streams and first counter."""
        v, u, z = state[:3]
        syn = state.s if self.syn_decay is not None else None
        B = v.shape[0]
        counts = torch.empty_like(v)
        drive = v.new_empty((B, self.num_outputs))
        gain, iconst, w, w_out, rest, substeps, dt, a, b, c, d, vpeak = self._consts
        self._fn(v.data_ptr(), u.data_ptr(), z.data_ptr(), counts.data_ptr(), w, network.data_ptr(), x.data_ptr(),
                 x.shape[1], gain, iconst, keys.data_ptr() if self.bernoulli else None, base, history.data_ptr(),
                 history.shape[0], slot, rate_div, w_out, self.num_outputs, rest, drive.data_ptr(), B,
                 self.num_neurons, substeps, dt, a, b, c, d, vpeak, None if syn is None else syn.data_ptr(),
                 0.0 if self.syn_decay is None else float(self.syn_decay), torch.get_num_threads())
        return drive, counts

    def decode(self, drive: Tensor, sigma: Tensor, decoder: int, action_max: float, threshold: float) -> Tensor:
        """Actions ``[B, K]`` from ``drive [B, K]`` and each row's gain ``sigma [B]`` (the drive's
        dtype, contiguous): ``decoder`` 0 (``SigmoidForce``), 1 (``BangBang`` at ``threshold``) or 2
        (``LinearReadout`` clamped to ``+-action_max``), the modules' bits (the sigmoid is
        ``portable_math``'s)."""
        B, K = drive.shape
        action = torch.empty_like(drive)
        lib = _library()
        fn = lib.rate_decode_f32 if drive.dtype == torch.float32 else lib.rate_decode_f64
        fn(drive.data_ptr(), sigma.data_ptr(), action.data_ptr(), B, K, int(decoder), float(action_max),
           float(threshold))
        return action
