/* The breeding step and speciation (see breed.h; evolution.kernels.breed documents them).

   A run at a time (threads share out the runs) and a child at a time within it, touching only
   the child's genes and evaluating only the draws it uses: a draw is addressed by its counter
   in the run's stream (counter_rng.h), so skipping the unused ones changes nothing. The
   arithmetic is the tensor reference's, in its order, without contraction (-ffp-contract=off),
   so the children are the same bit for bit (tests/evolution/test_breed_kernel.py). */
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
#define DEFINE_BREED(T, SFX)                                                                      \
static inline T clampT_##SFX(T x, T lo, T hi) { x = x < lo ? lo : x; return x > hi ? hi : x; }   \
/* Phase 1: crossover (or a copy of the first parent), then the add-node choice. */              \
static inline void phase1_##SFX(const T *pw, const uint8_t *pc, const uint8_t *pe, const uint8_t *pn, const T *ps,\
                  const int64_t *a_idx, const int64_t *b_idx, const uint8_t *do_cross,            \
                  const uint8_t *active, T *cw, uint8_t *cc, uint8_t *ce, uint8_t *cn, T *cs,     \
                  int64_t *src, int64_t *dst, uint8_t *request, const int64_t *keys,             \
                  const int64_t *base, const int64_t *blocks, int64_t R, int64_t P, int64_t N,   \
                  double inherit_disabled, double node_add_prob, int64_t idx0, int64_t row0,            \
                  int64_t row1, uint64_t *gbits, const T *pm, T *cm, int64_t split_first_bias,     \
                  int64_t first_output) {                                                         \
    const int64_t NN = N * N, W = (NN + 63) / 64;                                                 \
    for (int64_t row = row0; row < row1; ++row) {                                                   \
        const int64_t r = row / P, p = row % P, crow = row - row0; /* child arrays: the run's block */\
        const uint64_t key = (uint64_t)keys[r], b0 = (uint64_t)base[r];                          \
        /* parents: rows of pw (a_idx, b_idx indexed from row idx0) */                           \
        const int64_t a = a_idx[row - idx0], b = b_idx[row - idx0];                               \
        const T *fw = pw + a * NN, *ow = pw + b * NN;                                             \
        const uint8_t *fc = pc + a * NN, *fe = pe + a * NN, *oc = pc + b * NN, *oe = pe + b * NN; \
        T *w = cw + crow * NN; uint8_t *c = cc + crow * NN, *e = ce + crow * NN;                  \
        memcpy(c, fc, NN); memcpy(cn + crow * N, pn + a * N, N);                                  \
        memcpy(w, fw, NN * sizeof(T)); /* no gene: weight 0 in every genome */                    \
        /* mutation_num ([NEATC]), where carried: inherited as the weights are */                  \
        const T *fm = pm ? pm + a * NN : NULL, *om = pm ? pm + b * NN : NULL;                     \
        T *m = cm ? cm + crow * NN : NULL;                                                        \
        if (m) memcpy(m, fm, NN * sizeof(T));                                                     \
        uint64_t *bits = gbits + row * W; /* the child's genes: the first parent's */             \
        pack_bits(fc, NN, W, bits);                                                               \
        int32_t genes[MAX_SLOTS];                                                                 \
        if (do_cross[row]) {                                                                      \
            const uint64_t c_from = b0 + blocks[B_FROM_OTHER] + p * NN;                           \
            const uint64_t c_stay = b0 + blocks[B_STAYS] + p * NN;                                \
            memset(e, 0, NN);                                                                     \
            const int64_t n = bits_to_slots(bits, W, genes);                                      \
            double u_from[MAX_SLOTS], u_stay[MAX_SLOTS];                                          \
            _Pragma("omp simd")                                                                   \
            for (int64_t g = 0; g < n; ++g) {                                                     \
                u_from[g] = uniform01(key, c_from + genes[g]);                                    \
                u_stay[g] = uniform01(key, c_stay + genes[g]);                                    \
            }                                                                                     \
            const int avg = do_cross[row] == 2; /* [NEATC] mate_multipoint_avg */                 \
            for (int64_t g = 0; g < n; ++g) {                                                     \
                const int64_t s = genes[g];                                                       \
                const int matching = oc[s] != 0;                                                  \
                if (matching && avg) w[s] = (T)(fw[s] + ow[s]) / (T)2;                            \
                else if (matching && u_from[g] < 0.5) w[s] = ow[s];                               \
                if (m && matching && avg) m[s] = (T)(fm[s] + om[s]) / (T)2;                       \
                else if (m && matching && u_from[g] < 0.5) m[s] = om[s];                          \
                const int dip = !fe[s] || (matching && !oe[s]);                                   \
                e[s] = !(dip && u_stay[g] < inherit_disabled);                                    \
            }                                                                                     \
            cs[crow] = uniform01(key, b0 + blocks[B_SIGMA_PICK] + p) < 0.5 ? ps[b] : ps[a];       \
        } else {                                                                                  \
            memcpy(e, fe, NN); cs[crow] = ps[a];                                                  \
        }                                                                                         \
        request[row] = 0; src[row] = 0; dst[row] = 0;                                             \
        if (active[row] && !(active[row] & 8) && uniform01(key, b0 + blocks[B_NODE_WANT] + p) < node_add_prob\
            && split_first_bias >= 0) { /* [NEATC]'s choice */                                     \
            const int64_t s = split_neatc(c, e, N, uniform01(key, b0 + blocks[B_NODE_PICK] + p), split_first_bias,\
                                          first_output);                                          \
            if (s >= 0) { src[row] = s / N; dst[row] = s % N; request[row] = 1; }                 \
        } else if (active[row] && !(active[row] & 8) && uniform01(key, b0 + blocks[B_NODE_WANT] + p) < node_add_prob) {\
            uint64_t on[MAX_SLOTS / 64];                                                          \
            pack_bits(e, NN, W, on);                                                              \
            const int64_t n = bits_to_slots(on, W, genes);                                        \
            if (n > 0) {                                                                          \
                const int64_t s = genes[pick_k(uniform01(key, b0 + blocks[B_NODE_PICK] + p), n)]; \
                src[row] = s / N; dst[row] = s % N; request[row] = 1;                             \
            }                                                                                     \
        }                                                                                         \
    }                                                                                             \
}                                                                                                 \
/* Phase 2, in place: the granted splits, add-connection, weights, sigma, enabled flags. The    \
   normals are drawn for the whole run at once: pass 1 makes every decision and lists each     \
   normal's counter with what it is for (a job), pass 2 computes them in one vector loop (a    \
   child has a few genes, too few to fill a vector), pass 3 applies them child by child in the  \
   reference's order (a new connection's initial weight before the weight mutation). */       \
static inline void phase2_##SFX(T *cw, uint8_t *cc, uint8_t *ce, uint8_t *cn, T *cs, const int64_t *new_node,  \
                  const uint8_t *granted, const int64_t *src, const int64_t *dst,                 \
                  const uint8_t *active, const int64_t *keys, const int64_t *base,                \
                  const int64_t *blocks, int64_t R, int64_t P, int64_t N, int64_t first_output,   \
                  int feed_forward, int per_gene, double conn_add_prob, double w_mean,            \
                  double w_stdev, double w_min, double w_max, double w_rate, double w_rate_sum,   \
                  double w_replace, double w_power, double s_rate, double s_power, double s_min,  \
                  double s_max, double toggle_rate, int64_t row0, int64_t row1, uint64_t *gbits,  \
                  int64_t *gbefore, int64_t *gcount, int64_t *gtop, int exclusive,                \
                  double node_add_prob, int neatc, int recur_split, int one_on, double one_prob,   \
                  double re_prob, int64_t first_hidden, double clone_link_prob, int64_t conn_tries,\
                  int w_uniform, int shared_link, T *cm) {                                        \
    const int64_t NN = N * N, W = (NN + 63) / 64;                                                 \
    const T mean = (T)w_mean, stdev = (T)w_stdev, lo = (T)w_min, hi = (T)w_max, power = (T)w_power;\
    /* weight_init_uniform: [NP]'s bounds, mean +- 2 stdev within [min, max], in double */       \
    const double u_lo = fmax(w_min, w_mean - 2.0 * w_stdev), u_hi = fmin(w_max, w_mean + 2.0 * w_stdev);\
    const int64_t max_jobs = (row1 - row0) * (NN + 3);                                            \
    /* conn_add_shared_weight: the run's first JOB_CONN of each slot (x2: drawn recurrent or not) */\
    /* (and with mutation_num: a later one records 0) */                                          \
    int64_t *first_link = shared_link || cm ? malloc(2 * NN * sizeof(int64_t)) : NULL;            \
    uint8_t *w_mut = cm ? calloc(row1 - row0, 1) : NULL; /* the children whose weights mutated */ \
    if (first_link) for (int64_t f = 0; f < 2 * NN; ++f) first_link[f] = -1;                      \
    uint64_t *job_counter = malloc(max_jobs * (sizeof(uint64_t) + sizeof(double) + 2 * sizeof(int32_t) + 1));\
    double *job_z = (double *)(job_counter + max_jobs);                                           \
    int32_t *job_row = (int32_t *)(job_z + max_jobs), *job_slot = job_row + max_jobs;             \
    uint8_t *job_kind = (uint8_t *)(job_slot + max_jobs);                                         \
    int64_t n_jobs = 0;                                                                           \
    const uint64_t key = (uint64_t)keys[row0 / P]; /* rows row0..row1 are one run */              \
    for (int64_t row = row0; row < row1; ++row) {                                                 \
        const int64_t r = row / P, p = row % P, crow = row - row0;                                \
        const uint64_t b0 = (uint64_t)base[r];                                                    \
        T *w = cw + crow * NN; uint8_t *c = cc + crow * NN, *e = ce + crow * NN, *nd = cn + crow * N;\
        uint64_t *bits = gbits + row * W; /* = c */                                               \
        if (granted[row]) {                                                                       \
            const int64_t i = src[row], j = dst[row], k = new_node[row];                          \
            const T old = w[i * N + j];                                                           \
            e[i * N + j] = 0;                                                                     \
            w[i * N + k] = (T)1; c[i * N + k] = 1; e[i * N + k] = 1;                              \
            w[k * N + j] = old; c[k * N + j] = 1; e[k * N + j] = 1;                               \
            if (cm) { cm[crow * NN + i * N + k] = 0; cm[crow * NN + k * N + j] = 0; } /* [NEATC] */ \
            nd[k] = 1;                                                                            \
            bits[(i * N + k) / 64] |= 1ULL << ((i * N + k) % 64);                                 \
            bits[(k * N + j) / 64] |= 1ULL << ((k * N + j) % 64);                                 \
        }                                                                                         \
        if (!active[row]) { bits_summary(bits, W, gbefore + row * W, gcount + row, gtop + row); continue; }\
        int32_t genes[MAX_SLOTS + 1];                                                             \
        int64_t n_genes = bits_to_slots(bits, W, genes);                                          \
        /* [NEATC] exclusive: add-node (its draw), else add-connection, else the rest */         \
        const int clone = (active[row] & 8) != 0; /* delta coding: a new link, else every weight */\
        const int node_drawn = exclusive && !clone && uniform01(key, b0 + blocks[B_NODE_WANT] + p) < node_add_prob;\
        const int conn_drawn = !node_drawn &&                                                     \
            uniform01(key, b0 + blocks[B_CONN_WANT] + p) < (clone ? clone_link_prob : conn_add_prob);\
        if (conn_drawn) {                                                                         \
            /* rows as bitsets: out[i] = genes i -> j; into[j] = i with a path i -> j (closure) */\
            uint64_t out[MAX_ROWS] = {0}, into[MAX_ROWS] = {0}, nodes = 0, ends = 0;              \
            for (int64_t j = 0; j < N; ++j) nodes |= (uint64_t)(nd[j] != 0) << j;                 \
            for (int64_t g = 0; g < n_genes; ++g) {                                               \
                const int64_t i = genes[g] / N, j = genes[g] % N;                                 \
                out[i] |= 1ULL << j; into[j] |= 1ULL << i; ends |= 1ULL << i | 1ULL << j;         \
            }                                                                                     \
            if (feed_forward) /* Warshall over the genes' end nodes only (the rest have no path) */\
                for (uint64_t ks = ends; ks; ks &= ks - 1) {                                      \
                    const int64_t k = __builtin_ctzll(ks);                                        \
                    const uint64_t via = into[k];                                                 \
                    for (uint64_t js = ends; js; js &= js - 1) {                                  \
                        const int64_t j = __builtin_ctzll(js);                                    \
                        into[j] |= via & (0 - (into[j] >> k & 1));                                \
                    }                                                                             \
                }                                                                                 \
            const uint64_t targets = nodes & ~((1ULL << first_output) - 1); /* not into inputs */ \
            uint64_t cand[MAX_ROWS];                                                              \
            int64_t n = 0;                                                                        \
            uint64_t reach[MAX_ROWS] = {0}; /* [NEATC]: reach[i] = j with a path j -> i of enabled genes */\
            const uint64_t outputs = (first_hidden >= 64 ? ~0ULL : (1ULL << first_hidden) - 1) & ~((1ULL << first_output) - 1);\
            const int want_rec = (active[row] & 4) != 0;                                          \
            if (recur_split) {                                                                    \
                uint64_t on_ends = 0;                                                             \
                for (int64_t g = 0; g < n_genes; ++g) {                                           \
                    if (!e[genes[g]]) continue;                                                   \
                    const int64_t i = genes[g] / N, j = genes[g] % N;                             \
                    reach[j] |= 1ULL << i; on_ends |= 1ULL << i | 1ULL << j;                      \
                }                                                                                 \
                for (uint64_t ks = on_ends; ks; ks &= ks - 1) {                                   \
                    const int64_t k = __builtin_ctzll(ks);                                        \
                    const uint64_t via = reach[k];                                                \
                    for (uint64_t js = on_ends; js; js &= js - 1) {                               \
                        const int64_t j = __builtin_ctzll(js);                                    \
                        reach[j] |= via & (0 - (reach[j] >> k & 1));                              \
                    }                                                                             \
                }                                                                                 \
            }                                                                                     \
            for (int64_t i = 0; i < N; ++i) {                                                     \
                uint64_t m = (nodes >> i & 1) ? targets & ~out[i] : 0;                            \
                if (feed_forward) m &= ~(into[i] | 1ULL << i); /* no self loop, no path j -> i */ \
                if (recur_split) { /* i -> j recurrent: j == i, a path j -> i, or an output end */\
                    const uint64_t rec = (outputs >> i & 1) ? ~0ULL : (reach[i] | 1ULL << i | outputs);\
                    m &= want_rec ? rec : ~rec;                                                   \
                }                                                                                 \
                cand[i] = m; n += __builtin_popcountll(m);                                        \
            }                                                                                     \
            int64_t s = -1;                                                                       \
            if (n > 0 && conn_tries > 0) { /* [NEATC] tries: mutate.py's _pick_by_tries, op by op */\
                const int loops = recur_split && want_rec;                                        \
                const int64_t nn = __builtin_popcountll(nodes), nt = __builtin_popcountll(targets);\
                int64_t total = 0;                                                                \
                for (int64_t i = 0; i < N; ++i)                                                   \
                    total += __builtin_popcountll(cand[i]) + (loops ? (int64_t)(cand[i] >> i & 1) * nn : 0);\
                const int64_t pairs = nn * nt * (loops ? 2 : 1);                                  \
                int64_t k = tries_law(uniform01(key, b0 + blocks[B_CONN_PICK] + p), total, pairs, conn_tries);\
                if (k >= 0) {                                                                     \
                    for (int64_t i = 0; i < N && s < 0; ++i)                                      \
                        for (uint64_t m = cand[i]; m; m &= m - 1) {                               \
                            const int64_t j = __builtin_ctzll(m);                                 \
                            const int64_t share = 1 + (loops && j == i ? nn : 0);                 \
                            if (k < share) { s = i * N + j; break; }                              \
                            k -= share;                                                           \
                        }                                                                         \
                }                                                                                 \
            } else if (n > 0) {                                                                   \
                int64_t k = pick_k(uniform01(key, b0 + blocks[B_CONN_PICK] + p), n), i = 0;       \
                while (k >= __builtin_popcountll(cand[i])) k -= __builtin_popcountll(cand[i++]);  \
                s = i * N + kth_bit(cand[i], k);                                                  \
            }                                                                                     \
            if (s >= 0) {                                                                         \
                job_counter[n_jobs] = b0 + blocks[B_CONN_INIT] + 2 * p; job_row[n_jobs] = (int32_t)crow;\
                int later = 0;                                                                    \
                if (first_link) { /* shared_link: a later one draws the first one's weight (its counter) */\
                    int64_t *first = first_link + (recur_split && want_rec) * NN + s;             \
                    later = *first >= 0;                                                          \
                    if (!later) *first = n_jobs;                                                  \
                    else if (shared_link) job_counter[n_jobs] = job_counter[*first];              \
                }                                                                                 \
                job_slot[n_jobs] = (int32_t)s; job_kind[n_jobs++] = later ? JOB_CONN_LATER : JOB_CONN;\
                c[s] = 1; e[s] = 1; bits[s / 64] |= 1ULL << (s % 64);                            \
                genes[n_genes++] = (int32_t)s;                                                    \
            }                                                                                     \
        }                                                                                         \
        if (clone ? !conn_drawn : (!exclusive || (!node_drawn && !conn_drawn))) {                 \
        const int genome_hit = uniform01(key, b0 + blocks[B_W_GENOME] + p) < w_rate || clone;     \
        const uint64_t c_u = b0 + blocks[B_W_U] + p * NN, c_z = b0 + blocks[B_W_NOISE] + 2 * p * NN;\
        if (w_mut) w_mut[crow] = neatc ? genome_hit : (per_gene || genome_hit);                   \
        if (neatc && genome_hit) { /* [NEATC] mutate_link_weights: genes in slot order */        \
            n_genes = bits_to_slots(bits, W, genes);                                              \
            const int severe = (active[row] & 2) != 0;                                            \
            const double cnt = (double)n_genes;                                                   \
            for (int64_t g = 0; g < n_genes; ++g) {                                               \
                const double choice = uniform01(key, c_u + genes[g]);                             \
                const double half = uniform01(key, c_z + 2 * (uint64_t)genes[g] + 1);             \
                const int tail = cnt >= 10.0 && (double)g > cnt * 0.8;                            \
                const double gauss = severe ? 0.3 : (tail ? 0.5 : 0.0);                           \
                const double cold = severe ? 0.1 : (tail ? 0.3 : (half > 0.5 ? -0.1 : 0.0));      \
                job_counter[n_jobs] = c_z + 2 * (uint64_t)genes[g]; job_row[n_jobs] = (int32_t)crow;\
                job_slot[n_jobs] = genes[g]; job_kind[n_jobs] = choice > gauss ? JOB_NC_PERTURB : JOB_NC_REPLACE;\
                n_jobs += choice > cold;                                                          \
            }                                                                                     \
        } else if (per_gene || genome_hit) {                                                      \
            /* which genes change, and how */                                                     \
            double u[MAX_SLOTS + 1];                                                              \
            _Pragma("omp simd")                                                                   \
            for (int64_t g = 0; g < n_genes; ++g) u[g] = uniform01(key, c_u + genes[g]);          \
            for (int64_t g = 0; g < n_genes; ++g) {                                               \
                int h, rep;                                                                       \
                if (per_gene) { const int perturb = u[g] < w_rate;                                \
                                rep = !perturb && u[g] < w_rate_sum; h = perturb || rep; }         \
                else { rep = u[g] < w_replace; h = 1; }                                           \
                job_counter[n_jobs] = c_z + 2 * (uint64_t)genes[g]; job_row[n_jobs] = (int32_t)crow;\
                job_slot[n_jobs] = genes[g]; job_kind[n_jobs] = rep ? JOB_REPLACE : JOB_PERTURB;  \
                n_jobs += h;                                                                      \
            }                                                                                     \
        }                                                                                         \
        if (!clone && uniform01(key, b0 + blocks[B_S_WANT] + p) < s_rate) {                       \
            job_counter[n_jobs] = b0 + blocks[B_S_NOISE] + 2 * p; job_row[n_jobs] = (int32_t)crow; \
            job_slot[n_jobs] = 0; job_kind[n_jobs++] = JOB_SIGMA;                                 \
        }                                                                                         \
        const uint64_t c_t = b0 + blocks[B_TOGGLE] + p * NN;                                      \
        uint8_t flip[MAX_SLOTS + 1];                                                              \
        _Pragma("omp simd")                                                                       \
        for (int64_t g = 0; g < n_genes; ++g) flip[g] = uniform01(key, c_t + genes[g]) < toggle_rate; \
        for (int64_t g = 0; g < n_genes; ++g) e[genes[g]] ^= flip[g] & !clone;                    \
        if (one_on && !clone) { /* [NEATC] toggle one gene, then re-enable the first disabled one */        \
            int32_t sorted[MAX_SLOTS + 1];                                                        \
            const int64_t n_sorted = bits_to_slots(bits, W, sorted);                              \
            if (uniform01(key, b0 + blocks[B_ONE_WANT] + p) < one_prob && n_sorted > 0) {          \
                const int64_t s = sorted[pick_k(uniform01(key, b0 + blocks[B_ONE_PICK] + p), n_sorted)];\
                if (!e[s]) e[s] = 1;                                                              \
                else {                                                                            \
                    const int64_t i = s / N;                                                      \
                    int others = 0;                                                               \
                    for (int64_t j = 0; j < N; ++j) others += i * N + j != s && c[i * N + j] && e[i * N + j];\
                    if (others) e[s] = 0;                                                         \
                }                                                                                 \
            }                                                                                     \
            if (uniform01(key, b0 + blocks[B_REENABLE] + p) < re_prob)                            \
                for (int64_t g = 0; g < n_sorted; ++g) if (!e[sorted[g]]) { e[sorted[g]] = 1; break; }\
        }                                                                                         \
        }                                                                                         \
        bits_summary(bits, W, gbefore + row * W, gcount + row, gtop + row);                       \
    }                                                                                             \
    _Pragma("omp simd")                                                                           \
    for (int64_t q = 0; q < n_jobs; ++q) job_z[q] = normal_at(key, job_counter[q]);                \
    for (int64_t q = 0; q < n_jobs; ++q) {                                                        \
        T *w = cw + job_row[q] * NN;                                                              \
        const int64_t s = job_slot[q];                                                            \
        const T zt = (T)job_z[q];                                                                 \
        if (job_kind[q] <= JOB_CONN_LATER) {                                                      \
            T init = zt * stdev; init = init + mean;                                              \
            if (w_uniform) init = (T)(u_lo + (u_hi - u_lo) * uniform01(key, job_counter[q]));     \
            w[s] = clampT_##SFX(init, lo, hi);                                                    \
            if (cm) cm[job_row[q] * NN + s] = job_kind[q] == JOB_CONN ? w[s] : (T)0;              \
        } else if (job_kind[q] == JOB_SIGMA) {                                                    \
            T step = zt * (T)s_power;                                                             \
            cs[job_row[q]] = clampT_##SFX(cs[job_row[q]] + step, (T)s_min, (T)s_max);             \
        } else if (job_kind[q] >= JOB_NC_PERTURB) { /* a step uniform in +-power */               \
            const T step = (T)((2.0 * uniform01(key, job_counter[q]) - 1.0) * w_power);           \
            w[s] = clampT_##SFX(job_kind[q] == JOB_NC_PERTURB ? w[s] + step : step, lo, hi);       \
        } else {                                                                                  \
            T fresh = zt * stdev; fresh = fresh + mean;                                           \
            if (w_uniform) fresh = (T)(u_lo + (u_hi - u_lo) * uniform01(key, job_counter[q]));    \
            T step = zt * power; T pert = w[s] + step;                                            \
            w[s] = clampT_##SFX(job_kind[q] == JOB_REPLACE ? fresh : pert, lo, hi);               \
        }                                                                                         \
    }                                                                                             \
    /* [NEATC] mutate_link_weights: every gene's mutation_num is its weight (0 where no gene) */  \
    if (w_mut)                                                                                    \
        for (int64_t crow = 0; crow < row1 - row0; ++crow)                                        \
            if (w_mut[crow]) memcpy(cm + crow * NN, cw + crow * NN, NN * sizeof(T));              \
    free(job_counter); free(first_link); free(w_mut);                                             \
}                                                                                                 \
/* The closest living representative of run r within thr for genome rows row0 .. row0 + P of  \
   g (-1: none; first slot on ties): out[0 .. P). With ident (the species' numbers [R, S]):       \
   [NEATC]'s rule instead, the first within thr in the order the species were founded. */        \
static void nearest_reps_##SFX(genes_##SFX g, int64_t row0, int64_t P, genes_##SFX rep, const uint8_t *alive,\
                               int64_t r, int64_t S, int64_t NN, int64_t W, const double *coef, double thr,\
                               int64_t *out, const int64_t *ident) {                              \
    int64_t live[S > 0 ? S : 1], n_live = 0;                                                  \
    for (int64_t s = 0; s < S; ++s) if (alive[r * S + s]) live[n_live++] = s;                     \
    if (ident) /* oldest first: insertion sort by species number (stable: slot order on ties) */  \
        for (int64_t q = 1; q < n_live; ++q)                                                      \
            for (int64_t k = q; k > 0 && ident[r * S + live[k - 1]] > ident[r * S + live[k]]; --k) { \
                const int64_t t = live[k]; live[k] = live[k - 1]; live[k - 1] = t;                \
            }                                                                                     \
    /* The living representatives, one array per field (and per bitset word), so that the       \
       terms of a genome against all of them are vector loops; pair_terms's arithmetic. */      \
    const int64_t L = n_live > 0 ? n_live : 1;                                                    \
    char *soa = malloc(L * (2 * W * sizeof(uint64_t) + 2 * sizeof(int64_t) + 4 * sizeof(double)));    \
    uint64_t *rbits = (uint64_t *)soa; int64_t *rbefore = (int64_t *)(rbits + W * L);             \
    int64_t *rtop = rbefore + W * L, *mt = rtop + L; /* mt: matching genes */                     \
    double *rcnt = (double *)(mt + L), *rsig = rcnt + L, *st = rsig + L, *sg = st + L;            \
    for (int64_t q = 0; q < n_live; ++q) {                                                        \
        const int64_t rq = r * S + live[q];                                                       \
        for (int64_t k = 0; k < W; ++k) {                                                         \
            rbits[k * L + q] = rep.bits[rq * W + k]; rbefore[k * L + q] = rep.before[rq * W + k];    \
        }                                                                                         \
        rtop[q] = rep.top[rq]; rcnt[q] = (double)rep.cnt[rq];                                     \
        rsig[q] = (double)rep.sig[rep.map ? rep.map[rq] : rq];                                    \
    }                                                                                             \
    for (int64_t p = 0; p < P; ++p) {                                                             \
        /* Every representative's terms first (vector loops), then the choice in slot order,     \
           adding the weight term only where it can still matter: pair_dist's result, one       \
           representative at a time. */                                                        \
        const int64_t ra = row0 + p, ta = g.top[ra];                                             \
        const uint64_t *A = g.bits + ra * W; const int64_t *Abefore = g.before + ra * W;          \
        const double na = (double)g.cnt[ra], sa = (double)g.sig[g.map ? g.map[ra] : ra];          \
        if (n_live < VECTOR_REPS) { /* too few for vectors: pair_terms itself */                   \
            for (int64_t q = 0; q < n_live; ++q) {                                                \
                const terms_##SFX t = pair_terms_##SFX(g, ra, rep, r * S + live[q], W, coef);     \
                st[q] = t.structure; sg[q] = t.sigma; mt[q] = t.match;                            \
            }                                                                                     \
        } else {                                                                                  \
            for (int64_t q = 0; q < n_live; ++q) mt[q] = 0;                                       \
            for (int64_t k = 0; k < W; ++k) {                                                     \
                const uint64_t a = A[k], *col = rbits + k * L;                                    \
                for (int64_t q = 0; q < n_live; ++q) mt[q] += __builtin_popcountll(a & col[q]);   \
            }                                                                                     \
            const int64_t wa = ta < 0 ? 0 : ta / 64;                                              \
            const uint64_t ma = ta < 0 ? 0 : upto_mask(ta);                                       \
            const uint64_t *bw = rbits + wa * L; const int64_t *bb = rbefore + wa * L;            \
            for (int64_t q = 0; q < n_live; ++q) {                                                \
                const int64_t tb = rtop[q], wb = tb < 0 ? 0 : tb / 64;                            \
                const int64_t a_upto = tb < 0 ? 0 : Abefore[wb] + __builtin_popcountll(A[wb] & upto_mask(tb));\
                const int64_t b_upto = ta < 0 ? 0 : bb[q] + __builtin_popcountll(bw[q] & ma);     \
                st[q] = structure_term(na, rcnt[q], a_upto, b_upto, mt[q], coef);                 \
                sg[q] = coef[3] * fabs(sa - rsig[q]);                                             \
            }                                                                                     \
        }                                                                                         \
        if (ident) { /* first fit: the weight term only where the rest is below thr */           \
            out[p] = -1;                                                                          \
            for (int64_t q = 0; q < n_live; ++q) {                                                \
                if (st[q] + sg[q] >= thr) continue;                                               \
                const terms_##SFX t = {st[q], sg[q], mt[q]};                                      \
                if (pair_full_##SFX(g, ra, rep, r * S + live[q], NN, W, coef, t) < thr) { out[p] = live[q]; break; }\
            }                                                                                     \
            continue;                                                                             \
        }                                                                                         \
        double best = INFINITY; int64_t bk = -1;                                                  \
        for (int64_t q = 0; q < n_live; ++q) {                                                    \
            const double bound = best < thr ? best : thr, partial = st[q] + sg[q];                \
            if (partial >= bound) { if (partial < best) { best = partial; bk = live[q]; } continue; }    \
            const terms_##SFX t = {st[q], sg[q], mt[q]};                                          \
            const double d = pair_full_##SFX(g, ra, rep, r * S + live[q], NN, W, coef, t);        \
            if (d < best) { best = d; bk = live[q]; }                                             \
        }                                                                                         \
        out[p] = best < thr ? bk : -1;                                                            \
    }                                                                                             \
    free(soa);                                                                                    \
}                                                                                                 \
/* One breeding step, a run at a time (its children stay in cache between the phases):            \
   phase 1 for the run, its node registry (as evolution.innovation.assign_split_nodes:            \
   distinct splits ranked in slot order take the free hidden slots in ascending order),           \
   phase 2. */                                                                                    \
void breed_##SFX(const T *pw, const uint8_t *pc, const uint8_t *pe, const uint8_t *pn, const T *ps,\
                 const int64_t *a_idx, const int64_t *b_idx, const uint8_t *do_cross,             \
                 const uint8_t *active, T *cw, uint8_t *cc, uint8_t *ce, uint8_t *cn, T *cs,      \
                 int64_t *src, int64_t *dst, uint8_t *request, const int64_t *keys,               \
                 const int64_t *base, const int64_t *blocks, int64_t R, int64_t P, int64_t N,     \
                 double inherit_disabled, double node_add_prob, int64_t *new_node, uint8_t *granted,\
                 int64_t first_output, int feed_forward, int per_gene, double conn_add_prob,      \
                 double w_mean, double w_stdev, double w_min, double w_max, double w_rate,        \
                 double w_rate_sum, double w_replace, double w_power, double s_rate, double s_power,\
                 double s_min, double s_max, double toggle_rate, const uint8_t *reserved,         \
                 int64_t first_hidden, const int64_t *dest_runs, uint64_t *gbits, int64_t *gbefore,\
                 int64_t *gcount, int64_t *gtop, const int64_t *gmap, const uint64_t *r_bits,     \
                 const int64_t *r_pre, const int64_t *r_cnt, const int64_t *r_top, const T *r_w,  \
                 const T *r_sig, const uint8_t *r_alive, int64_t S, const double *coef, double thr,\
                 int64_t *nearest, int exclusive, int neatc, int recur_split, int one_on,         \
                 double one_prob, double re_prob, double clone_link_prob, int64_t conn_tries,     \
                 const int64_t *r_ident, int w_uniform, int shared_link, const T *pm, T *cm,     \
                 int64_t split_first_bias, int threads) {                                         \
    const int64_t NN = N * N, words = (NN + 63) / 64;                                             \
    _Pragma("omp parallel for schedule(static) num_threads(threads)")                             \
    for (int64_t r = 0; r < R; ++r) {                                                             \
        const int64_t row0 = r * P, row1 = row0 + P;                                              \
        /* dest_runs: the children overwrite their parents' run dest_runs[r] of the parent arrays \
           (the same arrays as the child ones), so the run's parents are copied aside first. */ \
        const int64_t c0 = (dest_runs ? dest_runs[r] : r) * P;                                    \
        T *cw_r = cw + c0 * NN, *cs_r = cs + c0, *cm_r = cm ? cm + c0 * NN : NULL;                \
        const T *pm_r = pm; T *m_aside = NULL;                                                    \
        uint8_t *cc_r = cc + c0 * NN, *ce_r = ce + c0 * NN, *cn_r = cn + c0 * N;                  \
        const T *pw_r = pw, *ps_r = ps; const uint8_t *pc_r = pc, *pe_r = pe, *pn_r = pn;          \
        int64_t idx0 = 0; char *aside = NULL; int64_t *loc = NULL;                                \
        const int64_t *ia = a_idx, *ib = b_idx;                                                   \
        if (dest_runs) { /* only the parents (a fifth of the run, say) are copied aside */        \
            loc = malloc(3 * P * sizeof(int64_t));                                                \
            int64_t *la = loc, *lb = loc + P, *slot = loc + 2 * P, n_used = 0;                    \
            for (int64_t q = 0; q < P; ++q) slot[q] = -1;                                         \
            for (int64_t row = row0; row < row1; ++row) {                                         \
                const int64_t a = a_idx[row] - c0, b = b_idx[row] - c0;                           \
                if (slot[a] < 0) slot[a] = n_used++;                                              \
                if (slot[b] < 0) slot[b] = n_used++;                                              \
                la[row - row0] = slot[a]; lb[row - row0] = slot[b];                               \
            }                                                                                     \
            aside = malloc(n_used * (NN * (sizeof(T) + 2) + N + sizeof(T)));                      \
            T *w = (T *)aside, *sg = w + n_used * NN;                                             \
            uint8_t *c = (uint8_t *)(sg + n_used), *e = c + n_used * NN, *nd = e + n_used * NN;   \
            for (int64_t q = 0; q < P; ++q) {                                                     \
                const int64_t k = slot[q], from = c0 + q;                                         \
                if (k < 0) continue;                                                              \
                memcpy(w + k * NN, pw + from * NN, NN * sizeof(T)); sg[k] = ps[from];             \
                memcpy(c + k * NN, pc + from * NN, NN); memcpy(e + k * NN, pe + from * NN, NN);   \
                memcpy(nd + k * N, pn + from * N, N);                                             \
            }                                                                                     \
            if (pm) { /* the parents' mutation_num aside too */                                   \
                m_aside = malloc(n_used * NN * sizeof(T));                                        \
                for (int64_t q = 0; q < P; ++q)                                                   \
                    if (slot[q] >= 0) memcpy(m_aside + slot[q] * NN, pm + (c0 + q) * NN, NN * sizeof(T));\
                pm_r = m_aside;                                                                   \
            }                                                                                     \
            pw_r = w; ps_r = sg; pc_r = c; pe_r = e; pn_r = nd; ia = la; ib = lb; idx0 = row0;    \
        }                                                                                         \
        phase1_##SFX(pw_r, pc_r, pe_r, pn_r, ps_r, ia, ib, do_cross, active, cw_r, cc_r, ce_r, cn_r,\
                     cs_r, src, dst, request, keys, base, blocks, R, P, N, inherit_disabled, node_add_prob,\
                     idx0, row0, row1, gbits, pm_r, cm_r, split_first_bias, first_output);        \
        free(aside); free(loc); free(m_aside);                                                    \
        uint8_t used[MAX_ROWS]; int64_t free_slots[MAX_ROWS], n_free = 0;                         \
        for (int64_t j = 0; j < N; ++j) used[j] = reserved[r * N + j];                            \
        for (int64_t q = 0; q < P; ++q)                                                           \
            for (int64_t j = 0; j < N; ++j) used[j] |= cn_r[q * N + j];                           \
        for (int64_t j = first_hidden; j < N; ++j) if (!used[j]) free_slots[n_free++] = j;        \
        uint64_t wanted[MAX_SLOTS / 64] = {0};                                                    \
        for (int64_t row = row0; row < row1; ++row)                                               \
            if (request[row]) { const int64_t f = src[row] * N + dst[row]; wanted[f / 64] |= 1ULL << (f % 64); }\
        int64_t before[MAX_SLOTS / 64], n = 0;                                                    \
        for (int64_t k = 0; k < words; ++k) { before[k] = n; n += __builtin_popcountll(wanted[k]); }\
        for (int64_t row = row0; row < row1; ++row) {                                             \
            granted[row] = 0; new_node[row] = 0;                                                  \
            if (!request[row]) continue;                                                          \
            const int64_t f = src[row] * N + dst[row];                                            \
            const int64_t k = before[f / 64] + __builtin_popcountll(wanted[f / 64] & ((1ULL << (f % 64)) - 1));\
            if (k < n_free) { granted[row] = 1; new_node[row] = free_slots[k]; }                  \
        }                                                                                         \
        phase2_##SFX(cw_r, cc_r, ce_r, cn_r, cs_r, new_node, granted, src, dst, active, keys, base, blocks, R, P, N,\
                     first_output, feed_forward, per_gene, conn_add_prob, w_mean, w_stdev, w_min, w_max,\
                     w_rate, w_rate_sum, w_replace, w_power, s_rate, s_power, s_min, s_max, toggle_rate,\
                     row0, row1, gbits, gbefore, gcount, gtop, exclusive, node_add_prob, neatc,   \
                     recur_split, one_on, one_prob, re_prob, first_hidden, clone_link_prob, conn_tries,\
                     w_uniform, shared_link, cm_r);                                               \
        if (nearest) { /* speciate's first step, while the run's children are in cache */         \
            const genes_##SFX cg = {gbits, gbefore, gcount, gtop, cm ? cm : cw, cs, gmap}; /* the distance's weights */\
            const genes_##SFX rg = {r_bits, r_pre, r_cnt, r_top, r_w, r_sig, NULL};               \
            nearest_reps_##SFX(cg, row0, P, rg, r_alive, r, S, NN, words, coef, thr, nearest + row0, r_ident);\
        }                                                                                         \
    }                                                                                             \
}                                                                                                 \
/* Species of genomes g[R, P] (speciate's rule): the closest living representative of rep[R, S] \
   within thr, first slot on ties; the rest found species in genome order, each in the lowest \
   slot without members (slots >= S mean the caller must grow), and every genome still without \
   a species within thr of a founder joins it. founded[r, k]: run r's k-th new slot. */         \
void assign_species_##SFX(const uint64_t *g_bits, const int64_t *g_pre, const int64_t *g_cnt,     \
                          const int64_t *g_top, const T *g_w, const T *g_sig, const int64_t *g_map,\
                          const uint64_t *r_bits,                                                 \
                          const int64_t *r_pre, const int64_t *r_cnt,\
                          const int64_t *r_top, const T *r_w, const T *r_sig, const int64_t *r_map,\
                          const uint8_t *alive,                                                   \
                          int64_t R, int64_t P, int64_t S, int64_t NN, int64_t W, const double *coef,\
                          double thr, int64_t *species, int64_t *founded, int64_t *n_founded,     \
                          uint8_t *taken, const int64_t *nearest, const int64_t *r_ident,         \
                          int threads) {                                                          \
    const genes_##SFX g = {g_bits, g_pre, g_cnt, g_top, g_w, g_sig, g_map};                       \
    const genes_##SFX rep = {r_bits, r_pre, r_cnt, r_top, r_w, r_sig, r_map};                     \
    _Pragma("omp parallel for schedule(static) num_threads(threads)")                            \
    for (int64_t r = 0; r < R; ++r) {                                                             \
        int64_t *sp = species + r * P;                                                            \
        uint8_t *tk = taken + r * (S + P);                                                        \
        memset(tk, 0, S + P);                                                                     \
        if (nearest) memcpy(sp, nearest + r * P, P * sizeof(int64_t)); /* found by breed_ */      \
        else nearest_reps_##SFX(g, r * P, P, rep, alive, r, S, NN, W, coef, thr, sp, r_ident);      \
        for (int64_t p = 0; p < P; ++p) {                                                         \
            if (sp[p] >= 0) tk[sp[p]] = 1;                                                        \
        }                                                                                         \
        int64_t n = 0, free_slot = 0;                                                             \
        for (int64_t p = 0; p < P; ++p) {                                                         \
            if (sp[p] >= 0) continue;                                                             \
            while (tk[free_slot]) ++free_slot;                                                    \
            const int64_t slot = free_slot;                                                       \
            tk[slot] = 1; sp[p] = slot; founded[r * P + n++] = slot;                              \
            for (int64_t q = p + 1; q < P; ++q)                                                   \
                if (sp[q] < 0 && pair_dist_##SFX(g, r * P + q, g, r * P + p, NN, W, coef, thr) < thr) sp[q] = slot; \
        }                                                                                         \
        n_founded[r] = n;                                                                         \
    }                                                                                             \
}
DEFINE_BREED(float, f32)
DEFINE_BREED(double, f64)

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
