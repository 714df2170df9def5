/* The breeding step and speciation as C kernels, for evolution.kernels.breed (which documents
   the arguments). Every function here is exported; snn_torch.kernels.build sets the ctypes signatures
   from these prototypes, and breed.c includes this header, so the compiler checks them. */
#ifndef SNN_NEAT_BREED_H
#define SNN_NEAT_BREED_H

#include <stdint.h>

/* One breeding step, a run at a time: crossover, add-node with the run's node registry,
   add-connection, weight, sigma and enabled mutations; the children's gene bitsets; with the
   representatives (r_*), each child's closest one (speciate's first step). pm, cm: the parents'
   and children's mutation_num ([NEATC]), or NULL where not carried; with cm, the closest
   representative goes by the children's mutation_num. split_first_bias: the first bias node for
   [NEATC]'s choice of the gene to split (node_add_neatc), or -1 for any enabled gene. */
void breed_f32(const float *pw, const uint8_t *pc, const uint8_t *pe, const uint8_t *pn, const float *ps,
               const int64_t *a_idx, const int64_t *b_idx, const uint8_t *do_cross, const uint8_t *active,
               float *cw, uint8_t *cc, uint8_t *ce, uint8_t *cn, float *cs, int64_t *src, int64_t *dst,
               uint8_t *request, const int64_t *keys, const int64_t *base, const int64_t *blocks, int64_t R,
               int64_t P, int64_t N, double inherit_disabled, double node_add_prob, int64_t *new_node,
               uint8_t *granted, int64_t first_output, int feed_forward, int per_gene, double conn_add_prob,
               double w_mean, double w_stdev, double w_min, double w_max, double w_rate, double w_rate_sum,
               double w_replace, double w_power, double s_rate, double s_power, double s_min, double s_max,
               double toggle_rate, const uint8_t *reserved, int64_t first_hidden, const int64_t *dest_runs,
               uint64_t *gbits, int64_t *gbefore, int64_t *gcount, int64_t *gtop, const int64_t *gmap,
               const uint64_t *r_bits, const int64_t *r_pre, const int64_t *r_cnt, const int64_t *r_top,
               const float *r_w, const float *r_sig, const uint8_t *r_alive, int64_t S, const double *coef,
               double thr, int64_t *nearest, int exclusive, int neatc, int recur_split, int one_on,
               double one_prob, double re_prob, double clone_link_prob, int64_t conn_tries,
               const int64_t *r_ident, int w_uniform, int shared_link, const float *pm, float *cm,
               int64_t split_first_bias, int threads);
void breed_f64(const double *pw, const uint8_t *pc, const uint8_t *pe, const uint8_t *pn, const double *ps,
               const int64_t *a_idx, const int64_t *b_idx, const uint8_t *do_cross, const uint8_t *active,
               double *cw, uint8_t *cc, uint8_t *ce, uint8_t *cn, double *cs, int64_t *src, int64_t *dst,
               uint8_t *request, const int64_t *keys, const int64_t *base, const int64_t *blocks, int64_t R,
               int64_t P, int64_t N, double inherit_disabled, double node_add_prob, int64_t *new_node,
               uint8_t *granted, int64_t first_output, int feed_forward, int per_gene, double conn_add_prob,
               double w_mean, double w_stdev, double w_min, double w_max, double w_rate, double w_rate_sum,
               double w_replace, double w_power, double s_rate, double s_power, double s_min, double s_max,
               double toggle_rate, const uint8_t *reserved, int64_t first_hidden, const int64_t *dest_runs,
               uint64_t *gbits, int64_t *gbefore, int64_t *gcount, int64_t *gtop, const int64_t *gmap,
               const uint64_t *r_bits, const int64_t *r_pre, const int64_t *r_cnt, const int64_t *r_top,
               const double *r_w, const double *r_sig, const uint8_t *r_alive, int64_t S, const double *coef,
               double thr, int64_t *nearest, int exclusive, int neatc, int recur_split, int one_on,
               double one_prob, double re_prob, double clone_link_prob, int64_t conn_tries,
               const int64_t *r_ident, int w_uniform, int shared_link, const double *pm, double *cm,
               int64_t split_first_bias, int threads);
/* speciate's assignment: the closest living representative within thr, else found a species. */
void assign_species_f32(const uint64_t *g_bits, const int64_t *g_pre, const int64_t *g_cnt,
                        const int64_t *g_top, const float *g_w, const float *g_sig, const int64_t *g_map,
                        const uint64_t *r_bits, const int64_t *r_pre, const int64_t *r_cnt,
                        const int64_t *r_top, const float *r_w, const float *r_sig, const int64_t *r_map,
                        const uint8_t *alive, int64_t R, int64_t P, int64_t S, int64_t NN, int64_t W,
                        const double *coef, double thr, int64_t *species, int64_t *founded,
                        int64_t *n_founded, uint8_t *taken, const int64_t *nearest,
                        const int64_t *r_ident, int threads);
void assign_species_f64(const uint64_t *g_bits, const int64_t *g_pre, const int64_t *g_cnt,
                        const int64_t *g_top, const double *g_w, const double *g_sig, const int64_t *g_map,
                        const uint64_t *r_bits, const int64_t *r_pre, const int64_t *r_cnt,
                        const int64_t *r_top, const double *r_w, const double *r_sig, const int64_t *r_map,
                        const uint8_t *alive, int64_t R, int64_t P, int64_t S, int64_t NN, int64_t W,
                        const double *coef, double thr, int64_t *species, int64_t *founded,
                        int64_t *n_founded, uint8_t *taken, const int64_t *nearest,
                        const int64_t *r_ident, int threads);
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
