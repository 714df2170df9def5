/* Standard normals from two uniforms, the C side of evolution.rng.box_muller:
   sqrt(-2 log(1 - u1)) cos(2 pi u2), with log, cos and sqrt our own, built from IEEE-exact
   operations only (+ - * /, exponent bits), so these and the torch reference give the same bits
   on any machine. Branch-free, so loops over them vectorise. The kernels are built without
   contraction (-ffp-contract=off), which the bit-for-bit agreement needs.

   The series coefficients are evolution.rng's _LOG_C, _COS_C and _SIN_C as exact hex floats,
   lowest power first; tests/evolution/test_kernel_sources.py checks that they stay equal. */
#ifndef SNN_NEAT_BOX_MULLER_H
#define SNN_NEAT_BOX_MULLER_H

#include <stdint.h>
#include <string.h>

#include "counter_rng.h"

/* log1p(f) = 2s (1 + z/3 + z^2/5 + ...), s = f / (f + 2), z = s^2: 1 / (2k + 1) */
static const double BM_LOG_C[11] = {
    0x1.0000000000000p+0, 0x1.5555555555555p-2, 0x1.999999999999ap-3,
    0x1.2492492492492p-3, 0x1.c71c71c71c71cp-4, 0x1.745d1745d1746p-4,
    0x1.3b13b13b13b14p-4, 0x1.1111111111111p-4, 0x1.e1e1e1e1e1e1ep-5,
    0x1.af286bca1af28p-5, 0x1.8618618618618p-5,
};
/* cos x on [0, pi/4], in z = x^2: (-1)^k / (2k)! */
static const double BM_COS_C[10] = {
    0x1.0000000000000p+0, -0x1.0000000000000p-1, 0x1.5555555555555p-5,
    -0x1.6c16c16c16c17p-10, 0x1.a01a01a01a01ap-16, -0x1.27e4fb7789f5cp-22,
    0x1.1eed8eff8d898p-29, -0x1.93974a8c07c9dp-37, 0x1.ae7f3e733b81fp-45,
    -0x1.6827863b97d97p-53,
};
/* sin x / x on [0, pi/4], in z = x^2: (-1)^k / (2k + 1)! */
static const double BM_SIN_C[10] = {
    0x1.0000000000000p+0, -0x1.5555555555555p-3, 0x1.1111111111111p-7,
    -0x1.a01a01a01a01ap-13, 0x1.71de3a556c734p-19, -0x1.ae64567f544e4p-26,
    0x1.6124613a86d09p-33, -0x1.ae7f3e733b81fp-41, 0x1.952c77030ad4ap-49,
    -0x1.2f49b46814157p-57,
};
#define BM_LN2 0x1.62e42fefa39efp-1
#define BM_SQRT_HALF 0x1.6a09e667f3bcdp-1
#define BM_TWO_PI 0x1.921fb54442d18p+2

/* c[0] + c[1] z + ... + c[n - 1] z^(n - 1), Horner from the highest power as
   evolution.rng._horner. Unrolled, the constant arrays' loads fold into immediates. */
static inline double bm_horner(double z, const double *c, int n) {
    double p = c[n - 1];
    _Pragma("GCC unroll 16")
    for (int k = n - 2; k >= 0; --k) p = p * z + c[k];
    return p;
}
/* log(x) for x in [2^-53, 1]. */
static inline double bm_log_unit(double x) {
    uint64_t bits; memcpy(&bits, &x, 8);
    double e = (double)((int64_t)((bits >> 52) & 0x7FF) - 1022), m;  /* frexp, x normal */
    bits = (bits & 0x000FFFFFFFFFFFFFULL) | (1022ULL << 52); memcpy(&m, &bits, 8);
    const int small = m < BM_SQRT_HALF;
    m = small ? m * 2.0 : m; e = small ? e - 1.0 : e;
    const double f = m - 1.0, s = f / (f + 2.0), z = s * s;
    return e * BM_LN2 + (s + s) * bm_horner(z, BM_LOG_C, 11);
}
/* cos(2 pi u) for u in [0, 1), reduced exactly to an angle in [0, pi/4]. */
static inline double bm_cos_2pi(double u) {
    double t = u > 0.5 ? 1.0 - u : u;
    const int negate = t > 0.25;
    t = negate ? 0.5 - t : t;
    const int use_sin = t > 0.125;
    t = use_sin ? 0.25 - t : t;
    const double x = t * BM_TWO_PI, z = x * x;
    const double v = use_sin ? x * bm_horner(z, BM_SIN_C, 10) : bm_horner(z, BM_COS_C, 10);
    return negate ? -v : v;
}
/* sqrt(v) for v in {0} or [2^-60, 2^60] by Newton, as evolution.rng._sqrt: not the hardware
   sqrt, since torch's float64 sqrt is not correctly rounded on every CPU. */
static inline double bm_sqrt(double v) {
    uint64_t bits; memcpy(&bits, &v, 8);
    int64_t e = (int64_t)((bits >> 52) & 0x7FF) - 1022;
    double m;
    bits = (bits & 0x000FFFFFFFFFFFFFULL) | (1022ULL << 52); memcpy(&m, &bits, 8);
    const int odd = (e & 1) != 0;
    m = odd ? m * 2.0 : m;
    const int64_t half_e = (odd ? e - 1 : e) / 2;
    double y = 0.5 + 0.5 * m;
    for (int k = 0; k < 5; ++k) y = 0.5 * (y + m / y);
    const uint64_t sb = (uint64_t)(half_e + 1023) << 52;
    double scale; memcpy(&scale, &sb, 8);
    return v == 0.0 ? 0.0 : y * scale;
}
static inline double box_muller(double u1, double u2) {
    return bm_sqrt(-2.0 * bm_log_unit(1.0 - u1)) * bm_cos_2pi(u2);
}
/* The normal at counter c of a stream, from the uniforms at c and c + 1 (RunRNG.randn). */
static inline double normal_at(uint64_t key, uint64_t c) {
    return box_muller(uniform01(key, c), uniform01(key, c + 1));
}

#endif
