/* The C kernel of snn_torch.PopulationRecurrentSigmoid: synchronous updates of many recurrent
   sigmoid networks. Every function here is exported; snn_torch.kernels.build reads these prototypes to
   declare the ctypes signatures. */
#include <stdint.h>

/* For rows r of node values y[r][0..n), `updates` updates: clamp nodes [0, n_in) to inputs[r] and
   nodes [n_in, n_in + n_bias) to 1, z[j] = slope * sum_i y_c[i] * w[net[r]][i][j] (each product in
   T, summed over i ascending in double, rounded once to T, times slope in T), then
   y[j] = sigmoid(z[j]) (portable_math.h: computed in double, rounded once to T) and the clamp
   again: the torch module's _clamp, ordered_matvec, slope product and ordered_sigmoid, bit for
   bit. net NULL: row r uses network r. out receives the values (it may be y). */
void sigmoid_update_f32(const float *y, const float *inputs, const float *w, const int64_t *net, float *out,
                        int64_t rows, int64_t n, int64_t n_in, int64_t n_bias, float slope, int64_t updates,
                        int threads);
void sigmoid_update_f64(const double *y, const double *inputs, const double *w, const int64_t *net, double *out,
                        int64_t rows, int64_t n, int64_t n_in, int64_t n_bias, double slope, int64_t updates,
                        int threads);
