/* Control steps of population recurrent Izhikevich networks (see recurrent_izhikevich.h).

   The torch step (snn_torch.functional.recurrent.recurrent_izhikevich_step) is the definition:
   this kernel repeats its operations in the same order, with no floating-point contraction
   (built with -ffp-contract=off), so the two agree bit for bit (tests/snn_torch/test_network_kernel.py).
   Synaptic input sums over presynaptic slots in ascending order, as the torch step does.

   Lanes: each thread takes LANES consecutive rows at a time and runs their networks side by
   side, so the core overlaps what one network's serial chain (input sum, Heun, reset, next
   input sum) would leave idle. Constant sizes: networks run padded to 4..12, 16 or 24 neurons
   (padding neurons have no synapses and are held silent), so the usual sizes get code with the
   size a compile-time constant, which the compiler unrolls and vectorises. Every lane's
   arithmetic is its own network's, so a row's result does not depend on its lane, its chunk,
   its neighbours or the thread count. */
#include "recurrent_izhikevich.h"

#include "counter_rng.h"
#include "portable_math.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define MAXN 64
#define LANES 8

#define OWN(j) (all || own[j])
#define DEFINE_NEURON(NAME, T)                                                                 \
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
   `first` are spike sources (z and counts set by the caller), those from n_real on pad the    \
   network and stay silent. `all` is a constant after inlining, so the usual case carries no   \
   mask. */                                                                                    \
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
            vv[j] = OWN(j) ? v1[j] : vv[j]; uu[j] = OWN(j) ? u1[j] : uu[j];                    \
            zz[j] = OWN(j) ? (T)0 : zz[j];                                                     \
        }                                                                                      \
        return;                                                                                \
    }                                                                                          \
    /* Branch-free, so a constant size vectorises: every neuron's reset is computed and kept   \
       only where it spiked (v1 >= vpeak, or NaN, as the reference counts it). */              \
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
        NAME##_update_(vv, uu, zz, it, I, cnt, count, n, first, n_real, dt, a, b, c, d, vpeak, 1); \
    else                                                                                       \
        NAME##_update_(vv, uu, zz, it, I, cnt, count, n, first, n_real, dt, a, b, c, d, vpeak, 0); \
}                                                                                              \
/* Synaptic input to one network's neurons (weights W[pre*n+post]), pre ascending as the      \
   reference sums; silent neurons add exactly 0, so they are skipped. */                       \
static inline void NAME##_input(const T *zz, const T *W, T *it, int64_t n) {                   \
    for (int64_t j = 0; j < n; ++j) it[j] = 0;                                                 \
    for (int64_t k = 0; k < n; ++k) {                                                          \
        const T *Wk = W + k * n;                                                               \
        for (int64_t j = 0; j < n; ++j) it[j] += zz[k] * Wk[j];                                \
    }                                                                                          \
}                                                                                              \
/* ss not NULL: exponential synapses, the synaptic current ss <- sk ss + sk1 W z (sk the decay,     \
   sk1 = 1 - sk: snn_torch.functional.recurrent's _synaptic_input, in its order) drives them.   \
   Padding neurons get no input, so their ss stays 0. */                                       \
static inline void NAME##_lanes(T *vv, T *uu, T *zz, const T *const *W, const T *I, T *cnt,         \
                                int64_t lanes, int64_t n, int64_t first, int64_t n_real,       \
                                T dt, T a, T b, T c, T d, T vpeak, T *ss, T sk, T sk1) {       \
    T it[lanes * n];                                                                           \
    for (int64_t k = 0; k < lanes; ++k) NAME##_input(zz + k * n, W[k], it + k * n, n);         \
    if (ss)                                                                                    \
        for (int64_t j = 0; j < lanes * n; ++j) { ss[j] = ss[j] * sk + sk1 * it[j]; it[j] = ss[j]; } \
    NAME##_update(vv, uu, zz, it, I, cnt, lanes * n, n, first, n_real, dt, a, b, c, d, vpeak); \
}
DEFINE_NEURON(izh_f32, float)
DEFINE_NEURON(izh_f64, double)

/* Padded sizes 4..12, 16, 24 (else the network's own size): SIZED(CALL_N, CALL) runs CALL_N
   with N_ the constant padded size np, or CALL for other sizes. */
static inline int64_t padded_size(int64_t n) {
    return n < 4 ? 4 : n <= 12 ? n : n <= 16 ? 16 : n <= 24 ? 24 : n;
}
#define SIZE_CASE(K, CALL) case K: { enum { N_ = K }; CALL; break; }
#define SIZED(CALL_N, CALL) switch (np) {                                                      \
    SIZE_CASE(4, CALL_N) SIZE_CASE(5, CALL_N) SIZE_CASE(6, CALL_N) SIZE_CASE(7, CALL_N)        \
    SIZE_CASE(8, CALL_N) SIZE_CASE(9, CALL_N) SIZE_CASE(10, CALL_N) SIZE_CASE(11, CALL_N)      \
    SIZE_CASE(12, CALL_N) SIZE_CASE(16, CALL_N) SIZE_CASE(24, CALL_N) default: CALL; }
/* LANE_WIDTHS(CALL): CALL with a constant L_, the lanes in use rounded up to 1, 2, 4 or 8; the
   lanes past `lanes` hold zeros (finite numbers) that nothing reads. */
#define LANE_CASE(K, CALL) case K: { enum { L_ = K }; CALL; break; }
#define LANE_WIDTHS(CALL) switch (lanes > 4 ? LANES : lanes > 2 ? 4 : lanes) {                 \
    LANE_CASE(1, CALL) LANE_CASE(2, CALL) LANE_CASE(4, CALL) LANE_CASE(LANES, CALL) }

#define DEFINE_STEPS(NAME, PREFIX, T)                                                          \
void NAME(T *v, T *u, T *z, T *counts, const T *w, const int64_t *net, const T *iext,         \
          const T *src, const double *prob, const int64_t *keys, int64_t base, int64_t rows,  \
          int64_t n, int64_t n_src, int64_t substeps, T dt, T a,                               \
          T b, T c, T d, T vpeak, T *s, double syn_k, int threads) {                           \
    const int64_t np = padded_size(n), chunks = (rows + LANES - 1) / LANES;                    \
    const T sk = (T)syn_k, sk1 = (T)(1.0 - syn_k);                                             \
    _Pragma("omp parallel num_threads(threads)")                                               \
    {                                                                                          \
        T vv[LANES * MAXN], uu[LANES * MAXN], zz[LANES * MAXN], I[LANES * MAXN];               \
        T ss[LANES * MAXN]; /* synaptic currents (s not NULL); padding stays 0 */              \
        memset(ss, 0, sizeof ss);                                                              \
        T cnt[LANES * MAXN]; const T *W[LANES];                                                        \
        T *wbuf = (T *)calloc(LANES * np * np, sizeof(T)); /* padding stays 0: no synapses */  \
        /* Bernoulli spikes of a chunk's control step, drawn before its substeps (counter       \
           substep * n_src + source) and compared as integers (uniform01_threshold: the same    \
           decisions as uniform01 < p), read back in the substeps. */                          \
        const int64_t M = substeps * n_src;                                                    \
        const int bern = !src && n_src;                                                        \
        T *draws = bern ? (T *)malloc(LANES * M * sizeof(T)) : NULL;                           \
        memset(vv, 0, sizeof vv); memset(uu, 0, sizeof uu); memset(zz, 0, sizeof zz);          \
        memset(I, 0, sizeof I);                                                                \
        for (int k = 0; k < LANES; ++k) W[k] = wbuf + k * np * np;                             \
        _Pragma("omp for schedule(static)")                                                    \
        for (int64_t chunk = 0; chunk < chunks; ++chunk) {                                     \
            const int64_t r0 = chunk * LANES;                                                  \
            const int64_t lanes = rows - r0 < LANES ? rows - r0 : LANES;                       \
            for (int64_t k = 0; k < lanes; ++k) {                                              \
                const int64_t r = r0 + k, g = net ? net[r] : r;                                \
                const T *wg = w + g * n * n;                                                   \
                if (np == n) { /* no padding: read the network's weights where they are */     \
                    W[k] = wg;                                                            \
                } else {                                                                       \
                    T *wk = wbuf + k * np * np;                                                \
                    W[k] = wk;                                                                 \
                    for (int64_t i = 0; i < n; ++i)                                            \
                        memcpy(wk + i * np, wg + i * n, n * sizeof(T));                      \
                }                                                                              \
                memcpy(vv + k * np, v + r * n, n * sizeof(T));                                 \
                memcpy(uu + k * np, u + r * n, n * sizeof(T));                                 \
                memcpy(zz + k * np, z + r * n, n * sizeof(T));                                 \
                memcpy(I + k * np, iext + r * n, n * sizeof(T));                               \
                if (s) memcpy(ss + k * np, s + r * n, n * sizeof(T));                          \
                for (int64_t j = 0; j < np; ++j) cnt[k * np + j] = 0;                          \
            }                                                                                  \
            for (int64_t k = 0; k < lanes && bern; ++k) {                                      \
                const int64_t r = r0 + k;                                                      \
                const uint64_t key = (uint64_t)keys[r];                                        \
                T *dk = draws + k * M;                                                         \
                for (int64_t i = 0; i < n_src; ++i) {                                          \
                    const int64_t below = uniform01_threshold(prob[r * n_src + i]);            \
                    for (int64_t q = 0; q < substeps; ++q)                                     \
                        dk[q * n_src + i] =                                                    \
                            uniform01_bits(key, (uint64_t)(base + q * n_src + i)) < below ? (T)1 : (T)0; \
                }                                                                              \
            }                                                                                  \
            for (int64_t q = 0; q < substeps; ++q) {                                           \
                for (int64_t k = 0; k < lanes && n_src; ++k) {                                 \
                    const int64_t r = r0 + k;                                                  \
                    const T *sq = src ? src + (r * substeps + q) * n_src : draws + k * M + q * n_src; \
                    for (int64_t i = 0; i < n_src; ++i) {                                      \
                        zz[k * np + i] = sq[i];                                                \
                        cnt[k * np + i] += sq[i];                                              \
                    }                                                                          \
                }                                                                              \
                LANE_WIDTHS(SIZED(PREFIX##_lanes(vv, uu, zz, W, I, cnt, L_, N_, n_src, n, dt, a, b, c, d, vpeak, \
                                                 s ? ss : NULL, sk, sk1),                      \
                                  PREFIX##_lanes(vv, uu, zz, W, I, cnt, L_, np, n_src, n, dt, a, b, c, d, vpeak, \
                                                 s ? ss : NULL, sk, sk1)))                     \
            }                                                                                  \
            for (int64_t k = 0; k < lanes; ++k) {                                              \
                const int64_t r = r0 + k;                                                      \
                memcpy(v + r * n, vv + k * np, n * sizeof(T));                                 \
                memcpy(u + r * n, uu + k * np, n * sizeof(T));                                 \
                memcpy(z + r * n, zz + k * np, n * sizeof(T));                                 \
                memcpy(counts + r * n, cnt + k * np, n * sizeof(T));                           \
                if (s) memcpy(s + r * n, ss + k * np, n * sizeof(T));                          \
            }                                                                                  \
        }                                                                                      \
        free(wbuf); free(draws);                                                               \
    }                                                                                          \
}
DEFINE_STEPS(izh_network_steps_f32, izh_f32, float)
DEFINE_STEPS(izh_network_steps_f64, izh_f64, double)

/* One control step of rate-coded controllers (see the header): encode, run the networks, record
   the counts in the rate window, read the drive out. Each piece repeats the torch modules'
   operations in their order (snn_torch.modules.coding, ordered_matvec), so the two agree bit for
   bit; the readout sums over slots in ascending order with a double accumulator. */
#define DEFINE_CONTROL(NAME, STEPS, T)                                                         \
void NAME(T *v, T *u, T *z, T *counts, const T *w, const int64_t *net, const T *x,             \
          int64_t n_x, T gain, const T *iconst, const int64_t *keys, int64_t base,            \
          T *history, int64_t window, int64_t slot, T rate_div, const T *w_out,               \
          int64_t n_out, const T *rest, T *drive, int64_t rows, int64_t n, int64_t substeps,   \
          T dt, T a, T b, T c, T d, T vpeak, T *s, double syn_k, int threads) {                \
    T *iext = (T *)malloc((size_t)(rows * n > 0 ? rows * n : 1) * sizeof(T));                 \
    double *prob = keys ? (double *)malloc((size_t)(rows * n_x > 0 ? rows * n_x : 1) * sizeof(double)) \
                        : NULL;                                                                \
    _Pragma("omp parallel for num_threads(threads) schedule(static)")                         \
    for (int64_t r = 0; r < rows; ++r) {                                                       \
        const T *xr = x + r * n_x;                                                             \
        for (int64_t j = 0; j < n; ++j)                                                        \
            iext[r * n + j] = (!keys && j < n_x) ? gain * xr[j] + iconst[j] : iconst[j];      \
        for (int64_t i = 0; keys && i < n_x; ++i) prob[r * n_x + i] = (double)(xr[i] * gain);   \
    }                                                                                          \
    STEPS(v, u, z, counts, w, net, iext, NULL, prob, keys, base, rows, n, keys ? n_x : 0,    \
          substeps, dt, a, b, c, d, vpeak, s, syn_k, threads);                                 \
    free(iext); free(prob);                                                                    \
    const int64_t plane = rows * n;                                                            \
    _Pragma("omp parallel for num_threads(threads) schedule(static)")                         \
    for (int64_t r = 0; r < rows; ++r) {                                                       \
        T y[MAXN];                                                                             \
        const int64_t g = net ? net[r] : r;                                                    \
        memcpy(history + slot * plane + r * n, counts + r * n, n * sizeof(T));                 \
        for (int64_t j = 0; j < n; ++j) {                                                      \
            T total = history[r * n + j]; /* whole numbers: exact in any order */              \
            for (int64_t k = 1; k < window; ++k) total += history[k * plane + r * n + j];      \
            y[j] = total / rate_div;                                                           \
            if (rest) y[j] = y[j] - rest[j];                                                   \
        }                                                                                      \
        const T *wg = w_out + g * n * n_out;                                                   \
        for (int64_t k = 0; k < n_out; ++k) {                                                  \
            double acc = (double)(y[0] * wg[k]);                                               \
            for (int64_t j = 1; j < n; ++j) acc += (double)(y[j] * wg[j * n_out + k]);         \
            drive[r * n_out + k] = (T)acc;                                                     \
        }                                                                                      \
    }                                                                                          \
}
DEFINE_CONTROL(izh_rate_control_step_f32, izh_network_steps_f32, float)
DEFINE_CONTROL(izh_rate_control_step_f64, izh_network_steps_f64, double)

/* The decoders of evolution.SpikingController (snn_torch.modules.coding's SigmoidForce, BangBang
   and LinearReadout as the controller calls them), one action from one drive: the modules'
   operations in their order, the sigmoid portable_math.h's. decoder 0: a_max (2 sigmoid(sigma d)
   - 1); 1: +-a_max on d > threshold; 2: a_max (sigma d) + 0, clamped to +-a_max. */
#define DEFINE_DECODE(NAME, T)                                                                 \
static inline T NAME##_decode(T drive, T sigma, int64_t decoder, T amax, T threshold) {        \
    if (decoder == 0) return amax * ((T)2 * (T)pm_sigmoid((double)(sigma * drive)) - (T)1);   \
    if (decoder == 1) return drive > threshold ? amax : -amax;                                 \
    const T v = amax * (sigma * drive) + (T)0;                                                 \
    return v < -amax ? -amax : (v > amax ? amax : v);                                          \
}                                                                                              \
void rate_decode_##NAME(const T *drive, const T *sigma, T *action, int64_t rows, int64_t n_out, \
                        int64_t decoder, double action_max, double threshold) {                \
    for (int64_t r = 0; r < rows; ++r)                                                         \
        for (int64_t k = 0; k < n_out; ++k)                                                    \
            action[r * n_out + k] = NAME##_decode(drive[r * n_out + k], sigma[r], decoder,      \
                                                  (T)action_max, (T)threshold);                \
}
DEFINE_DECODE(f32, float)
DEFINE_DECODE(f64, double)
