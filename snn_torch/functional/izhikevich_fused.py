"""``izhikevich_step`` as one autograd node with a hand-written backward, for the layers.

``izhikevich_step_fused`` returns exactly what ``izhikevich_step`` returns (the same float
operations in the same order, so the same bits; tested), but:

- the forward runs in place on a few buffers and computes the sub-step reset only for the
  neurons that spiked (a few percent per step), where the plain step integrates a reset
  branch for every neuron and selects with ``torch.where``;
- autograd sees one node per step instead of about 80, and that node keeps only ``v`` and
  Heun's predictor ``v_e`` for the whole layer (``v`` alone for Euler) plus a handful of
  values for the neurons that spiked (or, with ``substep_reset=False``, a 0/1 tensor of who
  did not spike: that reset runs in float arithmetic, which is faster on the CPU than masks
  and gives the same values, a zero's sign aside). The backward is the exact derivative of the forward
  (checked by ``gradcheck`` in float64 and against autograd of ``izhikevich_step``).

The spike itself stays outside the node: the node returns ``x = v1 - v_peak`` (mV) and the
caller's ``spike_fn(x)`` gives ``z``, so any surrogate works unchanged.

Used by the layer modules only. The evolution code (``recurrent_izhikevich_step``, the C
kernel) keeps ``izhikevich_step``. The fused form falls back to ``izhikevich_step`` (same
results, plain autograd) when a neuron parameter requires grad, when parameters or state
do not match the input's dtype, and under ``torch.compile`` (where Inductor fuses the plain
step itself, with no data-dependent shapes).
"""

from __future__ import annotations

import math
import threading
from typing import Any

import torch
from torch import Tensor
from torch.autograd.function import once_differentiable

from snn_torch.functional.izhikevich import (
    DEFAULT_DT_MS,
    DEFAULT_METHOD,
    IzhikevichParams,
    IzhikevichState,
    check_current,
    check_dt,
    check_method,
    izhikevich_step,
)
from snn_torch.functional.threshold import SpikeFn, heaviside

__all__ = ["izhikevich_step_fused", "fused_applies"]


# ---- scratch buffers ------------------------------------------------------------------------
# Intermediates that are neither returned nor saved go to per-thread buffers reused step after
# step: a fresh tensor of a large layer costs the allocator's page faults (an allocating op runs
# several times slower than the same op in place at batch 1024 on this CPU).
_local = threading.local()


def _scratch(name: str, like: Tensor) -> Tensor:
    buffers = getattr(_local, "buffers", None)
    if buffers is None:
        buffers = _local.buffers = {}
    key = (name, like.shape, like.dtype, like.device)
    buf = buffers.get(key)
    if buf is None:
        if len(buffers) > 64:
            buffers.clear()
        buf = buffers[key] = torch.empty_like(like, memory_format=torch.contiguous_format)
    return buf


# ---- forward pieces: the same operations, in the same order, as izhikevich.py ----------------

def _derivatives(v: Tensor, u: Tensor, i: Tensor, a: Any, b: Any, scratch: bool = False) -> tuple[Tensor, Tensor]:
    # (0.04 v + 5) v + 140 - u + i  and  a (b v - u), evaluated left to right as there.
    dv = torch.mul(v, 0.04, out=_scratch("dv", v)) if scratch else v * 0.04
    dv.add_(5.0).mul_(v).add_(140.0).sub_(u).add_(i)
    du = torch.mul(v, b, out=_scratch("du", v)) if scratch else v * b
    du.sub_(u).mul_(a)
    return dv, du


def _solve(v: Tensor, u: Tensor, i: Tensor, a: Any, b: Any, h: Any, heun: bool,
           keep_slopes: bool = False) -> tuple[Any, ...]:
    """One Euler or Heun step of length ``h`` (ms): ``(v1, u1, ve, slopes)``.

    ``ve`` is Heun's predictor for ``v`` (None for Euler). With ``keep_slopes``, ``slopes`` is
    ``(dv1, du1, s_v, s_u)``: the first slopes and the ones the update used (``dv1 + dv2`` for
    Heun, ``dv1`` again for Euler), which the derivative by ``h`` needs; otherwise None, and
    the update is written into the slope buffers in place.
    """
    # Heun's first slopes are intermediates unless the caller keeps them; Euler's become v1, u1.
    dv1, du1 = _derivatives(v, u, i, a, b, scratch=heun and not keep_slopes)
    if not heun:
        s_v, s_u = dv1, du1
        slopes = (dv1, du1, dv1, du1) if keep_slopes else None
        half = h
    else:
        ve = dv1 * h
        ve.add_(v)
        ue = du1 * h if keep_slopes else torch.mul(du1, h, out=_scratch("ue", u))
        ue.add_(u)
        s_v, s_u = _derivatives(ve, ue, i, a, b)
        s_v.add_(dv1)
        s_u.add_(du1)
        slopes = (dv1, du1, s_v, s_u) if keep_slopes else None
        half = 0.5 * h
    v1 = s_v * half if keep_slopes else s_v.mul_(half)
    v1.add_(v)
    u1 = s_u * half if keep_slopes else s_u.mul_(half)
    u1.add_(u)
    return v1, u1, (ve if heun else None), slopes


# ---- backward pieces ----------------------------------------------------------------------

def _solve_backward(gv1: Tensor, gu1: Tensor, v: Tensor | None, ve: Tensor | None, a: Any, b: Any, h: Any,
                    heun: bool, slopes: tuple[Tensor, ...] | None = None
                    ) -> tuple[Tensor | None, Tensor, Tensor, Tensor | None]:
    """Gradients of one ``_solve`` step from ``(gv1, gu1)``: ``(g_v, g_u, g_i, g_h)``.

    ``g_v`` is None when ``v`` is None (a constant start, the reset value c); ``g_h`` is None
    unless ``slopes = (dv1, du1, s_v, s_u)`` from the forward is given.
    dv/dv = 0.08 v + 5, dv/du = -1, dv/di = 1; du/dv = a b, du/du = -a.
    """
    ab = a * b
    g_h = None
    if heun:
        half = 0.5 * h
        gs_v = gv1 * half                      # on dv1 and dv2 alike
        gs_u = gu1 * half
        g_ve = ve * 0.08
        g_ve.add_(5.0).mul_(gs_v).add_(gs_u * ab)
        g_ue = gs_u * a
        g_ue.add_(gs_v).neg_()                 # -(gs_v + a gs_u)
        if slopes is not None:
            dv1, du1, s_v, s_u = slopes
            g_h = (gv1 * s_v + gu1 * s_u) * 0.5 + g_ve * dv1 + g_ue * du1
        g_dv1 = g_ve * h
        g_dv1.add_(gs_v)
        g_du1 = g_ue * h
        g_du1.add_(gs_u)
        g_i = gs_v + g_dv1
        g_u = g_du1 * a
        g_u.add_(g_dv1).neg_().add_(gu1).add_(g_ue)
    else:
        if slopes is not None:
            dv1, du1, _, _ = slopes
            g_h = gv1 * dv1 + gu1 * du1
        g_dv1 = gv1 * h
        g_du1 = gu1 * h
        g_i = g_dv1
        g_u = g_du1 * a
        g_u.add_(g_dv1).neg_().add_(gu1)
    g_v = None
    if v is not None:
        g_v = v * 0.08
        g_v.add_(5.0).mul_(g_dv1).add_(gv1).add_(g_du1 * ab)
        if heun:
            g_v.add_(g_ve)
    return g_v, g_u, g_i, g_h


def _dense_backward(gv1: Tensor, gu1: Tensor, v: Tensor, ve: Tensor | None, a: Any, b: Any, h: float,
                    heun: bool) -> tuple[Tensor, Tensor, Tensor]:
    """``_solve_backward`` for the whole layer: ``(g_v, g_u, g_i)``, written into ``gv1`` (which
    the caller owns) and two fresh tensors, the intermediates into scratch buffers."""
    ab = a * b
    if heun:
        half = 0.5 * h
        gs_v = torch.mul(gv1, half, out=_scratch("g1", v))     # on dv1 and dv2 alike
        gs_u = torch.mul(gu1, half, out=_scratch("g2", v))
        g_ve = torch.mul(ve, 0.08, out=_scratch("g3", v))
        g_ve.add_(5.0).mul_(gs_v).add_(torch.mul(gs_u, ab, out=_scratch("g4", v)))
        g_ue = torch.mul(gs_u, a, out=_scratch("g5", v))
        g_ue.add_(gs_v).neg_()                                   # -(gs_v + a gs_u)
        g_dv1 = torch.mul(g_ve, h, out=_scratch("g6", v))
        g_dv1.add_(gs_v)
        g_du1 = torch.mul(g_ue, h, out=_scratch("g4", v))
        g_du1.add_(gs_u)
        g_i = gs_v + g_dv1
        g_u = g_du1 * a
        g_u.add_(g_dv1).neg_().add_(gu1).add_(g_ue)
        g_v = gv1.add_(g_ve)
    else:
        g_i = gv1 * h                                            # g_dv1
        g_du1 = torch.mul(gu1, h, out=_scratch("g1", v))
        g_u = g_du1 * a
        g_u.add_(g_i).neg_().add_(gu1)
        g_v, g_dv1 = gv1, g_i
    g_v.add_(torch.mul(g_du1, ab, out=_scratch("g2", v)))
    g_v.add_(torch.mul(v, 0.08, out=_scratch("g5", v)).add_(5.0).mul_(g_dv1))
    return g_v, g_u, g_i


def _flat(x: Any, idx: Tensor, like: Tensor) -> Any:
    """``x`` (a float or a tensor broadcasting to ``like``) at the flat indices ``idx``."""
    if isinstance(x, Tensor) and x.dim():
        return x.expand_as(like).reshape(-1)[idx]
    return x


def _forward(i: Tensor, v: Tensor, u: Tensor, p: IzhikevichParams, dt: float, heun: bool,
             substep_reset: bool) -> tuple[Tensor, Tensor, Tensor, tuple[Tensor, ...]]:
    """``(x, v_new, u_new, saved)``: the step, and what the backward needs."""
    a, b, c, d, v_peak = p
    v1, u1, ve, _ = _solve(v, u, i, a, b, dt, heun)
    x = v1 - v_peak
    x.nan_to_num_(nan=0.0)  # NaN (overflow at absurd currents) counts as a spike, as in izhikevich_step
    if not substep_reset:
        # Reset at the end of the step, in float arithmetic (bool masks and torch.where are several
        # times slower on the CPU): z = [x >= 0] as 0./1.; v_new = v1 (1 - z) + c z and u_new = u1 + d z
        # give izhikevich_step's values exactly (x * 1 = x, x + 0 = x; nan_to_num makes a NaN v1 reset to c).
        z = x.sign().add_(1.0).clamp_(max=1.0)
        keep = 1.0 - z
        v1.nan_to_num_(nan=0.0, posinf=0.0, neginf=-math.inf).mul_(keep)  # -inf never spikes
        # z c is exact (z is 0 or 1), so add_(z, alpha=c), fused or not, rounds like v1 + z * c.
        v1.add_(z, alpha=c) if isinstance(c, float) else v1.add_(z * c)
        u1.add_(z, alpha=d) if isinstance(d, float) else u1.add_(z * d)
        return x, v1, u1, (v, ve, keep)
    idx = (x >= 0).view(-1).nonzero().squeeze(1)
    saved: tuple[Tensor, ...] = ()
    if idx.numel():
        vs, us, v1s, u1s = v.reshape(-1)[idx], u.reshape(-1)[idx], v1.view(-1)[idx], u1.view(-1)[idx]
        cs, ds = _flat(c, idx, v), _flat(d, idx, v)
        i_s = i.reshape(-1)[idx]
        a_s, b_s, vp_s = _flat(a, idx, v), _flat(b, idx, v), _flat(v_peak, idx, v)
        rise = v1s - vs
        q = (vp_s - vs) / rise
        theta = torch.nan_to_num(q, nan=0.0).clamp(0.0, 1.0)
        du = u1s - us
        u_th = us + theta * du + ds
        v_r = torch.zeros_like(vs) + cs
        hr = (1.0 - theta) * dt
        vn, un, ve_r, slopes = _solve(v_r, u_th, i_s, a_s, b_s, hr, heun, keep_slopes=True)
        saved = (rise, q, theta, du, hr, ve_r if heun else v_r, *slopes)
        v1.view(-1)[idx] = vn
        u1.view(-1)[idx] = un
    return x, v1, u1, (v, ve, idx, *saved)


class _IzhikevichStep(torch.autograd.Function):
    """``(i, v, u) -> (x, v_new, u_new)`` with ``x = nan_to_num(v1 - v_peak)`` (mV)."""

    @staticmethod
    def forward(ctx: Any, i: Tensor, v: Tensor, u: Tensor, p: IzhikevichParams, dt: float,  # type: ignore[override]
                heun: bool, substep_reset: bool) -> tuple[Tensor, Tensor, Tensor]:
        x, v1, u1, saved = _forward(i, v, u, p, dt, heun, substep_reset)
        ctx.save_for_backward(*saved)
        ctx.params, ctx.dt, ctx.heun, ctx.substep_reset = p, dt, heun, substep_reset
        return x, v1, u1

    @staticmethod
    @once_differentiable  # the backward writes into scratch buffers: no double backward
    def backward(ctx: Any, gx: Tensor | None, gv: Tensor | None, gu: Tensor | None):  # type: ignore[override]
        v, ve, idx, *saved = ctx.saved_tensors  # idx: spike indices, or the spike mask without substep_reset
        a, b, _, _, _ = ctx.params
        dt, heun = ctx.dt, ctx.heun
        zero = torch.zeros_like(v) if gx is None or gv is None or gu is None else None
        gx, gv, gu = (zero if g is None else g for g in (gx, gv, gu))
        if not ctx.substep_reset:  # idx is keep = 1 - z: v_new = v1 keep + c z, u_new = u1 + d z
            g_v, g_u, g_i = _dense_backward(torch.addcmul(gx, gv, idx), gu, v, ve, a, b, dt, heun)
            return g_i, g_v, g_u, None, None, None, None
        # Neurons that did not spike: v_new = v1, u_new = u1, and x = v1 - v_peak.
        gv1 = gv + gx
        gu1 = gu.clone() if idx.numel() else gu  # written below only where neurons spiked
        extra = None
        if idx.numel():
            gx_s, gvn, gun = gx.reshape(-1)[idx], gv.reshape(-1)[idx], gu.reshape(-1)[idx]
            rise, q, theta, du, hr, ve_r, dv1_r, du1_r, s_v, s_u = saved
            a_s, b_s = _flat(a, idx, v), _flat(b, idx, v)
            # The reset sub-step runs from the constant c over hr = (1 - theta) dt.
            _, g_uth, g_i_s, g_hr = _solve_backward(gvn, gun, None, ve_r, a_s, b_s, hr, heun,
                                                    slopes=(dv1_r, du1_r, s_v, s_u))
            # u_th = u + theta (u1 - u) + d;  hr = (1 - theta) dt;  theta = clamp(q, 0, 1)
            g_theta = g_uth * du - g_hr * dt
            g_q = g_theta * ((q >= 0.0) & (q <= 1.0)).to(q.dtype)
            # q = (v_peak - v) / rise, rise = v1 - v
            g_rise = -g_q * q / rise
            gv1_s = gx_s + g_rise
            gu1_s = g_uth * theta
            extra = (-g_q / rise - g_rise, g_uth * (1.0 - theta), g_i_s)
            gv1.view(-1)[idx] = gv1_s
            gu1.view(-1)[idx] = gu1_s
        g_v, g_u, g_i = _dense_backward(gv1, gu1, v, ve, a, b, dt, heun)
        if extra is not None:
            g_v.view(-1).index_add_(0, idx, extra[0])
            g_u.view(-1).index_add_(0, idx, extra[1])
            g_i.view(-1).index_add_(0, idx, extra[2])
        return g_i, g_v, g_u, None, None, None, None


def fused_applies(i_in: Tensor, state: IzhikevichState, p: IzhikevichParams, method: str) -> bool:
    """Whether ``izhikevich_step_fused`` takes its fused path for these arguments.

    Not under ``torch.compile`` (Inductor fuses the plain step, with static shapes), not when
    a parameter requires grad (the node has no parameter gradients), and only when the state
    is two tensors of one shape, and every tensor parameter matches the state's dtype
    (otherwise type promotion would change the arithmetic).
    """
    if torch.compiler.is_compiling() or method not in ("heun", "euler"):
        return False
    v, u = state
    if v.shape != u.shape or v.dtype != u.dtype or i_in.dtype != v.dtype or not v.is_floating_point():
        return False
    for value in p:
        if isinstance(value, Tensor) and (value.requires_grad or value.dtype != v.dtype):
            return False
    return True


def izhikevich_step_fused(
    i_in: Tensor,
    state: IzhikevichState,
    p: IzhikevichParams,
    *,
    dt_ms: float = DEFAULT_DT_MS,
    method: str = DEFAULT_METHOD,
    spike_fn: SpikeFn = heaviside,
    substep_reset: bool = True,
    validate: bool = True,
) -> tuple[Tensor, IzhikevichState]:
    """``izhikevich_step`` (same arguments, same results bit for bit) as one autograd node.

    Args:
        i_in: input current (mV/ms), broadcastable to ``state.v``.
        state: ``(v, u)`` before the step (mV, mV/ms).
        p: parameters, floats or tensors broadcasting against the state.
        dt_ms: step length (ms).
        Others as ``izhikevich_step``.

    Returns:
        ``(z, new_state)`` as ``izhikevich_step``. Gradients reach ``i_in``, ``v`` and ``u``
        (not parameters: a parameter that requires grad selects the plain step).
    """
    if validate:
        dt_ms = check_dt(dt_ms)
        check_current("i_in", i_in, state.v)
    check_method(method)
    if not fused_applies(i_in, state, p, method):
        return izhikevich_step(i_in, state, p, dt_ms=dt_ms, method=method, spike_fn=spike_fn,
                               substep_reset=substep_reset, validate=False)
    v, u = state
    i = i_in if i_in.shape == v.shape else i_in.expand_as(v)
    args = (i.contiguous(), v.contiguous(), u.contiguous(), p, float(dt_ms), method == "heun", substep_reset)
    if torch.is_grad_enabled() and (i.requires_grad or v.requires_grad or u.requires_grad):
        x, v_new, u_new = _IzhikevichStep.apply(*args)
    else:  # nothing to differentiate: skip the autograd node and what it saves
        x, v_new, u_new, _ = _forward(*args)
    return spike_fn(x), IzhikevichState(v_new, u_new)
