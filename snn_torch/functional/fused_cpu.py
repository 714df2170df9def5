"""A fused CPU kernel for many substeps of population recurrent Izhikevich networks.

``recurrent_izhikevich_step`` costs ~50 small tensor ops per substep, and for the small
networks NEAT evolves (N ~ 8) per-op overhead, not arithmetic, sets the speed. This module
runs ``substeps`` steps of the same arithmetic (Heun, sub-step reset, Heaviside spikes,
synchronous recurrence with a one-step delay) in one C loop per network, compiled once
with the system C compiler (``snn_torch._cbuild``) and called through ``ctypes``: one call per control step.

The reference torch step stays the definition; the kernel repeats its operations in the
same order with no floating-point contraction, and ``tests/snn_torch/test_fused_cpu.py``
checks the two agree. Rows are independent, so a row's result does not depend on the batch
it shares or on the thread count. Where no compiler is found, ``fused_available()`` is
False and callers use the torch step. ``SNN_NEAT_FUSED=0`` turns the kernel off.
"""

from __future__ import annotations

import ctypes

import torch
from torch import Tensor

from snn_torch._cbuild import load_c_library
from snn_torch.functional.izhikevich import IzhikevichParams
from snn_torch.functional.recurrent import RecurrentState

__all__ = ["fused_available", "fused_recurrent_izhikevich_steps", "supports"]

MAX_NODES = 256  # per-row scratch arrays live on the stack

# One network's substeps (NAME_row) and the batch kernel over rows (NAME). ROW_SOURCE is
# shared with kernels that embed the network in a closed loop (tasks.fused_loop).
ROW_SOURCE = r"""
#include <math.h>
#include <stdint.h>
#define MAXN 256

#define OWN(j) (all || own[j])
#define DEFINE_ROW(NAME, T)                                                                    \
static inline void NAME##_heun(T v, T u, T i, T a, T b, T h, T *vo, T *uo) {                  \
    T dv1 = ((T)0.04 * v + (T)5.0) * v + (T)140.0 - u + i;                                     \
    T du1 = a * (b * v - u);                                                                   \
    T v2 = v + h * dv1, u2 = u + h * du1;                                                      \
    T dv2 = ((T)0.04 * v2 + (T)5.0) * v2 + (T)140.0 - u2 + i;                                  \
    T du2 = a * (b * v2 - u2);                                                                 \
    T half = (T)0.5 * h;                                                                       \
    *vo = v + half * (dv1 + dv2);                                                              \
    *uo = u + half * (du1 + du2);                                                              \
}                                                                                              \
/* Neurons [0, count) of networks of n neurons side by side, after their synaptic input is     \
   summed into it[]: Heun, then the sub-step reset where they spiked; adds spikes to cnt.      \
   Unless `all`, only neurons first <= j < n_real of each network are updated: those below     \
   `first` are driven from outside (their z and counts set by the caller), those from n_real   \
   on pad the network and stay silent. `all` is a constant after inlining, so the usual        \
   case carries no mask. */                                                                    \
static inline void NAME##_update_(T *vv, T *uu, T *zz, const T *it, const T *I, T *cnt,        \
                                  int64_t count, int64_t n, int64_t first, int64_t n_real,     \
                                  T dt, T a, T b, T c, T d, T vpeak, const int all) {          \
    T v1[count], u1[count], in[count];                                                         \
    unsigned char own[all ? 1 : count];                                                        \
    if (!all)                                                                                  \
        for (int64_t k = 0; k < count; k += n)                                                 \
            for (int64_t j = 0; j < n; ++j) own[k + j] = j >= first && j < n_real;             \
    int any = 0;                                                                               \
    for (int64_t j = 0; j < count; ++j) {                                                      \
        in[j] = I[j] + it[j];                                                                  \
        NAME##_heun(vv[j], uu[j], in[j], a, b, dt, &v1[j], &u1[j]);                            \
        any |= !(v1[j] - vpeak < 0) & OWN(j);                                                  \
    }                                                                                          \
    if (!any) {                                                                                \
        for (int64_t j = 0; j < count; ++j) {                                                  \
            vv[j] = OWN(j) ? v1[j] : vv[j]; uu[j] = OWN(j) ? u1[j] : uu[j]; zz[j] = OWN(j) ? (T)0 : zz[j];\
        }                                                                                      \
        return;                                                                                \
    }                                                                                          \
    /* Branch-free, so a constant size vectorises: every neuron's reset is computed and kept  \
       only where it spiked (v1 >= vpeak, or NaN, as the reference counts it). The kept     \
       values come from the same operations as the reference's, so they are the same; a    \
       neuron that did not spike keeps exactly the no-spike values. */                       \
    for (int64_t j = 0; j < count; ++j) {                                                      \
        int spiked = !(v1[j] - vpeak < 0);                                                     \
        T th = (vpeak - vv[j]) / (v1[j] - vv[j]);                                              \
        th = isnan(th) ? (T)0 : th;                                                            \
        th = th < 0 ? (T)0 : (th > 1 ? (T)1 : th);                                             \
        T ur = uu[j] + th * (u1[j] - uu[j]) + d;                                               \
        T vr = (T)0 + c, vs, us;                                                               \
        NAME##_heun(vr, ur, in[j], a, b, ((T)1.0 - th) * dt, &vs, &us);                        \
        T vn = spiked ? vs : v1[j], un = spiked ? us : u1[j];                                  \
        vv[j] = OWN(j) ? vn : vv[j];                                                           \
        uu[j] = OWN(j) ? un : uu[j];                                                           \
        zz[j] = OWN(j) ? (spiked ? (T)1 : (T)0) : zz[j];                                       \
        cnt[j] += OWN(j) & spiked ? (T)1 : (T)0;                                               \
    }                                                                                          \
}                                                                                              \
static inline void NAME##_update(T *vv, T *uu, T *zz, const T *it, const T *I, T *cnt,         \
                                 int64_t count, int64_t n, int64_t first, int64_t n_real,      \
                                 T dt, T a, T b, T c, T d, T vpeak) {                          \
    if (first == 0 && n_real == n)                                                             \
        NAME##_update_(vv, uu, zz, it, I, cnt, count, n, first, n_real, dt, a, b, c, d, vpeak, 1);\
    else                                                                                       \
        NAME##_update_(vv, uu, zz, it, I, cnt, count, n, first, n_real, dt, a, b, c, d, vpeak, 0);\
}                                                                                              \
/* Synaptic input to one network's neurons (weights W[pre*n+post]) in the reference's order \
   (pre ascending); silent neurons add exactly 0, so they are skipped. */                      \
static inline void NAME##_input(const T *zz, const T *W, T *it, int64_t n) {                   \
    for (int64_t j = 0; j < n; ++j) it[j] = 0;                                                 \
    for (int64_t k = 0; k < n; ++k) {                                                          \
        if (zz[k] == 0) continue;                                                              \
        const T *Wk = W + k * n;                                                               \
        for (int64_t j = 0; j < n; ++j) it[j] += zz[k] * Wk[j];                                \
    }                                                                                          \
}                                                                                              \
/* One substep of `lanes` networks of n neurons each, side by side (network k: neurons        \
   k*n .. k*n+n-1, weights W[k]), so the core overlaps their independent work; neurons below  \
   `first` in each network are driven from outside (e.g. Bernoulli inputs). */               \
static inline void NAME##_lanes(T *vv, T *uu, T *zz, const T *const *W, const T *I, T *cnt,   \
                                int64_t lanes, int64_t n, int64_t first, int64_t n_real,       \
                                T dt, T a, T b, T c, T d, T vpeak) {                           \
    T it[lanes * n];                                                                           \
    for (int64_t k = 0; k < lanes; ++k) NAME##_input(zz + k * n, W[k], it + k * n, n);         \
    NAME##_update(vv, uu, zz, it, I, cnt, lanes * n, n, first, n_real, dt, a, b, c, d, vpeak); \
}                                                                                              \
static inline void NAME##_row(T *vv, T *uu, T *zz, const T *W, const T *I, T *cnt, int64_t n, \
                              int64_t substeps, T dt, T a, T b, T c, T d, T vpeak) {           \
    for (int64_t s = 0; s < substeps; ++s)                                                     \
        NAME##_lanes(vv, uu, zz, &W, I, cnt, 1, n, 0, n, dt, a, b, c, d, vpeak);                \
}

DEFINE_ROW(izh_f32, float)
DEFINE_ROW(izh_f64, double)
"""

_BATCH_SOURCE = r"""
#define DEFINE_BATCH(NAME, ROW, T)                                                             \
void NAME(T *v, T *u, T *z, const T *w, const T *iext, T *counts, int64_t rows, int64_t n,    \
          int64_t substeps, T dt, T a, T b, T c, T d, T vpeak, int threads) {                 \
    _Pragma("omp parallel for schedule(static) num_threads(threads)")                          \
    for (int64_t r = 0; r < rows; ++r) {                                                       \
        for (int64_t j = 0; j < n; ++j) counts[r * n + j] = 0;                                 \
        ROW(v + r * n, u + r * n, z + r * n, w + r * n * n, iext + r * n, counts + r * n, n,  \
            substeps, dt, a, b, c, d, vpeak);                                                  \
    }                                                                                          \
}
DEFINE_BATCH(izh_steps_f32, izh_f32_row, float)
DEFINE_BATCH(izh_steps_f64, izh_f64_row, double)
"""
_SOURCE = ROW_SOURCE + _BATCH_SOURCE

_lib: ctypes.CDLL | None = None


def fused_available() -> bool:
    """True if the kernel compiled (once per process) and ``SNN_NEAT_FUSED`` is not ``0``."""
    global _lib
    _lib = load_c_library("izh_steps", _SOURCE)
    if _lib is not None and not hasattr(_lib, "_typed"):
        for name, ct in (("izh_steps_f32", ctypes.c_float), ("izh_steps_f64", ctypes.c_double)):
            fn = getattr(_lib, name)
            fn.restype = None
            fn.argtypes = [ctypes.c_void_p] * 6 + [ctypes.c_int64] * 3 + [ct] * 6 + [ctypes.c_int]
        _lib._typed = True
    return _lib is not None


def supports(state: RecurrentState, w_eff: Tensor, p: IzhikevichParams) -> bool:
    """Whether the kernel can run this case: CPU, float32/64, scalar parameters, N <= 256."""
    scalars = all(isinstance(x, (int, float)) for x in p)
    return (scalars and state.v.device.type == "cpu" and state.v.dtype in (torch.float32, torch.float64)
            and state.v.dim() == 2 and state.v.shape[-1] <= MAX_NODES and fused_available())


def fused_recurrent_izhikevich_steps(
    i_ext: Tensor, state: RecurrentState, w_eff: Tensor, p: IzhikevichParams, *, dt_ms: float, substeps: int,
) -> tuple[Tensor, RecurrentState]:
    """``substeps`` steps of ``recurrent_izhikevich_step`` (Heun, sub-step reset, Heaviside)
    under a constant external current.

    Args:
        i_ext: external current (mV/ms) ``[B, N]``, constant over the substeps.
        state: ``RecurrentState`` with ``[B, N]`` tensors (not modified).
        w_eff: effective weights ``[B, N, N]`` (pre x post), already masked.
        p: scalar parameters; dt_ms: substep (ms); substeps: how many.

    Returns:
        ``(counts, new_state)``: spikes per neuron over the substeps ``[B, N]``, and the state.
    """
    if not supports(state, w_eff, p):
        raise ValueError("the fused CPU kernel needs CPU float32/float64 [B, N] state, N <= 256, scalar "
                         "parameters and a working C compiler; check supports() first")
    dtype, (B, N) = state.v.dtype, state.v.shape
    if w_eff.shape != (B, N, N) or w_eff.dtype != dtype or i_ext.shape != (B, N) or i_ext.dtype != dtype:
        raise ValueError(f"expected w_eff [{B}, {N}, {N}] and i_ext [{B}, {N}] of {dtype}, got "
                         f"{tuple(w_eff.shape)} {w_eff.dtype} and {tuple(i_ext.shape)} {i_ext.dtype}")
    v, u, z = (t.contiguous().clone() for t in state)  # the kernel updates these in place
    w = w_eff.contiguous()
    i = i_ext.contiguous()
    counts = torch.empty_like(v)
    fn = _lib.izh_steps_f32 if dtype == torch.float32 else _lib.izh_steps_f64
    fn(v.data_ptr(), u.data_ptr(), z.data_ptr(), w.data_ptr(), i.data_ptr(), counts.data_ptr(), B, N,
       int(substeps), float(dt_ms), float(p.a), float(p.b), float(p.c), float(p.d), float(p.v_peak),
       torch.get_num_threads())
    return counts, RecurrentState(v, u, z)
