"""Leaky integrate-and-fire (LIF) and leaky integrator (LI) neurons as pure tensor functions.

Both follow NIR's definitions (so they export and import unchanged), with time in ms and
voltages in mV::

    tau_mem dv/dt = (v_leak - v) + r I           (LI: that is all; its output is v)
    LIF: spike when v >= v_th, then v <- v_reset ("zero") or v <- v - (v_th - v_reset) ("subtract")

``I`` is held over each step, so the update is exact for any ``dt_ms``:
``v1 = v_inf + (v - v_inf) exp(-dt/tau_mem)`` with ``v_inf = v_leak + r I``. The reset is
not differentiated through the spike (``z.detach()``), as in ``izhikevich_step``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import Tensor

from snn_torch.functional.threshold import SpikeFn, heaviside

Scalar = float | Tensor

__all__ = ["LIFParams", "LIFState", "LIFRecurrentState", "LIParams", "LIState", "RESETS", "lif_init", "lif_step", "li_init",
           "li_step", "leak_factor"]

RESETS = ("zero", "subtract")


class LIFParams(NamedTuple):
    """LIF parameters: floats, or tensors broadcasting against the state (e.g. ``[N]``).

    Attributes:
        tau_mem_ms: membrane time constant (ms).
        v_leak: resting potential (mV).
        v_th: firing threshold (mV).
        v_reset: potential after a spike (mV; ``"subtract"`` removes ``v_th - v_reset``).
        r: input resistance (mV per unit of input current).
    """

    tau_mem_ms: Scalar = 10.0
    v_leak: Scalar = 0.0
    v_th: Scalar = 1.0
    v_reset: Scalar = 0.0
    r: Scalar = 1.0


class LIFState(NamedTuple):
    """``v``: membrane potential (mV)."""

    v: Tensor


class LIFRecurrentState(NamedTuple):
    """``v`` (mV) and ``z`` the previous step's spikes, fed back through the recurrent weights."""

    v: Tensor
    z: Tensor


class LIParams(NamedTuple):
    """Leaky integrator parameters: ``tau_mem_ms`` (ms), ``v_leak`` (mV), ``r`` (mV per unit current)."""

    tau_mem_ms: Scalar = 10.0
    v_leak: Scalar = 0.0
    r: Scalar = 1.0


class LIState(NamedTuple):
    """``v``: membrane potential (mV), the integrator's output."""

    v: Tensor


def leak_factor(tau_mem_ms: Scalar, dt_ms: float) -> Scalar:
    """``exp(-dt_ms / tau_mem_ms)``: what is left of ``v - v_inf`` after one step."""
    if isinstance(tau_mem_ms, Tensor):
        return torch.exp(-dt_ms / tau_mem_ms)
    return math.exp(-dt_ms / tau_mem_ms)


def _relax(i_in: Tensor, v: Tensor, tau_mem_ms: Scalar, v_leak: Scalar, r: Scalar, dt_ms: float) -> Tensor:
    v_inf = v_leak + r * i_in
    return v_inf + (v - v_inf) * leak_factor(tau_mem_ms, dt_ms)


def lif_init(shape: tuple[int, ...] | torch.Size, p: LIFParams, *, device: torch.device | str | None = None,
             dtype: torch.dtype = torch.float32) -> LIFState:
    """Rest state: ``v = v_leak`` (mV)."""
    v = torch.zeros(tuple(shape), device=device, dtype=dtype) + p.v_leak
    return LIFState(v.to(dtype))


def lif_step(i_in: Tensor, state: LIFState, p: LIFParams, *, dt_ms: float = 1.0, spike_fn: SpikeFn = heaviside,
             reset: str = "zero") -> tuple[Tensor, LIFState]:
    """Advance LIF neurons one step of ``dt_ms`` (ms) under the current ``i_in`` held over it.

    Returns ``(z, new_state)``; ``z`` is 1.0 where ``v`` reached ``v_th`` (mV) in this step.
    """
    if reset not in RESETS:
        raise ValueError(f"reset must be one of {RESETS}, got {reset!r}")
    v1 = _relax(i_in, state.v, p.tau_mem_ms, p.v_leak, p.r, dt_ms)
    z = spike_fn(v1 - p.v_th)
    spiked = z.detach()
    if reset == "zero":  # v_reset where spiked, else v1; arithmetic, not torch.where (slow on the CPU)
        v_new = v1 * (1.0 - spiked) + spiked * p.v_reset
    else:
        v_new = v1 - spiked * (p.v_th - p.v_reset)
    return z, LIFState(v_new)


def li_init(shape: tuple[int, ...] | torch.Size, p: LIParams, *, device: torch.device | str | None = None,
            dtype: torch.dtype = torch.float32) -> LIState:
    """Rest state: ``v = v_leak`` (mV)."""
    v = torch.zeros(tuple(shape), device=device, dtype=dtype) + p.v_leak
    return LIState(v.to(dtype))


def li_step(i_in: Tensor, state: LIState, p: LIParams, *, dt_ms: float = 1.0) -> tuple[Tensor, LIState]:
    """Advance leaky integrators one step of ``dt_ms`` (ms); returns ``(v, new_state)``, ``v`` in mV."""
    v = _relax(i_in, state.v, p.tau_mem_ms, p.v_leak, p.r, dt_ms)
    return v, LIState(v)
