/* The compatibility distance of two genomes from their gene bitsets (breed.c's species
   assignment, and the tests' distances): excess, disjoint and matching genes by popcounts, the
   weight term summed in double over the matching genes, the sigma term. */
#ifndef SNN_NEAT_GENE_DISTANCE_H
#define SNN_NEAT_GENE_DISTANCE_H

#include <math.h>
#include <stdint.h>

/* Bits 0 .. t % 64 of a word (t >= 0): the slots <= t within t's word. */
static inline uint64_t upto_mask(int64_t t) { return ~0ULL >> (63 - t % 64); }
/* The compatibility distance's structural term from gene counts: na, nb genes, a_upto of a's
   genes at slots <= b's highest, b_upto of b's at slots <= a's highest, match in both. */
static inline double structure_term(double na, double nb, int64_t a_upto, int64_t b_upto, int64_t match,
                                    const double *coef) {
    const double excess = (na - (double)a_upto) + (nb - (double)b_upto);
    const double disjoint = na + nb - 2.0 * (double)match - excess;
    const double n_max = na > nb ? na : nb;
    const double norm = n_max >= coef[4] ? n_max : 1.0;
    return coef[0] * excess / norm + coef[1] * disjoint / norm;
}
#define DEFINE_GENE_DISTANCE(T, SFX)                                                              \
/* map: the weight and sigma row of each bitset row (NULL: the same row). */                     \
typedef struct { const uint64_t *bits; const int64_t *before, *cnt, *top; const T *w, *sig; const int64_t *map; } genes_##SFX; \
/* The terms of the compatibility distance of row ra of set a and row rb of set b without the  \
   weights: structure (excess and disjoint) and sigma, and the matching genes. */               \
typedef struct { double structure, sigma; int64_t match; } terms_##SFX;                          \
static inline terms_##SFX pair_terms_##SFX(genes_##SFX a, int64_t ra, genes_##SFX b, int64_t rb,  \
                                           int64_t W, const double *coef) {                      \
    const uint64_t *A = a.bits + ra * W, *B = b.bits + rb * W;                                    \
    const int64_t ta = a.top[ra], tb = b.top[rb];                                                 \
    int64_t match = 0;                                                                            \
    for (int64_t k = 0; k < W; ++k) match += __builtin_popcountll(A[k] & B[k]);                   \
    /* genes of A at slots <= tb, of B at slots <= ta: whole words before, then a mask */         \
    const int64_t a_upto = tb < 0 ? 0 : a.before[ra * W + tb / 64] + __builtin_popcountll(A[tb / 64] & upto_mask(tb));\
    const int64_t b_upto = ta < 0 ? 0 : b.before[rb * W + ta / 64] + __builtin_popcountll(B[ta / 64] & upto_mask(ta));\
    const int64_t wra = a.map ? a.map[ra] : ra, wrb = b.map ? b.map[rb] : rb;                      \
    terms_##SFX t = {structure_term((double)a.cnt[ra], (double)b.cnt[rb], a_upto, b_upto, match, coef),\
                     coef[3] * fabs((double)a.sig[wra] - (double)b.sig[wrb]), match};             \
    return t;                                                                                     \
}                                                                                                 \
/* The whole distance from its terms: the mean weight difference of the matching genes added. */\
static inline double pair_full_##SFX(genes_##SFX a, int64_t ra, genes_##SFX b, int64_t rb,      \
                                     int64_t NN, int64_t W, const double *coef, terms_##SFX t) { \
    const uint64_t *A = a.bits + ra * W, *B = b.bits + rb * W;                                    \
    const int64_t wra = a.map ? a.map[ra] : ra, wrb = b.map ? b.map[rb] : rb;                      \
    double wdiff = 0.0;                                                                           \
    const T *wa = a.w + wra * NN, *wb = b.w + wrb * NN;                                           \
    for (int64_t k = 0; k < W; ++k)                                                               \
        for (uint64_t both = A[k] & B[k]; both; both &= both - 1) {                               \
            const int64_t s = k * 64 + __builtin_ctzll(both);                                     \
            wdiff += fabs((double)wa[s] - (double)wb[s]);                                         \
        }                                                                                         \
    const double w_mean = t.match > 0 ? wdiff / (double)t.match : 0.0;                            \
    return t.structure + coef[2] * w_mean + t.sigma;                                              \
}                                                                                                 \
/* The compatibility distance; or, when the terms without weights already reach `bound`, that  \
   partial sum (>= bound, and <= the distance: the weight term is >= 0 and rounded addition is \
   monotone), skipping the weight term. */                                                     \
static inline double pair_dist_##SFX(genes_##SFX a, int64_t ra, genes_##SFX b, int64_t rb,      \
                                     int64_t NN, int64_t W, const double *coef, double bound) { \
    const terms_##SFX t = pair_terms_##SFX(a, ra, b, rb, W, coef);                                \
    const double partial = t.structure + t.sigma;                                                 \
    return partial >= bound ? partial : pair_full_##SFX(a, ra, b, rb, NN, W, coef, t);            \
}
DEFINE_GENE_DISTANCE(float, f32)
DEFINE_GENE_DISTANCE(double, f64)

#endif
