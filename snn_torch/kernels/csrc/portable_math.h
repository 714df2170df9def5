/* sin, cos, exp and the sigmoid of snn_torch.functional.portable_math, in C: the same float64
   operations in the same order, so a kernel that includes this agrees with the torch path bit for
   bit (built with -ffp-contract=off: no product is fused into a sum). Everything here is static
   inline: a header of helpers, not of exported functions. */
#ifndef SNN_PORTABLE_MATH_H
#define SNN_PORTABLE_MATH_H

#include <math.h>
#include <stdint.h>
#include <string.h>

#define PM_EXP_CLAMP 708.0
#define PM_LOG2E 1.4426950408889634
#define PM_LN2_HI 6.93147180369123816490e-01
#define PM_LN2_LO 1.90821492927058770002e-10
#define PM_TWO_OVER_PI 6.36619772367581382433e-01
#define PM_PIO2_1 1.57079632673412561417e+00
#define PM_PIO2_2 6.07710050630396597660e-11
#define PM_PIO2_3 2.02226624871116645580e-21

/* Taylor coefficients in Horner order, as the torch module computes them: 1/n! for n = 12..2;
   the tails of sin and cos past their leading terms, (-1)^k/(2k+1)! for k = 8..2 and
   (-1)^k/(2k)! for k = 9..3. Each is the double nearest the exact fraction (the torch module
   divides 1.0 by an exact integer factorial, which rounds the same). */
static const double PM_EXP_C[11] = {
    1.0 / 479001600.0, 1.0 / 39916800.0, 1.0 / 3628800.0, 1.0 / 362880.0, 1.0 / 40320.0, 1.0 / 5040.0,
    1.0 / 720.0, 1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 1.0 / 2.0};
static const double PM_SIN_TAIL[7] = {
    1.0 / 355687428096000.0, -1.0 / 1307674368000.0, 1.0 / 6227020800.0, -1.0 / 39916800.0,
    1.0 / 362880.0, -1.0 / 5040.0, 1.0 / 120.0};
static const double PM_COS_TAIL[7] = {
    -1.0 / 6402373705728000.0, 1.0 / 20922789888000.0, -1.0 / 87178291200.0, 1.0 / 479001600.0,
    -1.0 / 3628800.0, 1.0 / 40320.0, -1.0 / 720.0};
/* -1/6 and 1/24 as double-doubles (high part, exact remainder) */
#define PM_S1_HI (-1.0 / 6.0)
#define PM_S1_LO (-9.25185853854297e-18)
#define PM_C2_HI (1.0 / 24.0)
#define PM_C2_LO 2.3129646346357427e-18
#define PM_SPLIT 134217729.0 /* 2^27 + 1: Dekker's splitting constant */

static inline double pm_horner(double z, const double *c, int m) {
    double acc = c[0];
    for (int i = 1; i < m; ++i) acc = acc * z + c[i];
    return acc;
}

static inline double pm_pow2(double k) {
    const uint64_t bits = (uint64_t)((int64_t)k + 1023) << 52;
    double out;
    memcpy(&out, &bits, sizeof out);
    return out;
}

/* p + *e == a * b exactly (Dekker; no fused multiply-add needed) */
static inline double pm_two_prod(double a, double b, double *e) {
    const double p = a * b;
    const double ca = a * PM_SPLIT, ah = ca - (ca - a), al = a - ah;
    const double cb = b * PM_SPLIT, bh = cb - (cb - b), bl = b - bh;
    *e = (((ah * bh - p) + ah * bl) + al * bh) + al * bl;
    return p;
}

/* s + *e == a + b exactly (Knuth) */
static inline double pm_two_sum(double a, double b, double *e) {
    const double s = a + b, bb = s - a;
    *e = (a - (s - bb)) + (b - bb);
    return s;
}

/* sin and cos of x (rad); NaN for NaN or infinite x. The torch module's steps, in its order. */
static inline void pm_sincos(double x, double *sin_out, double *cos_out) {
    if (!isfinite(x)) {
        *sin_out = *cos_out = NAN;
        return;
    }
    const double k = floor(x * PM_TWO_OVER_PI + 0.5);
    double rl, zl, cl, tl, e, ql, ul, e2;
    const double rh = pm_two_sum(x - k * PM_PIO2_1, -(k * PM_PIO2_2), &rl);
    rl = rl - k * PM_PIO2_3;
    const double zh = pm_two_prod(rh, rh, &zl);
    const double ch = pm_two_prod(rh, zh, &cl);
    cl = cl + rh * zl;
    const double th = pm_two_prod(ch, PM_S1_HI, &tl);
    tl = (tl + ch * PM_S1_LO) + cl * PM_S1_HI;
    double s = pm_two_sum(rh, th, &e);
    s = s + (e + ((tl + (ch * zh) * pm_horner(zh, PM_SIN_TAIL, 7)) + rl * (1.0 - 0.5 * zh)));
    const double w = pm_two_sum(1.0, -(0.5 * zh), &e);
    const double qh = pm_two_prod(zh, zh, &ql);
    ql = ql + 2.0 * (zh * zl);
    const double uh = pm_two_prod(qh, PM_C2_HI, &ul);
    ul = (ul + qh * PM_C2_LO) + ql * PM_C2_HI;
    double c = pm_two_sum(w, uh, &e2);
    c = c + (e2 + (e + (((ul - 0.5 * zl) + (qh * zh) * pm_horner(zh, PM_COS_TAIL, 7)) - rl * rh)));
    const int64_t q = (int64_t)k & 3;
    const double sr = (q & 1) ? c : s, cr = (q & 1) ? s : c;
    *sin_out = q >= 2 ? -sr : sr;
    *cos_out = (q == 1 || q == 2) ? -cr : cr;
}

/* e^x with x clamped to [-708, 708]; NaN in, NaN out. */
static inline double pm_exp(double x) {
    if (isnan(x)) return x;
    const double xc = x < -PM_EXP_CLAMP ? -PM_EXP_CLAMP : (x > PM_EXP_CLAMP ? PM_EXP_CLAMP : x);
    const double k = floor(xc * PM_LOG2E + 0.5);
    const double r = (xc - k * PM_LN2_HI) - k * PM_LN2_LO;
    const double p = 1.0 + r * (1.0 + r * pm_horner(r, PM_EXP_C, 11));
    return p * pm_pow2(k);
}

/* 1 / (1 + e^-x) in double (float callers round the result once, as the torch module does). */
static inline double pm_sigmoid(double x) { return 1.0 / (1.0 + pm_exp(-x)); }

#endif
