"""The non-Markov cart-pole closed loop as one C kernel: plant, encoder, network, decoder.

``tasks.controllers.closed_loop`` is the readable reference: a few dozen torch ops per
control step over the whole batch. This kernel runs each batch row's whole episode in one C
loop (rows spread over threads), so a row stops costing anything the moment it fails, no
Python runs per control step, and a row's result depends on nothing but its own genome: the
same in any batch, with any thread count. The arithmetic repeats the reference's operations
in order (no contraction); only ``sin``, ``cos`` and ``exp`` come from the C library rather
than torch's vectorised versions, so the two paths agree to rounding (tested), not bit for bit.
"""

from __future__ import annotations

import ctypes

import torch
from torch import Tensor

from snn_torch._cbuild import load_c_library
from snn_torch.functional.fused_cpu import MAX_NODES, ROW_SOURCE
from tasks.cartpole import CartPoleParams, PlantError

__all__ = ["loop_available", "spiking_loop", "sigmoid_loop", "markov_spiking_loop", "genome_keys"]

_LOOP_SOURCE = r"""
#define DEFINE_PLANT(NAME, T)                                                                  \
/* Explicit Euler as tasks.cartpole.cartpole_step, same operation order. */                    \
/* mpl = m_pole * l and total = m_cart + m_pole come rounded from double, as in torch. */     \
static inline void NAME(T *s, T force, T tau, T g, T total, T mp, T mpl, T l) {                \
    T x = s[0], xd = s[1], th = s[2], thd = s[3];                                              \
    T sn = sin(th), cs = cos(th);                                                              \
    T temp = (-force - mpl * thd * thd * sn) / total;                                            \
    T thacc = (g * sn + cs * temp) / (l * ((T)(4.0 / 3.0) - mp * cs * cs / total));           \
    T xacc = (force + mpl * (thd * thd * sn - thacc * cs)) / total;                             \
    s[0] = x + tau * xd; s[1] = xd + tau * xacc; s[2] = th + tau * thd; s[3] = thd + tau * thacc; \
}
DEFINE_PLANT(plant_f32, float)
DEFINE_PLANT(plant_f64, double)

#define NORM(T, v, lim) ({ T q_ = ((v) / (lim) + (T)1.0) * (T)0.5; q_ < 0 ? (T)0 : (q_ > 1 ? (T)1 : q_); })

/* SIZE_CASES(CALL): `case k: CALL; break;` for k = 4..12 and 16, with N_ standing for k. */
#define SIZE_CASE(K, CALL) case K: { enum { N_ = K }; CALL; break; }
#define SIZE_CASES(CALL) SIZE_CASE(4, CALL) SIZE_CASE(5, CALL) SIZE_CASE(6, CALL) SIZE_CASE(7, CALL) \
    SIZE_CASE(8, CALL) SIZE_CASE(9, CALL) SIZE_CASE(10, CALL) SIZE_CASE(11, CALL) SIZE_CASE(12, CALL) \
    SIZE_CASE(16, CALL)

/* Rate decoding over the window of the last `window` control steps (hist[k * n + j]: spikes
   of node j in slot k), summed in slot order as the torch reference does. */
#define DEFINE_DECODE(SUFFIX, T)                                                               \
static inline T window_rate_##SUFFIX(const T *hist, int64_t window, int64_t n, int64_t j, T denom) { \
    T sum = hist[j];                                                                           \
    for (int64_t k = 1; k < window; ++k) sum += hist[k * n + j];                               \
    return sum / denom;                                                                        \
}                                                                                              \
/* sum_j wo[j] (r_j - rest[j]) (rest NULL: 0), accumulated in double over j ascending. */      \
static inline T weighted_rate_##SUFFIX(const T *hist, int64_t window, int64_t n, T denom,       \
                                       const T *wo, const T *rest) {                           \
    double acc = 0;                                                                            \
    for (int64_t j = 0; j < n; ++j) {                                                          \
        if (wo[j] == 0) continue; /* an absent connection adds exactly 0 */                    \
        T rate = window_rate_##SUFFIX(hist, window, n, j, denom);                              \
        if (rest) rate = rate - rest[j];                                                       \
        acc += (double)(rate * wo[j]);                                                         \
    }                                                                                          \
    return (T)acc;                                                                             \
}
DEFINE_DECODE(f32, float)
DEFINE_DECODE(f64, double)

/* Lanes: each thread runs LANES episodes in lockstep, one network per lane, so the substep
   works on LANES independent networks at once and the core overlaps what one network's
   serial chain (matvec, Heun, reset, next matvec) would leave idle. A lane whose episode
   ends takes the next row at once. Every lane's arithmetic is its network's alone, in the
   reference's order, so a row's result does not depend on its lane or its neighbours. */
#define LANES 8
static inline int64_t next_row(int64_t *next, int64_t rows) {
    int64_t r;
    _Pragma("omp atomic capture")
    r = (*next)++;
    return r < rows ? r : -1;
}

/* status[r]: 0 ok, 1 the plant produced NaN or inf. */
#define DEFINE_SNN_LOOP(NAME, LSUB, PLANT, T, EXP, SUFFIX)                                     \
void NAME(const T *w, const T *wout, const T *sigma, const T *state0, int64_t *steps,         \
          int64_t *status, int64_t rows, int64_t n, int64_t max_steps, int64_t substeps,      \
          int64_t window, T dt, T a, T b, T c, T d, T vpeak, T ibg, T imax, T window_s,        \
          T tau, T g, T total, T mp, T mpl, T l, T xlim, T thlim, int threads) {               \
    int64_t next = 0;                                                                          \
    _Pragma("omp parallel num_threads(threads)")                                               \
    {                                                                                          \
        T vv[LANES * MAXN], uu[LANES * MAXN], zz[LANES * MAXN], I[LANES * MAXN];              \
        T cnt[LANES * MAXN], hist[LANES * 16 * MAXN], s[LANES][4];                             \
        const T *W[LANES];                                                                     \
        int64_t row[LANES], t[LANES];                                                          \
        int live = 0;                                                                          \
        for (int k = 0; k < LANES; ++k) {                                                      \
            W[k] = w; row[k] = -1; s[k][0] = s[k][1] = s[k][2] = s[k][3] = 0;                  \
            for (int64_t j = 0; j < n; ++j) { vv[k * n + j] = (T)-65.0; uu[k * n + j] = b * vv[k * n + j]; zz[k * n + j] = 0; } \
        }                                                                                      \
        for (;;) {                                                                             \
            /* fill free lanes; rows with no steps to run finish here */                     \
            for (int k = 0; k < LANES; ++k) {                                                  \
                while (row[k] < 0) {                                                           \
                    int64_t r = next_row(&next, rows);                                         \
                    if (r < 0) break;                                                          \
                    status[r] = 0;                                                             \
                    if (max_steps <= 0) { steps[r] = 0; continue; }                            \
                    row[k] = r; t[k] = 0; W[k] = w + r * n * n; ++live;                        \
                    for (int q = 0; q < 4; ++q) s[k][q] = state0[4 * r + q];                   \
                    for (int64_t j = 0; j < n; ++j) { vv[k * n + j] = (T)-65.0; uu[k * n + j] = b * vv[k * n + j]; zz[k * n + j] = 0; } \
                    for (int64_t q = 0; q < window * n; ++q) hist[k * 16 * n + q] = 0;        \
                }                                                                              \
            }                                                                                  \
            if (live == 0) break;                                                              \
            for (int k = 0; k < LANES; ++k) {                                                  \
                T xn = NORM(T, s[k][0], xlim), thn = NORM(T, s[k][2], thlim);                  \
                T *Ik = I + k * n;                                                             \
                for (int64_t j = 0; j < n; ++j) { Ik[j] = ibg; cnt[k * n + j] = 0; }          \
                Ik[0] = ibg + imax * xn; Ik[1] = ibg + imax * thn;                             \
            }                                                                                  \
            /* a constant n for the usual sizes lets the compiler unroll and vectorise */    \
            for (int64_t q = 0; q < substeps; ++q) {                                           \
                switch (n) {                                                                   \
                    SIZE_CASES(LSUB(vv, uu, zz, W, I, cnt, LANES, N_, dt, a, b, c, d, vpeak))         \
                    default: LSUB(vv, uu, zz, W, I, cnt, LANES, n, dt, a, b, c, d, vpeak);          \
                }                                                                              \
            }                                                                                  \
            for (int k = 0; k < LANES; ++k) {                                                  \
                int64_t r = row[k];                                                            \
                if (r < 0) continue; /* an idle lane: its numbers are never read */           \
                T *hk = hist + k * 16 * n, *slot = hk + (t[k] % window) * n;                   \
                for (int64_t j = 0; j < n; ++j) slot[j] = cnt[k * n + j];                      \
                int64_t in_window = t[k] + 1 < window ? t[k] + 1 : window;                     \
                T denom = (T)((double)in_window * (double)window_s);                           \
                T drive = weighted_rate_##SUFFIX(hk, window, n, denom, wout + r * n, 0);       \
                T fn = (T)1 / ((T)1 + EXP(-(sigma[r] * drive)));                               \
                T force = (T)10.0 * ((T)2.0 * fn - (T)1.0);                                    \
                T *sk = s[k];                                                                  \
                PLANT(sk, force, tau, g, total, mp, mpl, l);                                   \
                int end = 0;                                                                   \
                if (!(isfinite(sk[0]) && isfinite(sk[1]) && isfinite(sk[2]) && isfinite(sk[3]))) { \
                    status[r] = 1; end = 1;                                                    \
                } else if (fabs((double)sk[0]) > (double)xlim || fabs((double)sk[2]) > (double)thlim) { \
                    end = 1;                                                                   \
                } else if (++t[k] >= max_steps) {                                              \
                    end = 1;                                                                   \
                }                                                                              \
                if (end) { steps[r] = t[k]; row[k] = -1; --live; }                             \
            }                                                                                  \
        }                                                                                      \
    }                                                                                          \
}
DEFINE_SNN_LOOP(snn_loop_f32, izh_f32_lanes, plant_f32, float, expf, f32)
DEFINE_SNN_LOOP(snn_loop_f64, izh_f64_lanes, plant_f64, double, exp, f64)

/* One network update of LANES sigmoid networks (lane k: values y[k*n ..], weights W[k]):
   y_j <- 1 / (1 + exp(-slope * sum_i y_i W_ij)), the sum over i ascending, as the reference. */
#define DEFINE_SIG_UPDATE(NAME, T, EXP)                                                        \
static inline void NAME(T *y, const T *const *W, int64_t n, T slope) {                         \
    T acc[LANES * MAXN];                                                                       \
    for (int k = 0; k < LANES; ++k) {                                                          \
        const T *yk = y + k * n, *Wk = W[k];                                                   \
        T *ak = acc + k * n;                                                                   \
        for (int64_t j = 0; j < n; ++j) ak[j] = 0;                                             \
        for (int64_t i = 0; i < n; ++i)                                                        \
            for (int64_t j = 0; j < n; ++j) ak[j] += yk[i] * Wk[i * n + j];                    \
    }                                                                                          \
    for (int64_t j = 0; j < LANES * n; ++j) y[j] = (T)1 / ((T)1 + EXP(-(slope * acc[j])));     \
}
DEFINE_SIG_UPDATE(sig_update_f32, float, expf)
DEFINE_SIG_UPDATE(sig_update_f64, double, exp)

#define DEFINE_SIG_LOOP(NAME, UPDATE, PLANT, T)                                                \
/* inputs: state variables obs[k] scaled by lim[k] to [0, 1]; bang: F = +-10 N on y > 0.5 */   \
void NAME(const T *w, const T *state0, int64_t *steps, int64_t *status, int64_t rows,          \
          int64_t n, int64_t n_in, int64_t first_out, int64_t max_steps, int64_t updates,      \
          const int64_t *obs, const T *lim, int64_t bang,                                      \
          T slope, T tau, T g, T total, T mp, T mpl, T l, T xlim, T thlim, int threads) {      \
    int64_t next = 0;                                                                          \
    _Pragma("omp parallel num_threads(threads)")                                               \
    {                                                                                          \
        T y[LANES * MAXN], in[LANES][8], s[LANES][4];                                          \
        const T *W[LANES];                                                                     \
        int64_t row[LANES], t[LANES];                                                          \
        int live = 0;                                                                          \
        for (int k = 0; k < LANES; ++k) {                                                      \
            W[k] = w; row[k] = -1; s[k][0] = s[k][1] = s[k][2] = s[k][3] = 0;                  \
            for (int64_t j = 0; j < n; ++j) y[k * n + j] = 0;                                  \
        }                                                                                      \
        for (;;) {                                                                             \
            for (int k = 0; k < LANES; ++k) {                                                  \
                while (row[k] < 0) {                                                           \
                    int64_t r = next_row(&next, rows);                                         \
                    if (r < 0) break;                                                          \
                    status[r] = 0;                                                             \
                    if (max_steps <= 0) { steps[r] = 0; continue; }                            \
                    row[k] = r; t[k] = 0; W[k] = w + r * n * n; ++live;                        \
                    for (int q = 0; q < 4; ++q) s[k][q] = state0[4 * r + q];                   \
                    for (int64_t j = 0; j < n; ++j) y[k * n + j] = 0;                          \
                }                                                                              \
            }                                                                                  \
            if (live == 0) break;                                                              \
            for (int k = 0; k < LANES; ++k)                                                    \
                for (int64_t q = 0; q < n_in; ++q) in[k][q] = NORM(T, s[k][obs[q]], lim[q]);   \
            for (int64_t q = 0; q < updates; ++q) {                                            \
                for (int k = 0; k < LANES; ++k) {                                              \
                    T *yk = y + k * n;                                                         \
                    for (int64_t j = 0; j < n_in; ++j) yk[j] = in[k][j];                       \
                    for (int64_t j = n_in; j < first_out; ++j) yk[j] = 1;                      \
                }                                                                              \
                switch (n) {                                                                   \
                    SIZE_CASES(UPDATE(y, W, N_, slope))                                        \
                    default: UPDATE(y, W, n, slope);                                           \
                }                                                                              \
                for (int k = 0; k < LANES; ++k) {                                              \
                    T *yk = y + k * n;                                                         \
                    for (int64_t j = 0; j < n_in; ++j) yk[j] = in[k][j];                       \
                    for (int64_t j = n_in; j < first_out; ++j) yk[j] = 1;                      \
                }                                                                              \
            }                                                                                  \
            for (int k = 0; k < LANES; ++k) {                                                  \
                int64_t r = row[k];                                                            \
                if (r < 0) continue; /* an idle lane: its numbers are never read */           \
                T out = y[k * n + first_out];                                                  \
                T force = bang ? (out > (T)0.5 ? (T)10.0 : (T)-10.0) : (T)10.0 * ((T)2.0 * out - (T)1.0); \
                T *sk = s[k];                                                                  \
                PLANT(sk, force, tau, g, total, mp, mpl, l);                                   \
                int end = 0;                                                                   \
                if (!(isfinite(sk[0]) && isfinite(sk[1]) && isfinite(sk[2]) && isfinite(sk[3]))) { \
                    status[r] = 1; end = 1;                                                    \
                } else if (fabs((double)sk[0]) > (double)xlim || fabs((double)sk[2]) > (double)thlim) { \
                    end = 1;                                                                   \
                } else if (++t[k] >= max_steps) {                                              \
                    end = 1;                                                                   \
                }                                                                              \
                if (end) { steps[r] = t[k]; row[k] = -1; --live; }                             \
            }                                                                                  \
        }                                                                                      \
    }                                                                                          \
}
DEFINE_SIG_LOOP(sig_loop_f32, sig_update_f32, plant_f32, float)
DEFINE_SIG_LOOP(sig_loop_f64, sig_update_f64, plant_f64, double)

/* Counter-based random numbers (splitmix64): a row's stream depends on its key alone. */
static inline uint64_t mix64(uint64_t x) {
    x += 0x9E3779B97F4A7C15ULL;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    return x ^ (x >> 31);
}
static inline double uniform01(uint64_t key, uint64_t counter) {
    return (double)(mix64(key ^ mix64(counter)) >> 11) * 0x1.0p-53;
}
/* FNV-1a over a row's bytes: a key that is a pure function of the genome. */
void row_keys(const unsigned char *data, int64_t rows, int64_t bytes_per_row, uint64_t *keys) {
    for (int64_t r = 0; r < rows; ++r) {
        uint64_t h = 0xcbf29ce484222325ULL;
        const unsigned char *p = data + r * bytes_per_row;
        for (int64_t k = 0; k < bytes_per_row; ++k) { h ^= p[k]; h *= 0x100000001b3ULL; }
        keys[r] = mix64(h);
    }
}

/* Markov task: n_in Bernoulli input nodes fire in each substep with probability norm * pmax.
   wout == NULL: F = +10 N when the output neuron's rate over the window exceeds thr_hz, else -10 N.
   wout != NULL: the output node decodes, as in the non-Markov task, from the rates r_j of the
   nodes wired to it (inputs included): F = +10 N when sum_j wout[j] (r_j - rest[j]) exceeds
   thr_hz, else -10 N. */
#define DEFINE_MARKOV_LOOP(NAME, SUBSTEP, PLANT, T, SUFFIX)                                            \
void NAME(const T *w, const T *wout, const T *rest, const uint64_t *keys, const T *state0, int64_t *steps,    \
          int64_t *status, int64_t rows, int64_t n, int64_t n_in, int64_t out, int64_t max_steps, \
          int64_t substeps, int64_t window, const int64_t *obs, const T *lim,                   \
          T dt, T a, T b, T c, T d, T vpeak, T ibg, T pmax, T thr_hz, T window_s,              \
          T tau, T g, T total, T mp, T mpl, T l, T xlim, T thlim, int threads) {               \
    _Pragma("omp parallel for schedule(dynamic, 4) num_threads(threads)")                      \
    for (int64_t r = 0; r < rows; ++r) {                                                       \
        T vv[MAXN], uu[MAXN], zz[MAXN], I[MAXN], cnt[MAXN], hist[16 * MAXN], p[8];            \
        const T *W = w + r * n * n;                                                            \
        const T *WO = wout ? wout + r * n : 0;                                                 \
        T s[4] = {state0[4 * r], state0[4 * r + 1], state0[4 * r + 2], state0[4 * r + 3]};      \
        for (int64_t j = 0; j < n; ++j) { vv[j] = (T)-65.0; uu[j] = b * vv[j]; zz[j] = 0; I[j] = ibg; } \
        for (int64_t k = 0; k < window * n; ++k) hist[k] = 0;                                  \
        uint64_t counter = 0;                                                                  \
        int64_t t = 0; status[r] = 0;                                                          \
        for (; t < max_steps; ++t) {                                                           \
            for (int64_t k = 0; k < n_in; ++k) p[k] = NORM(T, s[obs[k]], lim[k]) * pmax;       \
            for (int64_t j = 0; j < n; ++j) cnt[j] = 0;                                        \
            for (int64_t q = 0; q < substeps; ++q) {                                           \
                for (int64_t k = 0; k < n_in; ++k) {                                           \
                    zz[k] = uniform01(keys[r], counter++) < (double)p[k] ? (T)1 : (T)0;        \
                    cnt[k] += zz[k];                                                           \
                }                                                                              \
                switch (n) {                                                               \
                    SIZE_CASES(SUBSTEP(vv, uu, zz, W, I, cnt, N_, n_in, dt, a, b, c, d, vpeak)) \
                    default: SUBSTEP(vv, uu, zz, W, I, cnt, n, n_in, dt, a, b, c, d, vpeak);  \
                }                                                                          \
            }                                                                                  \
            T *slot = hist + (t % window) * n;                                                 \
            for (int64_t j = 0; j < n; ++j) slot[j] = cnt[j];                                  \
            int64_t in_window = t + 1 < window ? t + 1 : window;                               \
            T denom = (T)((double)in_window * (double)window_s);                               \
            T drive = WO ? weighted_rate_##SUFFIX(hist, window, n, denom, WO, rest)            \
                         : window_rate_##SUFFIX(hist, window, n, out, denom);                  \
            T force = drive > thr_hz ? (T)10.0 : (T)-10.0;                                     \
            PLANT(s, force, tau, g, total, mp, mpl, l);                                        \
            if (!(isfinite(s[0]) && isfinite(s[1]) && isfinite(s[2]) && isfinite(s[3]))) {     \
                status[r] = 1; break;                                                          \
            }                                                                                  \
            if (fabs((double)s[0]) > (double)xlim || fabs((double)s[2]) > (double)thlim) break; \
        }                                                                                      \
        steps[r] = t;                                                                          \
    }                                                                                          \
}
DEFINE_MARKOV_LOOP(markov_loop_f32, izh_f32_substep, plant_f32, float, f32)
DEFINE_MARKOV_LOOP(markov_loop_f64, izh_f64_substep, plant_f64, double, f64)
"""

MAX_WINDOW = 16
_lib: ctypes.CDLL | None = None


def loop_available() -> bool:
    """True if the closed-loop kernels compiled (once per process) and are enabled."""
    global _lib
    _lib = load_c_library("cartpole_loop", ROW_SOURCE + _LOOP_SOURCE)
    if _lib is not None and not hasattr(_lib, "_typed"):
        for suffix, ct in (("f32", ctypes.c_float), ("f64", ctypes.c_double)):
            snn = getattr(_lib, f"snn_loop_{suffix}")
            snn.restype = None
            snn.argtypes = [ctypes.c_void_p] * 6 + [ctypes.c_int64] * 5 + [ct] * 17 + [ctypes.c_int]
            sig = getattr(_lib, f"sig_loop_{suffix}")
            sig.restype = None
            sig.argtypes = ([ctypes.c_void_p] * 4 + [ctypes.c_int64] * 6 + [ctypes.c_void_p] * 2 + [ctypes.c_int64]
                            + [ct] * 9 + [ctypes.c_int])
            mk = getattr(_lib, f"markov_loop_{suffix}")
            mk.restype = None
            mk.argtypes = ([ctypes.c_void_p] * 7 + [ctypes.c_int64] * 7 + [ctypes.c_void_p] * 2 + [ct] * 18
                           + [ctypes.c_int])
        _lib.row_keys.restype = None
        _lib.row_keys.argtypes = [ctypes.c_void_p, ctypes.c_int64, ctypes.c_int64, ctypes.c_void_p]
        _lib._typed = True
    return _lib is not None


def _plant_args(plant: CartPoleParams) -> list[float]:
    # Python evaluates these products in double before torch rounds them; so do we.
    return [plant.gravity, plant.cart_mass + plant.pole_mass, plant.pole_mass, plant.pole_mass * plant.half_length,
            plant.half_length, plant.x_limit, plant.theta_limit]


def _finish(steps: Tensor, status: Tensor) -> Tensor:
    bad = torch.nonzero(status).flatten()
    if len(bad):
        raise PlantError(f"cart-pole state after a control step holds NaN or inf at {len(bad)} batch "
                         f"index/indices, first: {bad[:10].tolist()}")
    return steps


def spiking_loop(w: Tensor, w_out: Tensor, sigma: Tensor, state0: Tensor, *, max_steps: int, substeps: int,
                 window: int, dt_ms: float, neuron, i_background: float, i_input_max: float, window_s: float,
                 tau_s: float, plant: CartPoleParams) -> Tensor:
    """Steps balanced per row for the non-Markov spiking controller (see ``SpikingPolicy``)."""
    B, N = w_out.shape
    if N > MAX_NODES or window > MAX_WINDOW:
        raise ValueError(f"the fused loop handles N <= {MAX_NODES} and windows <= {MAX_WINDOW}, got {N}, {window}")
    dtype = w.dtype
    w, w_out, sigma = w.contiguous(), w_out.contiguous(), sigma.to(dtype).contiguous()
    s0 = state0.to(dtype).contiguous()
    steps = torch.empty(B, dtype=torch.int64)
    status = torch.empty(B, dtype=torch.int64)
    fn = _lib.snn_loop_f32 if dtype == torch.float32 else _lib.snn_loop_f64
    fn(w.data_ptr(), w_out.data_ptr(), sigma.data_ptr(), s0.data_ptr(), steps.data_ptr(), status.data_ptr(),
       B, N, int(max_steps), int(substeps), int(window), float(dt_ms), float(neuron.a), float(neuron.b),
       float(neuron.c), float(neuron.d), float(neuron.v_peak), float(i_background), float(i_input_max),
       float(window_s), float(tau_s), *_plant_args(plant), torch.get_num_threads())
    return _finish(steps, status)


def _observation(obs: tuple[int, ...], limits: tuple[float, ...], dtype: torch.dtype) -> tuple[Tensor, Tensor]:
    if len(obs) != len(limits) or not 1 <= len(obs) <= 8:
        raise ValueError(f"need 1 to 8 observed variables with one limit each, got {obs} and {limits}")
    return torch.tensor(obs, dtype=torch.int64), torch.tensor(limits, dtype=dtype)


def sigmoid_loop(w: Tensor, state0: Tensor, *, num_inputs: int, first_output: int, max_steps: int, updates: int,
                 slope: float, tau_s: float, plant: CartPoleParams, observe: tuple[int, ...] = (0, 2),
                 limits: tuple[float, ...] | None = None, bang_bang: bool = False) -> Tensor:
    """Steps balanced per row for a recurrent sigmoid controller (see ``SigmoidPolicy``):
    inputs are the state variables ``observe`` scaled from ``[-limit, limit]`` to [0, 1]."""
    B, N = w.shape[0], w.shape[-1]
    if N > MAX_NODES:
        raise ValueError(f"the fused loop handles N <= {MAX_NODES}, got {N}")
    dtype = w.dtype
    limits = (plant.x_limit, plant.theta_limit) if limits is None else limits
    obs, lim = _observation(observe, limits, dtype)
    if len(observe) != num_inputs:
        raise ValueError(f"num_inputs ({num_inputs}) must equal the observed variables ({len(observe)})")
    w = w.contiguous()
    s0 = state0.to(dtype).contiguous()
    steps = torch.empty(B, dtype=torch.int64)
    status = torch.empty(B, dtype=torch.int64)
    fn = _lib.sig_loop_f32 if dtype == torch.float32 else _lib.sig_loop_f64
    fn(w.data_ptr(), s0.data_ptr(), steps.data_ptr(), status.data_ptr(), B, N, int(num_inputs), int(first_output),
       int(max_steps), int(updates), obs.data_ptr(), lim.data_ptr(), int(bang_bang), float(slope), float(tau_s),
       *_plant_args(plant), torch.get_num_threads())
    return _finish(steps, status)


def genome_keys(flat: Tensor) -> Tensor:
    """A 64-bit key per row of ``flat`` ([B, ...], any dtype): a hash of the row's bytes, so
    a genome's noise depends on the genome alone (not its batch, run or position)."""
    data = flat.contiguous().reshape(flat.shape[0], -1)
    raw = data.view(torch.uint8) if data.dtype != torch.uint8 else data
    keys = torch.empty(flat.shape[0], dtype=torch.int64)
    _lib.row_keys(raw.data_ptr(), raw.shape[0], raw.shape[1], keys.data_ptr())
    return keys


def markov_spiking_loop(w: Tensor, w_out: Tensor | None, rest_hz: Tensor | None, keys: Tensor, state0: Tensor, *,
                        num_inputs: int,
                        output: int, max_steps: int,
                        substeps: int, window: int, dt_ms: float, neuron, i_background: float,
                        spike_prob_max: float, threshold_hz: float, window_s: float, tau_s: float,
                        plant: CartPoleParams, observe: tuple[int, ...], limits: tuple[float, ...]) -> Tensor:
    """Steps balanced per row for the Markov spiking controller (see ``MarkovSpikingPolicy``)."""
    B, N = w.shape[0], w.shape[-1]
    if N > MAX_NODES or window > MAX_WINDOW:
        raise ValueError(f"the fused loop handles N <= {MAX_NODES} and windows <= {MAX_WINDOW}, got {N}, {window}")
    dtype = w.dtype
    obs, lim = _observation(observe, limits, dtype)
    w, keys = w.contiguous(), keys.contiguous()
    if (w_out is None) != (rest_hz is None):
        raise ValueError("w_out and rest_hz go together (the weighted-rate decoder) or are both None")
    if w_out is not None:
        w_out, rest_hz = w_out.to(dtype).contiguous(), rest_hz.to(dtype).contiguous()
        if w_out.shape != (B, N) or rest_hz.shape != (N,):
            raise ValueError(f"w_out must be [{B}, {N}] and rest_hz [{N}], got {tuple(w_out.shape)}, "
                             f"{tuple(rest_hz.shape)}")
    s0 = state0.to(dtype).contiguous()
    steps = torch.empty(B, dtype=torch.int64)
    status = torch.empty(B, dtype=torch.int64)
    fn = _lib.markov_loop_f32 if dtype == torch.float32 else _lib.markov_loop_f64
    fn(w.data_ptr(), None if w_out is None else w_out.data_ptr(), None if w_out is None else rest_hz.data_ptr(),
       keys.data_ptr(), s0.data_ptr(), steps.data_ptr(), status.data_ptr(), B, N, int(num_inputs),
       int(output), int(max_steps), int(substeps), int(window), obs.data_ptr(), lim.data_ptr(), float(dt_ms),
       float(neuron.a), float(neuron.b), float(neuron.c), float(neuron.d), float(neuron.v_peak), float(i_background),
       float(spike_prob_max), float(threshold_hz), float(window_s), float(tau_s), *_plant_args(plant),
       torch.get_num_threads())
    return _finish(steps, status)
