/* Entry points for the tests only (see kernel_entry_points.h): the code they reach is the
   production kernels' own, from the shared headers. */
#include "kernel_entry_points.h"

#include <math.h>
#include <stdint.h>

#include "box_muller.h"
#include "gene_distance.h"

#define DEFINE_DISTANCES(T, SFX)                                                                  \
/* Distances between genome rows a[r, i] and b[r, j] (rows index the sets' flat arrays). */     \
void distances_##SFX(const uint64_t *bits_a, const int64_t *pre_a, const int64_t *cnt_a, const int64_t *top_a,\
                     const T *w_a, const T *sig_a, const int64_t *map_a, const int64_t *rows_a, int64_t Ka,\
                     const uint64_t *bits_b, const int64_t *pre_b, const int64_t *cnt_b, const int64_t *top_b,\
                     const T *w_b, const T *sig_b, const int64_t *map_b, const int64_t *rows_b, int64_t Kb,\
                     int64_t R, int64_t NN, int64_t W, const double *coef, double *out, int threads) { \
    const genes_##SFX a = {bits_a, pre_a, cnt_a, top_a, w_a, sig_a, map_a};                       \
    const genes_##SFX b = {bits_b, pre_b, cnt_b, top_b, w_b, sig_b, map_b};                       \
    _Pragma("omp parallel for schedule(static) num_threads(threads)")                            \
    for (int64_t q = 0; q < R * Ka; ++q) {                                                        \
        const int64_t r = q / Ka;                                                                 \
        for (int64_t jb = 0; jb < Kb; ++jb)                                                       \
            out[q * Kb + jb] = pair_dist_##SFX(a, rows_a[q], b, rows_b[r * Kb + jb], NN, W, coef, INFINITY); \
    }                                                                                             \
}
DEFINE_DISTANCES(float, f32)
DEFINE_DISTANCES(double, f64)

/* Normals at counters c0, c0 + 2, ... of a stream. */
void normals_check(uint64_t key, uint64_t c0, int64_t n, double *out) {
    for (int64_t k = 0; k < n; ++k) out[k] = normal_at(key, c0 + 2 * (uint64_t)k);
}
