/* Entry points for the tests only (tests/evolution/kernel_entry_points.py): built into a library of their own
   when a test asks, so production builds do not compile them. */
#ifndef SNN_NEAT_TEST_ENTRY_POINTS_H
#define SNN_NEAT_TEST_ENTRY_POINTS_H

#include <stdint.h>

/* Compatibility distances out[R, Ka, Kb] between rows of two gene bitset sets, with the code
   breed.c's species assignment uses (gene_distance.h). */
void distances_f32(const uint64_t *bits_a, const int64_t *pre_a, const int64_t *cnt_a, const int64_t *top_a,
                   const float *w_a, const float *sig_a, const int64_t *map_a, const int64_t *rows_a,
                   int64_t Ka, const uint64_t *bits_b, const int64_t *pre_b, const int64_t *cnt_b,
                   const int64_t *top_b, const float *w_b, const float *sig_b, const int64_t *map_b,
                   const int64_t *rows_b, int64_t Kb, int64_t R, int64_t NN, int64_t W, const double *coef,
                   double *out, int threads);
void distances_f64(const uint64_t *bits_a, const int64_t *pre_a, const int64_t *cnt_a, const int64_t *top_a,
                   const double *w_a, const double *sig_a, const int64_t *map_a, const int64_t *rows_a,
                   int64_t Ka, const uint64_t *bits_b, const int64_t *pre_b, const int64_t *cnt_b,
                   const int64_t *top_b, const double *w_b, const double *sig_b, const int64_t *map_b,
                   const int64_t *rows_b, int64_t Kb, int64_t R, int64_t NN, int64_t W, const double *coef,
                   double *out, int threads);
/* The normals at counters c0, c0 + 2, ... of a stream (box_muller.h's normal_at). */
void normals_check(uint64_t key, uint64_t c0, int64_t n, double *out);

#endif
