/* The breeding step and speciation as C kernels, for evolution.kernels.breed (which documents
   the arguments). Every function here is exported; snn_torch.kernels.build sets the ctypes signatures
   from these prototypes, and breed.c includes this header, so the compiler checks them. */
#ifndef SNN_NEAT_BREED_H
#define SNN_NEAT_BREED_H

#include <stdint.h>

/* What the breeding and speciation kernels take from NEATConfig, built by
   evolution.kernels.breed.breed_params (the config's names in brackets). */
typedef struct {
    double inherit_disabled;     /* disabled_inherit_prob */
    double node_add_prob;
    int64_t first_output;
    int64_t first_hidden;
    int feed_forward;
    int per_gene;                /* weight_mutate_per_gene */
    double conn_add_prob;
    double w_mean;               /* weight_init_mean */
    double w_stdev;              /* weight_init_stdev */
    double w_min;                /* weight_min_value */
    double w_max;                /* weight_max_value */
    double w_rate;               /* weight_mutate_rate */
    double w_rate_sum;           /* weight_mutate_rate + weight_replace_rate */
    double w_replace;            /* weight_replace_rate */
    double w_power;              /* weight_mutate_power */
    double s_rate;               /* sigma_mutate_rate */
    double s_power;              /* sigma_mutate_power */
    double s_min;                /* sigma_min_value */
    double s_max;                /* sigma_max_value */
    double toggle_rate;          /* enabled_mutate_rate */
    int exclusive;               /* mutation_exclusive */
    int neatc;                   /* weight_mutate_neatc */
    int recur_split;             /* conn_add_recurrence */
    int one_on;                  /* mutate_toggle_one runs (breed.toggles_one) */
    double one_prob;             /* toggle_enable_prob */
    double re_prob;              /* gene_reenable_prob */
    double clone_link_prob;      /* a delta-coding clone's new link (neat121.CLONE_LINK_PROB, or 0) */
    int64_t conn_tries;          /* conn_add_tries */
    int w_uniform;               /* weight_init_uniform */
    int shared_link;             /* conn_add_shared_weight */
    int64_t split_first_bias;    /* node_add_neatc: the first bias node (num_inputs), else -1 */
    double coef[5];              /* compatibility_{excess, disjoint, weight, sigma}_coefficient,
                                    compatibility_normalize_min_genes */
    double thr;                  /* compatibility_threshold */
} breed_params;

/* Gene bitsets of M genome rows (evolution.kernels.breed.GeneBits) and the weights and sigmas
   the distance reads beside them; weight and sigma of the entry point's type (float for _f32,
   double for _f64). */
typedef struct {
    const uint64_t *bits;        /* [M, W] */
    const int64_t *before;       /* [M, W] genes in the words before */
    const int64_t *count;        /* [M] */
    const int64_t *top;          /* [M] highest slot, -1: none */
    const void *weight;          /* [*, NN] */
    const void *sigma;           /* [*] */
    const int64_t *map;          /* [M] the weight and sigma row of each bitset row, or NULL: the same */
} gene_set;

/* breed's arrays: parents p* [*, P, ...] (rows a_idx, b_idx), children c* [R, P, ...], the run's
   draws, the node registry, the children's bitsets g*; with reps, each child's closest
   representative (speciate's first step). pw, ps, pm, cw, cs, cm of the entry point's type;
   pm, cm: mutation_num ([NEATC]), or NULL where not carried (with cm, the closest
   representative goes by the children's mutation_num). */
typedef struct {
    const void *pw;
    const uint8_t *pc;
    const uint8_t *pe;
    const uint8_t *pn;
    const void *ps;
    const void *pm;
    const int64_t *a_idx;        /* [R, P] the parents' rows */
    const int64_t *b_idx;
    const uint8_t *do_cross;     /* [R, P] 1 cross, 2 average the matching weights */
    const uint8_t *active;       /* [R, P] mutate; bits 2 severe, 4 recurrent link, 8 a clone */
    void *cw;
    uint8_t *cc;
    uint8_t *ce;
    uint8_t *cn;
    void *cs;
    void *cm;
    int64_t *src;                /* [R, P] the split gene's ends */
    int64_t *dst;
    uint8_t *request;            /* [R, P] a split asked for */
    int64_t *new_node;           /* [R, P] its node */
    uint8_t *granted;            /* [R, P] a free slot found */
    const int64_t *keys;         /* [R] */
    const int64_t *base;         /* [R] the step's first counter */
    const int64_t *blocks;       /* the draw blocks' first counters (breed_blocks) */
    const uint8_t *reserved;     /* [R, N] node slots not to give a new node */
    const int64_t *dest_runs;    /* [R] in place: the children overwrite these runs, or NULL */
    int64_t R;
    int64_t P;
    int64_t N;
    uint64_t *gbits;             /* [R * P, W] the children's bitsets out */
    int64_t *gbefore;
    int64_t *gcount;
    int64_t *gtop;
    const int64_t *gmap;         /* the children's weight rows, or NULL */
    const gene_set *reps;        /* [R, S] the representatives, or NULL: no closest search */
    const uint8_t *r_alive;      /* [R, S] */
    const int64_t *r_ident;      /* [R, S] species numbers: [NEATC]'s first fit, or NULL: closest */
    int64_t S;
    int64_t *nearest;            /* [R, P] out, -1: none within the threshold */
    int threads;
} breed_io;

/* assign_species' arrays: living slots alive [R, S]; species [R, P], founded [R, P] and
   n_founded [R] out; taken [R, S + P] scratch; nearest [R, P] (found by breed) or NULL. */
typedef struct {
    const uint8_t *alive;
    int64_t R;
    int64_t P;
    int64_t S;
    int64_t NN;
    int64_t W;
    int64_t *species;
    int64_t *founded;
    int64_t *n_founded;
    uint8_t *taken;
    const int64_t *nearest;
    const int64_t *r_ident;      /* [R, S] species numbers: [NEATC]'s first fit, or NULL: closest */
    int threads;
} assign_io;

/* One breeding step, a run at a time: crossover, add-node with the run's node registry,
   add-connection, weight, sigma and enabled mutations; the children's gene bitsets; with the
   representatives, each child's closest one (speciate's first step). */
void breed_f32(const breed_params *cfg, const breed_io *io);
void breed_f64(const breed_params *cfg, const breed_io *io);
/* speciate's assignment: the closest living representative within thr, else found a species. */
void assign_species_f32(const breed_params *cfg, const gene_set *genes, const gene_set *reps,
                        const assign_io *io);
void assign_species_f64(const breed_params *cfg, const gene_set *genes, const gene_set *reps,
                        const assign_io *io);
/* Gene bitsets, gene counts before each word, counts and highest slot of rows conn[M, NN]. */
void gene_bits(const uint8_t *conn, const int64_t *rows, const uint8_t *alive, int64_t M, int64_t NN,
               int64_t W, uint64_t *bits, int64_t *before, int64_t *count, int64_t *top, int threads);
/* speciate's bookkeeping for the founded species; -1 (nothing written) if a slot is >= S. */
int found_species(const int64_t *founded, const int64_t *n_founded, int64_t R, int64_t P, int64_t S,
                  int64_t generation, uint8_t *alive, double *best, int64_t *last, int64_t *created,
                  int64_t *ident, int64_t *next_id);
/* dst rows idx[0..n) = src rows, whole rows by memcpy; -1 if an index is outside [0, rows). */
int put_rows(char *dst, const char *src, const int64_t *idx, int64_t n, int64_t rows, int64_t row_bytes);
/* Node slots touched by the genes of the living representatives: out[R, N]. */
void touched_nodes(const uint64_t *bits, const uint8_t *alive, int64_t R, int64_t S, int64_t W, int64_t N,
                   uint8_t *out);

#endif
