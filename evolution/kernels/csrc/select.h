/* Parent selection and species representatives as C kernels, for evolution.kernels.select
   (which documents the arguments). Every function here is exported; snn_torch.kernels.build sets the
   ctypes signatures from these prototypes, and select.c includes this header. */
#ifndef SNN_NEAT_SELECT_H
#define SNN_NEAT_SELECT_H

#include <stdint.h>

/* reproduce's selection: the parents of each child, crossover or not, the elites. */
void select_parents(const double *fitness, const int64_t *species, const uint8_t *survivors,
                    const int64_t *counts, const int64_t *keys, const int64_t *base, int64_t R, int64_t P,
                    int64_t S, double survival, int survival_neatc, int64_t elitism, int64_t elitism_min, double inter_prob,
                    double cross_prob, int64_t *first, int64_t *second, uint8_t *do_cross, uint8_t *elite,
                    const uint8_t *champions, int threads);
/* speciate's representatives: each species' member with the highest draw, its genes copied. */
void choose_representatives_f32(const int64_t *species, const uint8_t *conn, const float *weight,
                                const float *sigma, const int64_t *runs, const int64_t *keys,
                                const int64_t *base, int64_t R, int64_t P, int64_t S, int64_t NN,
                                uint8_t *alive, uint8_t *rep_conn, float *rep_weight, float *rep_sigma,
                                int threads);
void choose_representatives_f64(const int64_t *species, const uint8_t *conn, const double *weight,
                                const double *sigma, const int64_t *runs, const int64_t *keys,
                                const int64_t *base, int64_t R, int64_t P, int64_t S, int64_t NN,
                                uint8_t *alive, uint8_t *rep_conn, double *rep_weight, double *rep_sigma,
                                int threads);
/* reproduce's species_offspring: species records, obliteration, survivors, offspring, the run's record. */
void species_offspring(const double *fitness, const int64_t *species, const uint8_t *alive,
                       const double *best_in, const int64_t *last_in, const int64_t *created,
                       const uint8_t *obl_in, const double *run_best_in, const int64_t *run_stale_in,
                       int64_t R, int64_t P, int64_t S, int64_t generation, int64_t max_stagnation,
                       int64_t species_elitism, double penalty, int64_t obliterate_interval,
                       int64_t obliterate_min_age, int64_t pop_stagnation, int64_t clock_before,
                       double *best_out, int64_t *last_out, uint8_t *obl_out, double *run_best_out,
                       int64_t *run_stale_out, uint8_t *survivors, int64_t *counts, uint8_t *delta, int threads);

#endif
