/* Entry points for the tests only (see kernel_entry_points.h): the code they reach is the
   production kernels' own, from the shared headers. */
#include "kernel_entry_points.h"

#include <math.h>
#include <stdint.h>

#include "box_muller.h"
#include "gene_distance.h"

#define DEFINE_DISTANCES(T, SFX)                                                                  \
/* Distances between genome rows a[r, i] and b[r, j] (rows index the sets' flat arrays). */     \
void distances_##SFX(const breed_params *cfg, const gene_set *sa, const gene_set *sb,            \
                     const distances_io *io) {                                                    \
    const genes_##SFX a = {sa->bits, sa->before, sa->count, sa->top, (const T *)sa->weight,       \
                           (const T *)sa->sigma, sa->map};                                         \
    const genes_##SFX b = {sb->bits, sb->before, sb->count, sb->top, (const T *)sb->weight,       \
                           (const T *)sb->sigma, sb->map};                                         \
    const int64_t *rows_a = io->rows_a, *rows_b = io->rows_b, Ka = io->Ka, Kb = io->Kb;           \
    const int64_t R = io->R, NN = io->NN, W = io->W;                                              \
    double *out = io->out;                                                                        \
    _Pragma("omp parallel for schedule(static) num_threads(io->threads)")                        \
    for (int64_t q = 0; q < R * Ka; ++q) {                                                        \
        const int64_t r = q / Ka;                                                                 \
        for (int64_t jb = 0; jb < Kb; ++jb)                                                       \
            out[q * Kb + jb] = pair_dist_##SFX(a, rows_a[q], b, rows_b[r * Kb + jb], NN, W, cfg->coef, INFINITY); \
    }                                                                                             \
}
DEFINE_DISTANCES(float, f32)
DEFINE_DISTANCES(double, f64)

/* Normals at counters c0, c0 + 2, ... of a stream. */
void normals_check(uint64_t key, uint64_t c0, int64_t n, double *out) {
    for (int64_t k = 0; k < n; ++k) out[k] = normal_at(key, c0 + 2 * (uint64_t)k);
}
