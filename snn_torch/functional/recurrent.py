"""Population-batched recurrent Izhikevich networks.

``P`` networks of ``N`` neurons each, one weight matrix per network: ``weight[p, i, j]`` is
the synapse from neuron ``i`` (pre) to neuron ``j`` (post), the NEAT connection slot
``(i, j)``. Semantics are synchronous with a one-step delay: at every step each neuron
receives ``I = i_ext + sum_i w[i, j] z_prev[i]``, so any recurrence (self loops included)
needs no topological sort.

The synaptic sum runs over presynaptic slots in ascending order (``ordered_synaptic_current``),
not as a matmul: a matmul's blocking, and so its rounding, depends on the batch and matrix
sizes, and a network's result must not depend on the batch it shares or on how many node
slots the batch simulates (an unused slot adds exact zeros). The C kernel
(``snn_torch.kernels.network``) sums in the same order and equals this step bit for bit.

The state may carry extra batch axes between ``P`` and ``N`` (``[P, B, N]``), for example
several episodes per network.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import Tensor

from snn_torch.functional.izhikevich import (
    DEFAULT_DT_MS,
    DEFAULT_METHOD,
    DEFAULT_V0_MV,
    IzhikevichParams,
    IzhikevichState,
    check_current,
    check_dt,
    izhikevich_init,
    izhikevich_step,
)
from snn_torch.functional.threshold import SpikeFn, heaviside

__all__ = [
    "RecurrentState",
    "SynapticState",
    "synaptic_decay",
    "masked_weights",
    "recurrent_init",
    "recurrent_izhikevich_step",
    "recurrent_izhikevich_run",
    "recurrent_izhikevich_steps",
    "recurrent_izhikevich_substep",
    "ordered_synaptic_current",
]


class RecurrentState(NamedTuple):
    """``v`` (mV), ``u`` (mV/ms) and ``z`` the previous step's spikes, each ``[P, ..., N]``."""

    v: Tensor
    u: Tensor
    z: Tensor


class SynapticState(NamedTuple):
    """``RecurrentState`` plus ``s`` (mV/ms), each neuron's synaptic current through exponential
    synapses (a synaptic time constant, ``synaptic_decay``), each ``[P, ..., N]``."""

    v: Tensor
    u: Tensor
    z: Tensor
    s: Tensor


def synaptic_decay(tau_ms: float, dt_ms: float) -> float | None:
    """Per-step decay ``exp(-dt / tau)`` of exponential synapses of time constant ``tau_ms``
    (ms); None for ``tau_ms`` 0 (instantaneous synapses: a spike's current lasts one step).

    With a decay ``k`` the synaptic current follows ``s <- k s + (1 - k) W z``: a spike delivers
    the same charge as an instantaneous synapse, spread over about ``tau_ms``, so the weights
    keep their meaning and ``tau_ms`` -> 0 gives the instantaneous synapse back."""
    if isinstance(tau_ms, bool) or not isinstance(tau_ms, (int, float)) or not math.isfinite(tau_ms) or tau_ms < 0:
        raise ValueError(f"synapse_tau_ms must be a finite number >= 0 (ms), got {tau_ms!r}")
    return None if tau_ms == 0 else math.exp(-float(dt_ms) / float(tau_ms))


def _synaptic_input(state: RecurrentState | SynapticState, z_prev: Tensor, w_eff: Tensor,
                    syn_decay: float | None) -> tuple[Tensor, Tensor | None]:
    """The synaptic current into each neuron this step, and the new ``s`` (None without decay)."""
    drive = ordered_synaptic_current(z_prev, w_eff)
    if syn_decay is None:
        return drive, None
    if not isinstance(state, SynapticState):
        raise ValueError("a synaptic time constant needs a SynapticState (the layer's initial_state makes one)")
    s = state.s * syn_decay + (1.0 - syn_decay) * drive
    return s, s


def masked_weights(weight: Tensor, mask: Tensor) -> Tensor:
    """``weight`` where ``mask`` is True, else exactly 0 (even for inf or NaN weights).

    Raises ``ValueError`` naming the argument on a shape, dtype or rank mismatch.
    """
    if not isinstance(weight, Tensor) or weight.dim() != 3 or weight.shape[-1] != weight.shape[-2]:
        shape = tuple(weight.shape) if isinstance(weight, Tensor) else type(weight).__name__
        raise ValueError(f"weight must be a [P, N, N] tensor, got {shape}")
    if not weight.is_floating_point():
        raise ValueError(f"weight must be floating point, got {weight.dtype}")
    if not isinstance(mask, Tensor) or mask.shape != weight.shape:
        shape = tuple(mask.shape) if isinstance(mask, Tensor) else type(mask).__name__
        raise ValueError(f"mask must have weight's shape {tuple(weight.shape)}, got {shape}")
    if mask.dtype != torch.bool:
        raise ValueError(f"mask must be a bool tensor, got {mask.dtype}")
    if mask.device != weight.device:
        raise ValueError(f"mask is on {mask.device}, but weight is on {weight.device}")
    return torch.where(mask, weight, torch.zeros((), dtype=weight.dtype, device=weight.device))


def recurrent_init(
    shape: tuple[int, ...] | torch.Size,
    p: IzhikevichParams,
    *,
    v0_mv: float = DEFAULT_V0_MV,
    device: torch.device | str | None = None,
    dtype: torch.dtype = torch.float32,
    synaptic: bool = False,
) -> RecurrentState | SynapticState:
    """Rest state for ``shape = (P, ..., N)``: ``v = v0_mv``, ``u = b v``, no spikes (and with
    ``synaptic``, a ``SynapticState`` with no synaptic current)."""
    v, u = izhikevich_init(shape, p, v0_mv=v0_mv, device=device, dtype=dtype)
    if synaptic:
        return SynapticState(v, u, torch.zeros_like(v), torch.zeros_like(v))
    return RecurrentState(v, u, torch.zeros_like(v))


def ordered_synaptic_current(z: Tensor, w_eff: Tensor) -> Tensor:
    """``sum_i z[..., i] w_eff[:, i, :]`` for ``z [P, ..., N]`` and ``w_eff [P, N, N]``, summed
    over ``i`` ascending from an exact 0 (``0 + t_0 + t_1 + ...``): the same bits for a row
    whatever the batch size or the number of slots beyond its last synapse."""
    flat = z.reshape(z.shape[0], -1, z.shape[-1])
    acc = torch.zeros_like(flat)
    for i in range(flat.shape[-1]):
        acc = acc + flat[:, :, i : i + 1] * w_eff[:, i : i + 1, :]
    return acc.reshape(z.shape)


def recurrent_izhikevich_step(
    i_ext: Tensor,
    state: RecurrentState,
    w_eff: Tensor,
    p: IzhikevichParams,
    *,
    dt_ms: float = DEFAULT_DT_MS,
    method: str = DEFAULT_METHOD,
    spike_fn: SpikeFn = heaviside,
    substep_reset: bool = True,
    validate: bool = True,
    syn_decay: float | None = None,
) -> tuple[Tensor, RecurrentState]:
    """One step of ``P`` recurrent networks.

    Args:
        i_ext: external current (mV/ms) broadcastable to the state, ``[P, ..., N]``.
        state: ``RecurrentState`` before the step.
        w_eff: effective weights ``[P, N, N]`` (pre x post), already masked
            (``masked_weights``), in the state's dtype.
        syn_decay: ``synaptic_decay``'s per-step decay of exponential synapses (``state`` then
            a ``SynapticState``); None: instantaneous synapses.
        Others as ``izhikevich_step``.

    Returns:
        ``(z, new_state)`` with ``z`` the spikes of this step, ``[P, ..., N]``.
    """
    if validate:
        dt_ms = check_dt(dt_ms)
        _check_weights(w_eff, state.v)
        check_current("i_ext", i_ext, state.v)
    drive, syn = _synaptic_input(state, state.z, w_eff, syn_decay)
    i_total = i_ext + drive
    z, (v, u) = izhikevich_step(
        i_total, IzhikevichState(state.v, state.u), p, dt_ms=dt_ms, method=method,
        spike_fn=spike_fn, substep_reset=substep_reset, validate=False,
    )
    return z, (RecurrentState(v, u, z) if syn is None else SynapticState(v, u, z, syn))


def _check_weights(w_eff: Tensor, v: Tensor) -> None:
    if w_eff.dim() != 3 or w_eff.shape[0] != v.shape[0] or w_eff.shape[1:] != (v.shape[-1],) * 2:
        raise ValueError(
            f"weights must be [P, N, N] = [{v.shape[0]}, {v.shape[-1]}, {v.shape[-1]}] for a "
            f"state of shape {tuple(v.shape)}, got {tuple(w_eff.shape)}"
        )
    if w_eff.dtype != v.dtype or w_eff.device != v.device:
        raise ValueError(
            f"weights are {w_eff.dtype} on {w_eff.device}, but the state is {v.dtype} on {v.device}"
        )


def recurrent_izhikevich_run(
    i_ext: Tensor,
    state: RecurrentState,
    w_eff: Tensor,
    p: IzhikevichParams,
    *,
    dt_ms: float = DEFAULT_DT_MS,
    method: str = DEFAULT_METHOD,
    spike_fn: SpikeFn = heaviside,
    substep_reset: bool = True,
    validate: bool = True,
    syn_decay: float | None = None,
) -> tuple[Tensor, RecurrentState]:
    """Run ``T = i_ext.shape[0]`` steps; returns spikes ``[T, P, ..., N]`` and the last state.

    Inputs are validated once; the result equals ``T`` calls of the step, bit for bit.
    """
    if validate:
        dt_ms = check_dt(dt_ms)
        _check_weights(w_eff, state.v)
        if not isinstance(i_ext, Tensor) or i_ext.dim() < 1:
            raise ValueError("i_ext must be a tensor with time as its first dimension")
        if i_ext.shape[0] > 0:
            check_current("i_ext[t]", i_ext[0], state.v, check_finite=False)
        if not bool(torch.isfinite(i_ext).all()):
            raise ValueError("i_ext holds NaN or inf")
        if not bool(torch.isfinite(w_eff).all()):
            raise ValueError("weights hold NaN or inf where the mask is True")
    spikes = []
    for t in range(i_ext.shape[0]):
        z, state = recurrent_izhikevich_step(
            i_ext[t], state, w_eff, p, dt_ms=dt_ms, method=method, spike_fn=spike_fn,
            substep_reset=substep_reset, validate=False, syn_decay=syn_decay,
        )
        spikes.append(z)
    if not spikes:
        return state.v.new_zeros((0, *state.v.shape)), state
    return torch.stack(spikes), state


def recurrent_izhikevich_substep(
    i_ext: Tensor, state: RecurrentState, w_eff: Tensor, counts: Tensor, p: IzhikevichParams, *,
    dt_ms: float = DEFAULT_DT_MS, source: Tensor | None = None, method: str = DEFAULT_METHOD,
    spike_fn: SpikeFn = heaviside, substep_reset: bool = True, syn_decay: float | None = None,
) -> tuple[RecurrentState, Tensor]:
    """One substep of ``recurrent_izhikevich_steps``, its spikes added to ``counts``.

    ``source``: ``[P, S]`` spikes of the spike-source nodes ``0 .. S-1`` in this substep (their
    ``v`` and ``u`` are held), or None. Returns ``(state, counts + z)``; inputs are not checked.
    """
    z_prev = state.z
    n_src = 0 if source is None else source.shape[-1]
    if n_src:
        source = source.to(z_prev.dtype)
        z_prev = torch.cat([source, z_prev[:, n_src:]], dim=1)
    drive, syn = _synaptic_input(state, z_prev, w_eff, syn_decay)
    i_total = i_ext + drive
    z, (v, u) = izhikevich_step(
        i_total, IzhikevichState(state.v, state.u), p, dt_ms=dt_ms, method=method,
        spike_fn=spike_fn, substep_reset=substep_reset, validate=False,
    )
    if n_src:  # sources keep their v and u; their spikes are the given ones
        v = torch.cat([state.v[:, :n_src], v[:, n_src:]], dim=1)
        u = torch.cat([state.u[:, :n_src], u[:, n_src:]], dim=1)
        z = torch.cat([source, z[:, n_src:]], dim=1)
    new = RecurrentState(v, u, z) if syn is None else SynapticState(v, u, z, syn)
    return new, counts + z


def recurrent_izhikevich_steps(
    i_ext: Tensor,
    state: RecurrentState,
    w_eff: Tensor,
    p: IzhikevichParams,
    *,
    substeps: int,
    dt_ms: float = DEFAULT_DT_MS,
    source_spikes: Tensor | None = None,
    method: str = DEFAULT_METHOD,
    spike_fn: SpikeFn = heaviside,
    substep_reset: bool = True,
    syn_decay: float | None = None,
) -> tuple[Tensor, RecurrentState]:
    """``substeps`` steps under a constant external current: one control step of ``P`` networks.

    Args:
        i_ext: external current (mV/ms), ``[P, N]``, the same in every substep.
        state: ``RecurrentState`` of ``[P, N]`` tensors (not modified).
        w_eff: effective weights ``[P, N, N]`` (pre x post, mV/ms per spike), already masked.
        p: neuron parameters; dt_ms: substep (ms); substeps: how many.
        source_spikes: ``[P, substeps, S]`` spikes (0 or 1) of spike-source nodes ``0 .. S-1``
            in each substep (e.g. Bernoulli-coded inputs): their ``z`` is set to these and their
            ``v`` and ``u`` are held. None: every node is a neuron.
        syn_decay: exponential synapses' per-step decay (``synaptic_decay``; ``state`` a
            ``SynapticState``), None: instantaneous synapses.

    Returns:
        ``(counts, state)``: spikes per node over the substeps ``[P, N]`` (sources included),
        and the state after them. This is the definition the C kernel repeats bit for bit.
    """
    counts = torch.zeros_like(state.v)
    for q in range(substeps):
        state, counts = recurrent_izhikevich_substep(
            i_ext, state, w_eff, counts, p, dt_ms=dt_ms, method=method, spike_fn=spike_fn,
            substep_reset=substep_reset, source=None if source_spikes is None else source_spikes[:, q],
            syn_decay=syn_decay,
        )
    return counts, state
