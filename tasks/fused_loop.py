"""The cart-pole closed loops as C kernels: plant, encoder, network, decoder.

``tasks.controllers.closed_loop`` is the readable reference: a few dozen torch ops per
control step over the whole batch. These kernels run whole episodes in C: each thread keeps
8 episodes in lockstep lanes (one network per lane, so the core overlaps their independent
work), a lane whose episode ends takes the next batch row at once, and when rows run out
the last lanes move into the free ones. So a row stops costing anything the moment it
fails, no Python runs per control step, and a row's result depends on nothing but its own
genome: the same in any batch, lane or position, with any thread count. The arithmetic repeats the reference's operations
in order (no contraction); only ``sin``, ``cos`` and ``exp`` come from the C library rather
than torch's vectorised versions, so the two paths agree to rounding (tested), not bit for bit.
"""

from __future__ import annotations

import ctypes

import torch
from torch import Tensor

from evolution.rng import COUNTER_RNG_C
from snn_torch._cbuild import load_c_library
from snn_torch.functional.fused_cpu import MAX_NODES, ROW_SOURCE
from tasks.cartpole import CartPoleParams, PlantError

__all__ = ["loop_available", "spiking_loop", "sigmoid_loop", "markov_spiking_loop", "genome_keys"]

_LOOP_SOURCE = COUNTER_RNG_C + r"""
#include <stdlib.h>
#include <string.h>
#define DEFINE_PLANT(NAME, T)                                                                  \
/* Explicit Euler as tasks.cartpole.cartpole_step, same operation order, given sn = sin(theta) \
   and cs = cos(theta) (taken apart so a loop over lanes can call sin and cos first and then   \
   vectorise the rest). mpl = m_pole * l and total = m_cart + m_pole come rounded from         \
   double, as in torch. */                                                                     \
static inline void NAME##_trig(T *s, T force, T sn, T cs, T tau, T g, T total, T mp, T mpl, T l) { \
    T x = s[0], xd = s[1], th = s[2], thd = s[3];                                              \
    T temp = (-force - mpl * thd * thd * sn) / total;                                          \
    T thacc = (g * sn + cs * temp) / (l * ((T)(4.0 / 3.0) - mp * cs * cs / total));            \
    T xacc = (force + mpl * (thd * thd * sn - thacc * cs)) / total;                            \
    s[0] = x + tau * xd; s[1] = xd + tau * xacc; s[2] = th + tau * thd; s[3] = thd + tau * thacc; \
}                                                                                              \
static inline void NAME(T *s, T force, T tau, T g, T total, T mp, T mpl, T l) {                \
    NAME##_trig(s, force, sin(s[2]), cos(s[2]), tau, g, total, mp, mpl, l);                    \
}
DEFINE_PLANT(plant_f32, float)
DEFINE_PLANT(plant_f64, double)

/* Counter-based random numbers (splitmix64, COUNTER_RNG_C): a row's stream depends on its key alone. */
/* FNV-1a over a row's bytes: a key that is a pure function of the genome. */
void row_keys(const unsigned char *data, int64_t rows, int64_t bytes_per_row, uint64_t *keys) {
    for (int64_t r = 0; r < rows; ++r) {
        uint64_t h = 0xcbf29ce484222325ULL;
        const unsigned char *p = data + r * bytes_per_row;
        for (int64_t k = 0; k < bytes_per_row; ++k) { h ^= p[k]; h *= 0x100000001b3ULL; }
        keys[r] = mix64(h);
    }
}

#define NORM(T, v, lim) ({ T q_ = ((v) / (lim) + (T)1.0) * (T)0.5; q_ < 0 ? (T)0 : (q_ > 1 ? (T)1 : q_); })

/* Networks run at a padded size: 4..12, 16 or 24 nodes (else their own size), so the usual
   sizes get code with the size a constant, which the compiler unrolls and vectorises. Padding
   nodes have no connections and are held silent (neurons) or never read (sigmoid units), so
   they change no number. */
static inline int64_t padded_size(int64_t n) {
    return n < 4 ? 4 : n <= 12 ? n : n <= 16 ? 16 : n <= 24 ? 24 : n;
}
#define SIZE_CASE(K, CALL) case K: { enum { N_ = K }; CALL; break; }
/* SIZED(CALL_N, CALL): CALL_N with N_ the constant padded size np, or CALL for other sizes. */
#define SIZED(CALL_N, CALL) switch (np) {                                                      \
    SIZE_CASE(4, CALL_N) SIZE_CASE(5, CALL_N) SIZE_CASE(6, CALL_N) SIZE_CASE(7, CALL_N)        \
    SIZE_CASE(8, CALL_N) SIZE_CASE(9, CALL_N) SIZE_CASE(10, CALL_N) SIZE_CASE(11, CALL_N)      \
    SIZE_CASE(12, CALL_N) SIZE_CASE(16, CALL_N) SIZE_CASE(24, CALL_N) default: CALL; }
/* LANE_WIDTHS(CALL): CALL with a constant L_, the active lanes rounded up to 1, 2, 4 or 8;
   the lanes past `active` hold stale, finite numbers that nothing reads. */
#define LANE_CASE(K, CALL) case K: { enum { L_ = K }; CALL; break; }
#define LANE_WIDTHS(CALL) switch (active > 4 ? LANES : active > 2 ? 4 : active) {              \
    LANE_CASE(1, CALL) LANE_CASE(2, CALL) LANE_CASE(4, CALL) LANE_CASE(LANES, CALL) }

/* Rate decoding over the window of the last `window` control steps (hist[k * np + j]: spikes
   of node j in slot k), summed in slot order as the torch reference does. */
#define DEFINE_DECODE(SUFFIX, T)                                                               \
static inline T window_rate_##SUFFIX(const T *hist, int64_t window, int64_t np, int64_t j, T denom) { \
    T sum = hist[j];                                                                           \
    for (int64_t k = 1; k < window; ++k) sum += hist[k * np + j];                              \
    return sum / denom;                                                                        \
}                                                                                              \
/* sum_j wo[j] (r_j - rest[j]) over the n real nodes (rest NULL: 0), accumulated in double    \
   over j ascending. */                                                                        \
static inline T weighted_rate_##SUFFIX(const T *hist, int64_t window, int64_t n, int64_t np,   \
                                       T denom, const T *wo, const T *rest) {                  \
    double acc = 0;                                                                            \
    for (int64_t j = 0; j < n; ++j) {                                                          \
        if (wo[j] == 0) continue; /* an absent connection adds exactly 0 */                    \
        T rate = window_rate_##SUFFIX(hist, window, np, j, denom);                             \
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
_Static_assert(LANES > 4, "LANE_WIDTHS rounds 5 or more active lanes up to LANES");
static inline int64_t next_row(int64_t *next, int64_t rows) {
    int64_t r;
    _Pragma("omp atomic capture")
    r = (*next)++;
    return r < rows ? r : -1;
}
/* Lane bookkeeping shared by the loops. Lanes [0, active) hold episodes: row[k] (-1 between
   an episode's end and the next fill), t[k] steps done, s[k] the plant state, W[k] the
   network's weights padded to np x np (a buffer the lane owns). */
#define LANES_INIT(T)                                                                          \
    int64_t np = padded_size(n);                                                               \
    int64_t row[LANES], t[LANES]; T s[LANES][4]; int active = LANES;                           \
    T *wbuf = (T *)calloc(LANES * np * np, sizeof(T)), *W[LANES];                              \
    for (int k = 0; k < LANES; ++k) {                                                          \
        row[k] = -1; t[k] = 0; s[k][0] = s[k][1] = s[k][2] = s[k][3] = 0; W[k] = wbuf + k * np * np; \
    }
#define UNPAREN(...) __VA_ARGS__
/* Copy lane src's `len` values of arr (lanes `stride` apart) to lane k. */
#define COPY_LANE(arr, len, stride) memcpy((arr) + k * (stride), (arr) + src * (stride), (len) * sizeof *(arr))
/* Give every free lane the next row (copying its weights into the lane's buffer, then running
   START with k the lane, r the row); rows with no steps to run finish at once. When rows run
   out, the last lanes move into the free ones (MOVE copies lane src's own arrays to lane k),
   so finished episodes cost nothing. */
#define FILL_LANES(T, START, MOVE)                                                             \
    for (int k = 0; k < active; ++k) {                                                         \
        while (row[k] < 0) {                                                                   \
            int64_t r = next_row(&next, rows);                                                 \
            if (r < 0) break;                                                                  \
            status[r] = 0;                                                                     \
            if (max_steps <= 0) { steps[r] = 0; continue; }                                    \
            row[k] = r; t[k] = 0;                                                              \
            for (int q = 0; q < 4; ++q) s[k][q] = state0[4 * r + q];                           \
            for (int64_t i = 0; i < n; ++i)                                                    \
                for (int64_t j = 0; j < n; ++j) W[k][i * np + j] = w[(r * n + i) * n + j];     \
            UNPAREN START                                                                      \
        }                                                                                      \
    }                                                                                          \
    for (int k = 0; k < active;) {                                                             \
        if (row[k] >= 0) { ++k; continue; }                                                    \
        int src = --active;                                                                    \
        if (src > k) {                                                                         \
            T *wk = W[k];                                                                      \
            row[k] = row[src]; t[k] = t[src]; W[k] = W[src]; W[src] = wk; row[src] = -1;       \
            COPY_LANE(s[0], 4, 4);                                                             \
            UNPAREN MOVE                                                                       \
        }                                                                                      \
    }
/* After lane k's (row r's) plant step: the episode ends on NaN or inf (status 1), on leaving
   the track or the angle limit, or after max_steps; steps[r] counts the steps survived. */
#define END_STEP(T, k, r)                                                                      \
    {                                                                                          \
        const T *sk = s[k];                                                                    \
        int end = 0;                                                                           \
        if (!(isfinite(sk[0]) && isfinite(sk[1]) && isfinite(sk[2]) && isfinite(sk[3]))) {     \
            status[r] = 1; end = 1;                                                            \
        } else if (fabs((double)sk[0]) > (double)xlim || fabs((double)sk[2]) > (double)thlim) { \
            end = 1;                                                                           \
        } else if (++t[k] >= max_steps) {                                                      \
            end = 1;                                                                           \
        }                                                                                      \
        if (end) { steps[r] = t[k]; row[k] = -1; }                                             \
    }
/* A spiking lane's fresh state: every neuron at rest, no spikes, an empty rate window. */
#define SPIKING_START(T)                                                                       \
    for (int64_t j = k * np; j < (k + 1) * np; ++j) { vv[j] = (T)-65.0; uu[j] = b * vv[j]; zz[j] = 0; } \
    for (int64_t q = 0; q < 16 * np; ++q) hist[k * 16 * np + q] = 0;
#define SPIKING_MOVE                                                                           \
    COPY_LANE(vv, np, np); COPY_LANE(uu, np, np); COPY_LANE(zz, np, np); COPY_LANE(hist, 16 * np, 16 * np);

/* One substep of every active spiking lane; neurons below FIRST are driven from outside.
   A macro, not a function, so the lane width L_ and size N_ reach LSUB as constants. */
#define SPIKING_SUBSTEP(LSUB, T, FIRST)                                                        \
    LANE_WIDTHS(SIZED(LSUB(vv, uu, zz, (const T *const *)W, I, cnt, L_, N_, FIRST, n, dt, a, b, c, d, vpeak), \
                      LSUB(vv, uu, zz, (const T *const *)W, I, cnt, L_, np, FIRST, n, dt, a, b, c, d, vpeak)))
/* Lane k's spike counts of this control step into its rate window (hk: the window, denom:
   the window's length so far in s, as the torch reference divides). */
#define RATE_WINDOW(T, k, hk, denom)                                                           \
    T *hk = hist + k * 16 * np;                                                                \
    for (int64_t j = 0; j < np; ++j) hk[(t[k] % window) * np + j] = cnt[k * np + j];           \
    T denom = (T)((double)(t[k] + 1 < window ? t[k] + 1 : window) * (double)window_s);

/* Each thread's lane state of the spiking loops: v, u, spikes, input current, spike counts of
   the control step, and the rate window's history (up to 16 control steps). */
#define SPIKING_LANE_BUFFERS(T)                                                                \
    T vv[LANES * MAXN], uu[LANES * MAXN], zz[LANES * MAXN], I[LANES * MAXN];                   \
    T cnt[LANES * MAXN], hist[LANES * 16 * MAXN];

/* status[r]: 0 ok, 1 the plant produced NaN or inf. */
#define DEFINE_SNN_LOOP(NAME, LSUB, PLANT, T, EXP, SUFFIX)                                     \
void NAME(const T *w, const T *wout, const T *sigma, const T *state0, int64_t *steps,         \
          int64_t *status, int64_t rows, int64_t n, int64_t max_steps, int64_t substeps,      \
          int64_t window, T dt, T a, T b, T c, T d, T vpeak, T ibg, T imax, T window_s,        \
          T tau, T g, T total, T mp, T mpl, T l, T xlim, T thlim, int threads) {               \
    int64_t next = 0;                                                                          \
    _Pragma("omp parallel num_threads(threads)")                                               \
    {                                                                                          \
        SPIKING_LANE_BUFFERS(T)                                                                \
        LANES_INIT(T)                                                                          \
        for (int k = 0; k < LANES; ++k) { SPIKING_START(T) }                                   \
        for (;;) {                                                                             \
            FILL_LANES(T, (SPIKING_START(T)), (SPIKING_MOVE))                                  \
            if (active == 0) break;                                                            \
            for (int k = 0; k < active; ++k) {                                                 \
                T xn = NORM(T, s[k][0], xlim), thn = NORM(T, s[k][2], thlim);                  \
                T *Ik = I + k * np;                                                            \
                for (int64_t j = 0; j < np; ++j) { Ik[j] = ibg; cnt[k * np + j] = 0; }        \
                Ik[0] = ibg + imax * xn; Ik[1] = ibg + imax * thn;                             \
            }                                                                                  \
            for (int64_t q = 0; q < substeps; ++q) {                                           \
                SPIKING_SUBSTEP(LSUB, T, 0)                                                    \
            }                                                                                  \
            for (int k = 0; k < active; ++k) {                                                 \
                int64_t r = row[k];                                                            \
                RATE_WINDOW(T, k, hk, denom)                                                   \
                T drive = weighted_rate_##SUFFIX(hk, window, n, np, denom, wout + r * n, 0);   \
                T fn = (T)1 / ((T)1 + EXP(-(sigma[r] * drive)));                               \
                T force = (T)10.0 * ((T)2.0 * fn - (T)1.0);                                    \
                PLANT(s[k], force, tau, g, total, mp, mpl, l);                                 \
                END_STEP(T, k, r)                                                              \
            }                                                                                  \
        }                                                                                      \
        free(wbuf);                                                                            \
    }                                                                                          \
}
DEFINE_SNN_LOOP(snn_loop_f32, izh_f32_lanes, plant_f32, float, expf, f32)
DEFINE_SNN_LOOP(snn_loop_f64, izh_f64_lanes, plant_f64, double, exp, f64)

/* expf of many floats at once, equal bit for bit to glibc's expf (the algorithm of its
   e_expf.c: x N / ln 2 = k + r, 2^(k/N) from a 32-entry table, a cubic in r, all in double),
   written so the compiler vectorises it. Checked against glibc 2.36's expf on every float
   with |x| < 88: two inputs round the other way, and they, with |x| >= 88, NaN and inf, go to
   expf itself. tests/tasks/test_fused_loop.py checks a sample of all floats on the machine
   it runs on. */
static const uint64_t EXP2F_TABLE[32] = {
    0x3ff0000000000000, 0x3fefd9b0d3158574, 0x3fefb5586cf9890f, 0x3fef9301d0125b51,
    0x3fef72b83c7d517b, 0x3fef54873168b9aa, 0x3fef387a6e756238, 0x3fef1e9df51fdee1,
    0x3fef06fe0a31b715, 0x3feef1a7373aa9cb, 0x3feedea64c123422, 0x3feece086061892d,
    0x3feebfdad5362a27, 0x3feeb42b569d4f82, 0x3feeab07dd485429, 0x3feea47eb03a5585,
    0x3feea09e667f3bcd, 0x3fee9f75e8ec5f74, 0x3feea11473eb0187, 0x3feea589994cce13,
    0x3feeace5422aa0db, 0x3feeb737b0cdc5e5, 0x3feec49182a3f090, 0x3feed503b23e255d,
    0x3feee89f995ad3ad, 0x3feeff76f2fb5e47, 0x3fef199bdd85529c, 0x3fef3720dcef9069,
    0x3fef5818dcfba487, 0x3fef7c97337b9b5f, 0x3fefa4afa2a490da, 0x3fefd0765b6e4540
};
#define EXPF_HARD_1 0x1.04845ep+5f
#define EXPF_HARD_2 -0x1.f8cbb2p+5f
static inline __attribute__((always_inline)) void expf_many(const float *x, float *out, int64_t count) {
    const double c0 = 0x1.c6af84b912394p-5 / 32 / 32 / 32, c1 = 0x1.ebfce50fac4f3p-3 / 32 / 32;
    const double c2 = 0x1.62e42ff0c52d6p-1 / 32, inv_ln2_n = 0x1.71547652b82fep+0 * 32, shift = 0x1.8p+52;
    int fix = 0;
    for (int64_t j = 0; j < count; ++j) {
        double z = inv_ln2_n * (double)x[j], kd = z + shift;
        uint64_t ki, t;
        memcpy(&ki, &kd, 8);
        kd -= shift;
        double r = z - kd, s;
        t = EXP2F_TABLE[ki % 32] + (ki << 47);
        memcpy(&s, &t, 8);
        double p = c0 * r + c1, y = c2 * r + 1.0;
        y = p * (r * r) + y;
        out[j] = (float)(y * s);
        fix |= !(fabsf(x[j]) < 88.0f) | (x[j] == EXPF_HARD_1) | (x[j] == EXPF_HARD_2);
    }
    if (fix)
        for (int64_t j = 0; j < count; ++j)
            if (!(fabsf(x[j]) < 88.0f) || x[j] == EXPF_HARD_1 || x[j] == EXPF_HARD_2) out[j] = expf(x[j]);
}
static inline void exp_many(const double *x, double *out, int64_t count) {
    for (int64_t j = 0; j < count; ++j) out[j] = exp(x[j]);
}
/* For the tests: this library's expf_many and the C library's expf over n floats. */
void expf_many_check(const float *x, float *ours, float *libm, int64_t n) {
    expf_many(x, ours, n);
    for (int64_t j = 0; j < n; ++j) libm[j] = expf(x[j]);
}

/* (float)sin(x) and (float)cos(x) for float x exactly as libm's double sin and cos rounded to
   float (what the plant's sin(s[2]) computes), for up to LANES lanes at once, so the loop over
   lanes vectorises: reduction by pi/2 in three parts (fdlibm's constants; exact to about 1e-26
   for |x| < 2^12), Taylor polynomials on [-pi/4, pi/4] in double (a few ulp), then rounding to
   float. libm itself takes every value whose double could lie within 2^-46 (relative) of a float
   rounding boundary, where libm's double (within 1 ulp of the truth) might round the other way;
   so the float is the same. Also |x| >= 2^12, |r| < 2^-20 (0 included: libm keeps sin(-0) = -0)
   and non-finite x: about 1 in 10^6. */
static inline void sincos_lanes_f32(const float *x, int n, float *sn, float *cs) {
    uint64_t fix = 0, bad[LANES];
    for (int j = 0; j < n; ++j) {
        const double d = x[j];
        const double t = d * 0x1.45f306dc9c883p-1 + 0x1.8p52, kd = t - 0x1.8p52; /* round(d * 2 / pi) */
        uint64_t q; /* its low bits: the quadrant */
        memcpy(&q, &t, 8);
        const double r = ((d - kd * 0x1.921fb544p+0) - kd * 0x1.0b4611a6p-34) - kd * 0x1.3198a2e037073p-69;
        const double z = r * r;
        const double sr = r + r * (z * (((((((((-0x1.2f49b46814157p-57) * z + 0x1.952c77030ad4ap-49) * z + -0x1.ae7f3e733b81fp-41) * z + 0x1.6124613a86d09p-33) * z + -0x1.ae64567f544e4p-26) * z + 0x1.71de3a556c734p-19) * z + -0x1.a01a01a01a01ap-13) * z + 0x1.1111111111111p-7) * z + -0x1.5555555555555p-3)), cr = 1.0 + z * (((((((((-0x1.6827863b97d97p-53) * z + 0x1.ae7f3e733b81fp-45) * z + -0x1.93974a8c07c9dp-37) * z + 0x1.1eed8eff8d898p-29) * z + -0x1.27e4fb7789f5cp-22) * z + 0x1.a01a01a01a01ap-16) * z + -0x1.6c16c16c16c17p-10) * z + 0x1.5555555555555p-5) * z + -0x1.0000000000000p-1);
        double sv = (q & 1) ? cr : sr, cv = (q & 1) ? sr : cr;
        sv = (q & 2) ? -sv : sv;
        cv = ((q + 1) & 2) ? -cv : cv;
        const double ms = fabs(sv) * 0x1.0p-46, mc = fabs(cv) * 0x1.0p-46;
        const float s_lo = (float)(sv - ms), s_hi = (float)(sv + ms), c_lo = (float)(cv - mc), c_hi = (float)(cv + mc);
        sn[j] = s_lo; cs[j] = c_lo;
        const uint64_t b = !(fabs(d) < 0x1.0p12) | (fabs(r) < 0x1.0p-20) | (s_lo != s_hi) | (c_lo != c_hi);
        bad[j] = b;
        fix |= b;
    }
    if (fix)
        for (int j = 0; j < n; ++j)
            if (bad[j]) { sn[j] = (float)sin((double)x[j]); cs[j] = (float)cos((double)x[j]); }
}
/* For the tests: this library's sincos_lanes_f32 and libm's, over n floats. */
void sincos_check(const float *x, float *ours_s, float *ours_c, float *libm_s, float *libm_c, int64_t n) {
    for (int64_t j = 0; j < n; j += LANES) {
        const int m = n - j < LANES ? (int)(n - j) : LANES;
        sincos_lanes_f32(x + j, m, ours_s + j, ours_c + j);
    }
    for (int64_t j = 0; j < n; ++j) { libm_s[j] = (float)sin((double)x[j]); libm_c[j] = (float)cos((double)x[j]); }
}
/* One network update of `lanes` sigmoid networks (lane k: values y[k*np ..], weights W[k]):
   y_j <- 1 / (1 + exp(-slope * sum_i y_i W_ij)), the sum over the n real nodes i ascending,
   as the reference; padding units (j >= n) get values nothing reads. */
#define DEFINE_SIG_UPDATE(NAME, T, EXPS)                                                       \
static inline __attribute__((always_inline)) void NAME(T *y, const T *const *W, int64_t lanes, int64_t np, \
                                                   int64_t n, T slope) {                       \
    T acc[lanes * np];                                                                         \
    for (int64_t k = 0; k < lanes; ++k) {                                                      \
        const T *yk = y + k * np, *Wk = W[k];                                                  \
        T *ak = acc + k * np;                                                                  \
        for (int64_t j = 0; j < np; ++j) ak[j] = 0;                                            \
        /* vectorised over j: each ak[j] still sums over i ascending */                        \
        for (int64_t i = 0; i < n; ++i) {                                                      \
            _Pragma("omp simd")                                                                \
            for (int64_t j = 0; j < np; ++j) ak[j] += yk[i] * Wk[i * np + j];                  \
        }                                                                                      \
    }                                                                                          \
    T e[lanes * np];                                                                           \
    for (int64_t j = 0; j < lanes * np; ++j) acc[j] = -(slope * acc[j]);                       \
    EXPS(acc, e, lanes * np);                                                                  \
    for (int64_t j = 0; j < lanes * np; ++j) y[j] = (T)1 / ((T)1 + e[j]);                      \
}
DEFINE_SIG_UPDATE(sig_update_f32, float, expf_many)
DEFINE_SIG_UPDATE(sig_update_f64, double, exp_many)

#define DEFINE_SIG_LOOP(NAME, UPDATE, PLANT, T)                                                \
/* inputs: state variables obs[k] scaled by lim[k] to [0, 1]; bang: F = +-10 N on y > 0.5 */   \
void NAME(const T *w, const T *state0, int64_t *steps, int64_t *status, int64_t rows,          \
          int64_t n, int64_t n_in, int64_t first_out, int64_t max_steps, int64_t updates,      \
          const int64_t *obs, const T *lim, int64_t bang,                                      \
          T slope, T tau, T g, T total, T mp, T mpl, T l, T xlim, T thlim, int threads) {      \
    int64_t next = 0;                                                                          \
    _Pragma("omp parallel num_threads(threads)")                                               \
    {                                                                                          \
        T y[LANES * MAXN], in[LANES][8];                                                       \
        LANES_INIT(T)                                                                          \
        for (int64_t j = 0; j < LANES * np; ++j) y[j] = 0;                                     \
        for (;;) {                                                                             \
            FILL_LANES(T, (for (int64_t j = k * np; j < (k + 1) * np; ++j) y[j] = 0;),         \
                       (COPY_LANE(y, np, np);))                                                \
            if (active == 0) break;                                                            \
            for (int k = 0; k < active; ++k)                                                   \
                for (int64_t q = 0; q < n_in; ++q) in[k][q] = NORM(T, s[k][obs[q]], lim[q]);   \
            /* inputs and bias are set before every update: nothing reads them after it */     \
            for (int64_t q = 0; q < updates; ++q) {                                            \
                for (int k = 0; k < active; ++k) {                                             \
                    T *yk = y + k * np;                                                        \
                    for (int64_t j = 0; j < n_in; ++j) yk[j] = in[k][j];                       \
                    for (int64_t j = n_in; j < first_out; ++j) yk[j] = 1;                      \
                }                                                                              \
                LANE_WIDTHS(SIZED(UPDATE(y, (const T *const *)W, L_, N_, n, slope),            \
                                  UPDATE(y, (const T *const *)W, L_, np, n, slope)))           \
            }                                                                                  \
            T sn[LANES], cs[LANES];                                                            \
            SINCOS(T, active, s, sn, cs)                                                       \
            for (int k = 0; k < active; ++k) {                                                 \
                T out = y[k * np + first_out];                                                 \
                T force = bang ? (out > (T)0.5 ? (T)10.0 : (T)-10.0) : (T)10.0 * ((T)2.0 * out - (T)1.0); \
                PLANT##_trig(s[k], force, sn[k], cs[k], tau, g, total, mp, mpl, l);            \
            }                                                                                  \
            for (int k = 0; k < active; ++k) {                                                 \
                int64_t r = row[k];                                                            \
                END_STEP(T, k, r)                                                              \
            }                                                                                  \
        }                                                                                      \
        free(wbuf);                                                                            \
    }                                                                                          \
}
/* sin and cos of the lanes' angles: float lanes by sincos_lanes_f32, double ones by libm. */
#define SINCOS(T, n, s, sn, cs)                                                                \
    if (sizeof(T) == sizeof(float)) {                                                          \
        float th[LANES];                                                                       \
        for (int k = 0; k < (n); ++k) th[k] = (float)s[k][2];                                  \
        sincos_lanes_f32(th, (n), (float *)(sn), (float *)(cs));                               \
    } else {                                                                                   \
        for (int k = 0; k < (n); ++k) { sn[k] = sin(s[k][2]); cs[k] = cos(s[k][2]); }         \
    }
DEFINE_SIG_LOOP(sig_loop_f32, sig_update_f32, plant_f32, float)
DEFINE_SIG_LOOP(sig_loop_f64, sig_update_f64, plant_f64, double)

/* Markov task: n_in Bernoulli input nodes fire in each substep with probability norm * pmax.
   wout == NULL: F = +10 N when the output neuron's rate over the window exceeds thr_hz, else -10 N.
   wout != NULL: the output node decodes, as in the non-Markov task, from the rates r_j of the
   nodes wired to it (inputs included): F = +10 N when sum_j wout[j] (r_j - rest[j]) exceeds
   thr_hz, else -10 N. */
#define DEFINE_MARKOV_LOOP(NAME, LSUB, PLANT, T, SUFFIX)                                       \
void NAME(const T *w, const T *wout, const T *rest, const uint64_t *keys, const T *state0, int64_t *steps, \
          int64_t *status, int64_t rows, int64_t n, int64_t n_in, int64_t out, int64_t max_steps, \
          int64_t substeps, int64_t window, const int64_t *obs, const T *lim,                   \
          T dt, T a, T b, T c, T d, T vpeak, T ibg, T pmax, T thr_hz, T window_s,              \
          T tau, T g, T total, T mp, T mpl, T l, T xlim, T thlim, int threads) {               \
    int64_t next = 0;                                                                          \
    _Pragma("omp parallel num_threads(threads)")                                               \
    {                                                                                          \
        SPIKING_LANE_BUFFERS(T)                                                                \
        uint64_t counter[LANES];                                                               \
        const int64_t draws = substeps * n_in; /* input spikes per control step */             \
        T *spikes = (T *)malloc(LANES * draws * sizeof(T));                                    \
        double *prob = (double *)malloc(draws * sizeof(double));                               \
        LANES_INIT(T)                                                                          \
        for (int64_t j = 0; j < LANES * np; ++j) I[j] = ibg;                                   \
        for (int k = 0; k < LANES; ++k) { SPIKING_START(T) counter[k] = 0; }                   \
        for (;;) {                                                                             \
            FILL_LANES(T, (SPIKING_START(T) counter[k] = 0;), (SPIKING_MOVE counter[k] = counter[src];)) \
            if (active == 0) break;                                                            \
            /* This control step's input spikes, all drawn up front: draw q * n_in + i of a lane \
               is input i in substep q, from the same counter as one draw at a time, so the    \
               counter-based draws vectorise over the step. */                                 \
            for (int k = 0; k < active; ++k) {                                                 \
                T pk[8];                                                                       \
                for (int64_t q = 0; q < n_in; ++q) pk[q] = NORM(T, s[k][obs[q]], lim[q]) * pmax; \
                for (int64_t j = k * np; j < (k + 1) * np; ++j) cnt[j] = 0;                    \
                for (int64_t m = 0; m < draws; m += n_in)                                      \
                    for (int64_t i = 0; i < n_in; ++i) prob[m + i] = (double)pk[i];            \
                const uint64_t key = keys[row[k]], c0 = counter[k];                            \
                T *sk = spikes + k * draws;                                                    \
                for (int64_t m = 0; m < draws; ++m) sk[m] = uniform01(key, c0 + m) < prob[m] ? (T)1 : (T)0; \
                counter[k] += draws;                                                           \
            }                                                                                  \
            for (int64_t q = 0; q < substeps; ++q) {                                           \
                for (int k = 0; k < active; ++k) {                                             \
                    for (int64_t i = 0; i < n_in; ++i) {                                       \
                        T z = spikes[k * draws + q * n_in + i];                                \
                        zz[k * np + i] = z;                                                    \
                        cnt[k * np + i] += z;                                                  \
                    }                                                                          \
                }                                                                              \
                SPIKING_SUBSTEP(LSUB, T, n_in)                                                 \
            }                                                                                  \
            for (int k = 0; k < active; ++k) {                                                 \
                int64_t r = row[k];                                                            \
                RATE_WINDOW(T, k, hk, denom)                                                   \
                T drive = wout ? weighted_rate_##SUFFIX(hk, window, n, np, denom, wout + r * n, rest) \
                               : window_rate_##SUFFIX(hk, window, np, out, denom);             \
                T force = drive > thr_hz ? (T)10.0 : (T)-10.0;                                 \
                PLANT(s[k], force, tau, g, total, mp, mpl, l);                                 \
                END_STEP(T, k, r)                                                              \
            }                                                                                  \
        }                                                                                      \
        free(wbuf); free(spikes); free(prob);                                                  \
    }                                                                                          \
}
DEFINE_MARKOV_LOOP(markov_loop_f32, izh_f32_lanes, plant_f32, float, f32)
DEFINE_MARKOV_LOOP(markov_loop_f64, izh_f64_lanes, plant_f64, double, f64)
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
