/* The C kernel of snn_torch.PopulationRecurrentSigmoid: the clamp and the slot-ordered weighted
   sum of one synchronous update of many recurrent sigmoid networks. Every function here is
   exported; snn_torch._cbuild reads these prototypes to declare the ctypes signatures. */
#include <stdint.h>

/* For rows r of node values y[r][0..n): the values with nodes [0, n_in) clamped to inputs[r] and
   nodes [n_in, n_in + n_bias) to 1, then z[r][j] = slope * sum_i y_c[i] * w[net[r]][i][j]: each
   product in T, summed over i ascending in double, rounded once to T, times slope in T (the
   torch module's _clamp, ordered_matvec and slope product, bit for bit). net NULL: row r uses
   network r. z receives the pre-activation; the sigmoid stays in torch (its exp is torch's). */
void sigmoid_drive_f32(const float *y, const float *inputs, const float *w, const int64_t *net, float *z,
                       int64_t rows, int64_t n, int64_t n_in, int64_t n_bias, float slope, int threads);
void sigmoid_drive_f64(const double *y, const double *inputs, const double *w, const int64_t *net, double *z,
                       int64_t rows, int64_t n, int64_t n_in, int64_t n_bias, double slope, int threads);
