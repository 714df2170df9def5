/* Updates of recurrent sigmoid networks (see recurrent_sigmoid.h). Built with -ffp-contract=off:
   every product is rounded before it is added, as torch does; the sigmoid is portable_math.h's,
   the torch module's own. */
#include "recurrent_sigmoid.h"

#include <string.h>

#include "portable_math.h"

/* `updates` updates of one network's values y[0..n) in place (inputs x, weights W), scratch yc
   and acc of n each: also what evolution/kernels/csrc/episodes.c runs per row. */
#define DEFINE_UPDATE(NAME, T)                                                                 \
static inline void NAME##_row(T *y, const T *x, const T *W, int64_t n, int64_t n_in, int64_t n_bias, \
                              T slope, int64_t updates, T *yc, double *acc) {                  \
    for (int64_t u = 0; u < updates; ++u) {                                                    \
        for (int64_t i = 0; i < n; ++i) yc[i] = i < n_in ? x[i] : i < n_in + n_bias ? (T)1 : y[i]; \
        for (int64_t j = 0; j < n; ++j) acc[j] = (double)(yc[0] * W[j]);                       \
        for (int64_t i = 1; i < n; ++i)                                                        \
            for (int64_t j = 0; j < n; ++j) acc[j] += (double)(yc[i] * W[i * n + j]);          \
        for (int64_t j = 0; j < n; ++j)                                                        \
            y[j] = j < n_in ? x[j] : j < n_in + n_bias ? (T)1 : (T)pm_sigmoid((double)(slope * (T)acc[j])); \
    }                                                                                          \
}                                                                                              \
void NAME(const T *y, const T *inputs, const T *w, const int64_t *net, T *out, int64_t rows,   \
          int64_t n, int64_t n_in, int64_t n_bias, T slope, int64_t updates, int threads) {    \
    _Pragma("omp parallel for num_threads(threads) schedule(static)")                         \
    for (int64_t r = 0; r < rows; ++r) {                                                       \
        T yc[n];                                                                               \
        double acc[n];                                                                         \
        memcpy(out + r * n, y + r * n, (size_t)n * sizeof(T));                                 \
        NAME##_row(out + r * n, inputs + r * n_in, w + (net ? net[r] : r) * n * n, n, n_in, n_bias, slope, \
                   updates, yc, acc);                                                          \
    }                                                                                          \
}
DEFINE_UPDATE(sigmoid_update_f32, float)
DEFINE_UPDATE(sigmoid_update_f64, double)
