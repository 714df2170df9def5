/* Updates of recurrent sigmoid networks (see recurrent_sigmoid.h). Built with -ffp-contract=off:
   every product is rounded before it is added, as torch does; the sigmoid is portable_math.h's,
   the torch module's own. */
#include "recurrent_sigmoid.h"

#include <string.h>

#include "portable_math.h"

#define DEFINE_UPDATE(NAME, T)                                                                 \
void NAME(const T *y, const T *inputs, const T *w, const int64_t *net, T *out, int64_t rows,   \
          int64_t n, int64_t n_in, int64_t n_bias, T slope, int64_t updates, int threads) {    \
    _Pragma("omp parallel for num_threads(threads) schedule(static)")                         \
    for (int64_t r = 0; r < rows; ++r) {                                                       \
        T yc[n], yr[n];                                                                        \
        double acc[n];                                                                         \
        const T *W = w + (net ? net[r] : r) * n * n, *x = inputs + r * n_in;                   \
        memcpy(yr, y + r * n, (size_t)n * sizeof(T));                                          \
        for (int64_t u = 0; u < updates; ++u) {                                                \
            for (int64_t i = 0; i < n; ++i) yc[i] = i < n_in ? x[i] : i < n_in + n_bias ? (T)1 : yr[i]; \
            for (int64_t j = 0; j < n; ++j) acc[j] = (double)(yc[0] * W[j]);                   \
            for (int64_t i = 1; i < n; ++i)                                                    \
                for (int64_t j = 0; j < n; ++j) acc[j] += (double)(yc[i] * W[i * n + j]);      \
            for (int64_t j = 0; j < n; ++j)                                                    \
                yr[j] = j < n_in ? x[j] : j < n_in + n_bias ? (T)1                             \
                                        : (T)pm_sigmoid((double)(slope * (T)acc[j]));          \
        }                                                                                      \
        memcpy(out + r * n, yr, (size_t)n * sizeof(T));                                        \
    }                                                                                          \
}
DEFINE_UPDATE(sigmoid_update_f32, float)
DEFINE_UPDATE(sigmoid_update_f64, double)
