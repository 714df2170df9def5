/* Test-only exports of portable_math.h (see portable_math_probe.h). */
#include "portable_math_probe.h"

#include "portable_math.h"

void probe_sincos(const double *x, double *s, double *c, int64_t n) {
    for (int64_t i = 0; i < n; ++i) pm_sincos(x[i], s + i, c + i);
}

void probe_exp(const double *x, double *y, int64_t n) {
    for (int64_t i = 0; i < n; ++i) y[i] = pm_exp(x[i]);
}

void probe_sigmoid_f32(const float *x, float *y, int64_t n) {
    for (int64_t i = 0; i < n; ++i) y[i] = (float)pm_sigmoid((double)x[i]);
}
