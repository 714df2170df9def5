/* Clamp and slot-ordered weighted sum of recurrent sigmoid networks (see recurrent_sigmoid.h).
   Built with -ffp-contract=off: every product is rounded before it is added, as torch does. */
#include "recurrent_sigmoid.h"


#define DEFINE_DRIVE(NAME, T)                                                                  \
void NAME(const T *y, const T *inputs, const T *w, const int64_t *net, T *z, int64_t rows,      \
          int64_t n, int64_t n_in, int64_t n_bias, T slope, int threads) {                    \
    _Pragma("omp parallel for num_threads(threads) schedule(static)")                         \
    for (int64_t r = 0; r < rows; ++r) {                                                       \
        T yc[n];                                                                               \
        double acc[n];                                                                         \
        const T *yr = y + r * n, *W = w + (net ? net[r] : r) * n * n;                         \
        for (int64_t i = 0; i < n; ++i)                                                        \
            yc[i] = i < n_in ? inputs[r * n_in + i] : i < n_in + n_bias ? (T)1 : yr[i];        \
        for (int64_t j = 0; j < n; ++j) acc[j] = (double)(yc[0] * W[j]);                       \
        for (int64_t i = 1; i < n; ++i)                                                        \
            for (int64_t j = 0; j < n; ++j) acc[j] += (double)(yc[i] * W[i * n + j]);          \
        for (int64_t j = 0; j < n; ++j) z[r * n + j] = slope * (T)acc[j];                      \
    }                                                                                          \
}
DEFINE_DRIVE(sigmoid_drive_f32, float)
DEFINE_DRIVE(sigmoid_drive_f64, double)
