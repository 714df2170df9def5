/* Test-only exports of snn_torch/kernels/csrc/portable_math.h over arrays (tests/snn_torch/test_portable_math.py). */
#include <stdint.h>

void probe_sincos(const double *x, double *s, double *c, int64_t n);
void probe_exp(const double *x, double *y, int64_t n);
void probe_sigmoid_f32(const float *x, float *y, int64_t n);
