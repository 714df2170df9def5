/* Entry points for the tests only (tests/evolution/kernel_entry_points.py): built into a library of their own
   when a test asks, so production builds do not compile them. */
#ifndef SNN_NEAT_TEST_ENTRY_POINTS_H
#define SNN_NEAT_TEST_ENTRY_POINTS_H

#include <stdint.h>

#include "breed.h" /* breed_params, gene_set */

/* distances' rows and output: rows_a [R, Ka] of a, rows_b [R, Kb] of b (flat row indices),
   out [R, Ka, Kb]. */
typedef struct {
    const int64_t *rows_a;
    int64_t Ka;
    const int64_t *rows_b;
    int64_t Kb;
    int64_t R;
    int64_t NN;
    int64_t W;
    double *out;
    int threads;
} distances_io;

/* Compatibility distances between rows of two gene bitset sets (cfg's coefficients), with the
   code breed.c's species assignment uses (gene_distance.h). */
void distances_f32(const breed_params *cfg, const gene_set *a, const gene_set *b, const distances_io *io);
void distances_f64(const breed_params *cfg, const gene_set *a, const gene_set *b, const distances_io *io);
/* The normals at counters c0, c0 + 2, ... of a stream (box_muller.h's normal_at). */
void normals_check(uint64_t key, uint64_t c0, int64_t n, double *out);

#endif
