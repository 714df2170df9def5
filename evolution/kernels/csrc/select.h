/* Parent selection and species representatives as C kernels, for evolution.kernels.select
   (which documents the arguments). Every function here is exported; snn_torch.kernels.build sets the
   ctypes signatures from these prototypes, and select.c includes this header. */
#ifndef SNN_NEAT_SELECT_H
#define SNN_NEAT_SELECT_H

#include <stdint.h>

/* What the selection kernels take from NEATConfig, built once per call by
   evolution.kernels.select.select_params (the names there in brackets). */
typedef struct {
    double survival;             /* survival_threshold */
    int survival_neatc;
    int64_t elitism;
    int64_t elitism_min;         /* elitism_min_species_size */
    double inter_prob;           /* interspecies_crossover_prob */
    double cross_prob;           /* crossover_prob */
    int64_t max_stagnation;
    int64_t species_elitism;
    double penalty;              /* stagnant_fitness_factor */
    int64_t obliterate_interval;
    int64_t obliterate_min_age;
    int64_t pop_stagnation;      /* population_stagnation */
    int64_t clock_before;        /* stagnation_clock_before */
} select_params;

/* select_parents' arrays: [R, P] genomes, [R, S] species slots, [R] runs. */
typedef struct {
    const double *fitness;       /* [R, P] */
    const int64_t *species;      /* [R, P] */
    const uint8_t *survivors;    /* [R, S] */
    const int64_t *counts;       /* [R, S] offspring per slot */
    const int64_t *keys;         /* [R] */
    const int64_t *base;         /* [R] first counter of the run's draws */
    const uint8_t *champions;    /* [R] delta coding's runs, or NULL */
    int64_t R;
    int64_t P;
    int64_t S;
    int64_t *first;              /* [R, P] out */
    int64_t *second;             /* [R, P] out */
    uint8_t *do_cross;           /* [R, P] out */
    uint8_t *elite;              /* [R, P] out */
    int threads;
} select_parents_io;

/* species_offspring's arrays: the slots' records in ([R, S], run_* [R]) and out. */
typedef struct {
    const double *fitness;       /* [R, P] */
    const int64_t *species;      /* [R, P] */
    const uint8_t *alive;
    const double *best_in;
    const int64_t *last_in;
    const int64_t *created;
    const uint8_t *obl_in;
    const double *run_best_in;
    const int64_t *run_stale_in;
    int64_t R;
    int64_t P;
    int64_t S;
    int64_t generation;
    double *best_out;
    int64_t *last_out;
    uint8_t *obl_out;
    double *run_best_out;
    int64_t *run_stale_out;
    uint8_t *survivors;
    int64_t *counts;
    uint8_t *delta;
    int threads;
} offspring_io;

/* choose_representatives' arrays; weight, sigma, rep_weight, rep_sigma of the suffix's type
   (float for _f32, double for _f64). */
typedef struct {
    const int64_t *species;      /* [R, P] */
    const uint8_t *conn;         /* genomes [*, P, NN] */
    const void *weight;
    const void *sigma;
    const int64_t *runs;         /* [R] the genomes' runs, or NULL: run r */
    const int64_t *keys;
    const int64_t *base;
    int64_t R;
    int64_t P;
    int64_t S;
    int64_t NN;
    uint8_t *alive;              /* [R, S] out */
    uint8_t *rep_conn;           /* [R, S, NN] out */
    void *rep_weight;
    void *rep_sigma;
    int threads;
} reps_io;

/* reproduce's selection: the parents of each child, crossover or not, the elites. */
void select_parents(const select_params *cfg, const select_parents_io *io);
/* speciate's representatives: each species' member with the highest draw, its genes copied. */
void choose_representatives_f32(const reps_io *io);
void choose_representatives_f64(const reps_io *io);
/* reproduce's species_offspring: species records, obliteration, survivors, offspring, the run's record. */
void species_offspring(const select_params *cfg, const offspring_io *io);

#endif
