/* The breeding step and speciation (see breed.h; evolution.kernels.breed documents them).

   A run at a time (threads share out the runs) and a child at a time within it, touching only
   the child's genes and evaluating only the draws it uses: a draw is addressed by its counter
   in the run's stream (counter_rng.h), so skipping the unused ones changes nothing. The
   arithmetic is the tensor reference's, in its order, without contraction (-ffp-contract=off),
   so the children are the same bit for bit (tests/evolution/test_breed_kernel.py). The
   functions of one dtype are in breed_impl.h, included below once per dtype. */
#include "breed.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "box_muller.h"
#include "counter_rng.h"
#include "gene_distance.h"

/* The draw blocks of a step, in evolution.kernels.breed._BLOCKS's order. */
enum { B_FROM_OTHER, B_STAYS, B_SIGMA_PICK, B_NODE_WANT, B_NODE_PICK, B_CONN_WANT, B_CONN_PICK, B_CONN_INIT,
       B_W_GENOME, B_W_U, B_W_NOISE, B_S_WANT, B_S_NOISE, B_TOGGLE,
       B_ONE_WANT, B_ONE_PICK, B_REENABLE, /* only when toggle_one: breed_kernel._TOGGLE_ONE_BLOCKS */
       N_BLOCKS };
#define MAX_ROWS 64 /* the feed-forward closure: N <= 64 rows of one 64-bit word */

/* The bytes (0/1) of mask[0..n) as W = ceil(n / 64) words of bits, branch-free: eight bytes to
   eight bits by one multiply. */
static inline void pack_bits(const uint8_t *mask, int64_t n, int64_t W, uint64_t *out) {
    for (int64_t k = 0; k < W; ++k) {
        uint64_t word = 0;
        const int64_t lo = k * 64, hi = lo + 64 < n ? lo + 64 : n;
        int64_t s = lo;
        for (; s + 8 <= hi; s += 8) {
            uint64_t x; memcpy(&x, mask + s, 8);
            word |= (((x & 0x0101010101010101ULL) * 0x0102040810204080ULL) >> 56) << (s - lo);
        }
        for (; s < hi; ++s) word |= (uint64_t)(mask[s] != 0) << (s - lo);
        out[k] = word;
    }
}
/* The set bits' positions, ascending; returns how many. */
static inline int64_t bits_to_slots(const uint64_t *bits, int64_t W, int32_t *out) {
    int64_t m = 0;
    for (int64_t k = 0; k < W; ++k)
        for (uint64_t x = bits[k]; x; x &= x - 1) out[m++] = (int32_t)(k * 64 + __builtin_ctzll(x));
    return m;
}
/* A bitset's genes in the words before each word, its count and its highest slot (-1: none). */
static inline void bits_summary(const uint64_t *bits, int64_t W, int64_t *before, int64_t *count, int64_t *top) {
    int64_t n = 0, t = -1;
    for (int64_t k = 0; k < W; ++k) {
        before[k] = n;
        n += __builtin_popcountll(bits[k]);
        if (bits[k]) t = k * 64 + 63 - __builtin_clzll(bits[k]);
    }
    *count = n; *top = t;
}
/* Position of the k-th set bit of x (k < popcount(x)). */
static inline int kth_bit(uint64_t x, int64_t k) {
    while (k-- > 0) x &= x - 1;
    return __builtin_ctzll(x);
}
#define MAX_SLOTS 4096 /* N <= 64 */
static inline int64_t pick_k(double u, int64_t n) {
    int64_t k = (int64_t)(u * (double)n);
    return k > n - 1 ? n - 1 : (k < 0 ? 0 : k);
}

/* [NEATC]'s random tries, from one uniform u: the first of `tries` draws, each good with
   good / all, is the k-th good one (returned) or none of them is (-1). mutate.py's _tries_law, op by op. */
static int64_t tries_law(double u, int64_t good, int64_t all, int64_t tries) {
    const double miss = 1.0 - (double)good / (double)(all > 1 ? all : 1);
    double fail = 1.0;
    for (int64_t t = 0; t < tries; ++t) fail = fail * miss;
    if (good <= 0 || u < fail) return -1;
    const int64_t k = (int64_t)((u - fail) / (1.0 - fail) * (double)good);
    return k > good - 1 ? good - 1 : (k < 0 ? 0 : k);
}

/* [NEATC] Genome::mutate_add_node's gene to split, -1 for none: mutate.py's _pick_split_neatc, op by
   op. 20 random tries (the exact law of the first good one, from the one uniform u), a good gene
   being enabled and not from a bias node (rows [first_bias, first_output)). */
static int64_t split_neatc(const uint8_t *c, const uint8_t *e, int64_t N, double u, int64_t first_bias,
                           int64_t first_output) {
    const int64_t NN = N * N;
#define SPLITTABLE(s) (c[s] && e[s] && !((s) / N >= first_bias && (s) / N < first_output))
    int64_t n = 0, m = 0;
    for (int64_t s = 0; s < NN; ++s) {
        n += c[s] != 0;
        m += SPLITTABLE(s);
    }
    int64_t k = tries_law(u, m, n, 20);
    for (int64_t s = 0; k >= 0 && s < NN; ++s)
        if (SPLITTABLE(s) && k-- == 0) return s;
#undef SPLITTABLE
    return -1;
}

#define VECTOR_REPS 3 /* species assignment: vector loops over at least this many representatives */
/* what a phase-2 job is for (JOB_CONN_LATER: a link the run's child of an earlier job added first) */
enum { JOB_CONN, JOB_CONN_LATER, JOB_PERTURB, JOB_REPLACE, JOB_SIGMA, JOB_NC_PERTURB, JOB_NC_REPLACE };
#define PASTE_(x, y) x##y
#define PASTE(x, y) PASTE_(x, y)

/* phase1_, phase2_, nearest_reps_, breed_ and assign_species_ for each dtype */
#define T float
#define SFX f32
#include "breed_impl.h"
#undef T
#undef SFX

#define T double
#define SFX f64
#include "breed_impl.h"
#undef T
#undef SFX

/* Gene bitsets, counts and highest occupied slot (-1: none) of rows conn[M, NN] (rows: of those rows).
   alive (NULL: all): rows not alive are given no genes without reading them. */
void gene_bits(const uint8_t *conn, const int64_t *rows, const uint8_t *alive, int64_t M, int64_t NN, int64_t W,
               uint64_t *bits, int64_t *before, int64_t *count, int64_t *top, int threads) {
    _Pragma("omp parallel for schedule(static) num_threads(threads)")
    for (int64_t m = 0; m < M; ++m) {
        if (alive && !alive[m]) memset(bits + m * W, 0, W * sizeof(uint64_t));
        else pack_bits(conn + (rows ? rows[m] : m) * NN, NN, W, bits + m * W);
        bits_summary(bits + m * W, W, before + m * W, count + m, top + m);
    }
}
/* speciate's bookkeeping for the species assign_species_ founded: run r's k-th new slot
   founded[r * P + k] (k < n_founded[r]) lives, has no best fitness yet, was created and last
   improved in this generation, and takes the run's next species number. State [R, S]. */
int found_species(const int64_t *founded, const int64_t *n_founded, int64_t R, int64_t P, int64_t S,
                  int64_t generation, uint8_t *alive, double *best, int64_t *last, int64_t *created,
                  int64_t *ident, int64_t *next_id) {
    for (int64_t r = 0; r < R; ++r) /* -1, nothing written: a slot beyond the state */
        for (int64_t k = 0; k < n_founded[r]; ++k) if (founded[r * P + k] < 0 || founded[r * P + k] >= S) return -1;
    for (int64_t r = 0; r < R; ++r) {
        for (int64_t k = 0; k < n_founded[r]; ++k) {
            const int64_t q = r * S + founded[r * P + k];
            alive[q] = 1; best[q] = -INFINITY; last[q] = generation; created[q] = generation;
            ident[q] = next_id[r] + k;
        }
        next_id[r] += n_founded[r];
    }
    return 0;
}
/* dst rows idx[0..n) = src rows 0..n, whole rows of row_bytes; -1 if an index is outside [0, rows). */
int put_rows(char *dst, const char *src, const int64_t *idx, int64_t n, int64_t rows, int64_t row_bytes) {
    for (int64_t k = 0; k < n; ++k) if (idx[k] < 0 || idx[k] >= rows) return -1;
    for (int64_t k = 0; k < n; ++k) memcpy(dst + idx[k] * row_bytes, src + k * row_bytes, row_bytes);
    return 0;
}
/* Node slots touched by the genes of the living rows of bits[R * S, W] (N nodes): out[R, N]. */
void touched_nodes(const uint64_t *bits, const uint8_t *alive, int64_t R, int64_t S, int64_t W, int64_t N,
                   uint8_t *out) {
    memset(out, 0, R * N);
    for (int64_t r = 0; r < R; ++r) {
        uint64_t any[MAX_SLOTS / 64] = {0}; /* the run's living genes, all representatives at once */
        for (int64_t s = 0; s < S; ++s)
            if (alive[r * S + s])
                for (int64_t k = 0; k < W; ++k) any[k] |= bits[(r * S + s) * W + k];
        uint8_t *o = out + r * N;
        for (int64_t k = 0; k < W; ++k)
            for (uint64_t x = any[k]; x; x &= x - 1) {
                const int64_t slot = k * 64 + __builtin_ctzll(x);
                o[slot / N] = 1; o[slot % N] = 1;
            }
    }
}
