"""The breeding step and the compatibility distances as C kernels (CPU).

The tensor operators (``crossover``, ``mutate_*``, ``distance``) are the readable reference:
each touches every slot of every genome and draws a random number for every slot. These
kernels compute the same step a run at a time (threads share out the runs) and a child at a
time within it, touching only the child's genes and evaluating only the draws it uses: a
draw is addressed by its counter in the run's stream (``evolution.rng``), so skipping the
unused ones changes nothing, and the result is the same with any thread count.

- ``breed``: crossover, add-node (with the run's node registry in between), add-connection,
  weight, sigma and enabled mutations, in the reference's order and with its arithmetic
  (no contraction; float32 genomes round where torch rounds), and the same normals
  (``evolution.rng.box_muller``), so the children are the same bit for bit. It also writes
  the children's gene bitsets (``GeneBits``) and, given the representatives, each child's
  closest one (``speciate``'s first step), while a run's children are still in cache.
- ``assign_species``: ``speciate``'s rule (closest living representative within the
  threshold, else found a species in genome order) from per-genome gene bitsets: excess,
  disjoint and matching genes by popcounts (against all living representatives at once, as
  vector loops), the weight term summed in double and skipped once the other terms reach
  the bound. ``gene_distances`` gives the distances themselves.
  The reference sums the weight term another way (``L1 - a_only - b_only``), so the two
  agree to about 1e-15.
- ``touched_nodes``: the node slots the living representatives use, from their bitsets
  (the node registry's reserved slots).

``SNN_NEAT_FUSED=0`` disables the kernels (``snn_torch._cbuild``).
"""

from __future__ import annotations

import ctypes
import math
import threading

import torch
from torch import Tensor

from evolution import select_kernel
from evolution.config import NEATConfig
from evolution.population import Genomes
from evolution.rng import BOX_MULLER_C, COUNTER_RNG_C, RunRNG
from snn_torch._cbuild import load_c_library

__all__ = ["kernel_available", "usable_for", "wanted", "breed", "breed_blocks", "GeneBits", "gene_distances", "assign_species",
           "touched_nodes", "found_species", "put_rows"]

# Draw blocks of one breeding step, in the reference's order (the C enum B_* lists them in the
# same order): (name, "nn" for a [P, N, N] block or "p" for a [P] block, counters per draw).
_BLOCKS = (
    ("from_other", "nn", 1), ("stays_disabled", "nn", 1), ("sigma_pick", "p", 1),  # crossover
    ("node_want", "p", 1), ("node_pick", "p", 1),  # mutate_add_node
    ("conn_want", "p", 1), ("conn_pick", "p", 1), ("conn_init", "p", 2),  # mutate_add_connection
    ("w_genome", "p", 1), ("w_u", "nn", 1), ("w_noise", "nn", 2),  # mutate_weights
    ("s_want", "p", 1), ("s_noise", "p", 2),  # mutate_sigma
    ("toggle", "nn", 1),  # mutate_toggle_enabled
)


def breed_blocks(P: int, N: int) -> tuple[list[int], int]:
    """Each block's first counter relative to the step's first, and the step's total."""
    starts, at = [], 0
    for _, kind, per in _BLOCKS:
        starts.append(at)
        at += (P * N * N if kind == "nn" else P) * per
    return starts, at


_SOURCE = r"""
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
""" + COUNTER_RNG_C + BOX_MULLER_C + r"""
static inline double normal_at(uint64_t key, uint64_t c) {
    return box_muller(uniform01(key, c), uniform01(key, c + 1));
}
enum { B_FROM_OTHER, B_STAYS, B_SIGMA_PICK, B_NODE_WANT, B_NODE_PICK, B_CONN_WANT, B_CONN_PICK, B_CONN_INIT,
       B_W_GENOME, B_W_U, B_W_NOISE, B_S_WANT, B_S_NOISE, B_TOGGLE, N_BLOCKS };
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

#define VECTOR_REPS 3 /* species assignment: vector loops over at least this many representatives */
enum { JOB_CONN, JOB_PERTURB, JOB_REPLACE, JOB_SIGMA }; /* what a phase-2 normal is for */
#define DEFINE_BREED(T, SFX)                                                                      \
static inline T clampT_##SFX(T x, T lo, T hi) { x = x < lo ? lo : x; return x > hi ? hi : x; }   \
/* Phase 1: crossover (or a copy of the first parent), then the add-node choice. */              \
static inline void phase1_##SFX(const T *pw, const uint8_t *pc, const uint8_t *pe, const uint8_t *pn, const T *ps,\
                  const int64_t *a_idx, const int64_t *b_idx, const uint8_t *do_cross,            \
                  const uint8_t *active, T *cw, uint8_t *cc, uint8_t *ce, uint8_t *cn, T *cs,     \
                  int64_t *src, int64_t *dst, uint8_t *request, const int64_t *keys,             \
                  const int64_t *base, const int64_t *blocks, int64_t R, int64_t P, int64_t N,   \
                  double inherit_disabled, double node_add_prob, int64_t idx0, int64_t row0,            \
                  int64_t row1, uint64_t *gbits) {                                                \
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
            for (int64_t g = 0; g < n; ++g) {                                                     \
                const int64_t s = genes[g];                                                       \
                const int matching = oc[s] != 0;                                                  \
                if (matching && u_from[g] < 0.5) w[s] = ow[s];                                    \
                const int dip = !fe[s] || (matching && !oe[s]);                                   \
                e[s] = !(dip && u_stay[g] < inherit_disabled);                                    \
            }                                                                                     \
            cs[crow] = uniform01(key, b0 + blocks[B_SIGMA_PICK] + p) < 0.5 ? ps[b] : ps[a];       \
        } else {                                                                                  \
            memcpy(e, fe, NN); cs[crow] = ps[a];                                                  \
        }                                                                                         \
        request[row] = 0; src[row] = 0; dst[row] = 0;                                             \
        if (active[row] && uniform01(key, b0 + blocks[B_NODE_WANT] + p) < node_add_prob) {        \
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
                  int64_t *gbefore, int64_t *gcount, int64_t *gtop) {                             \
    const int64_t NN = N * N, W = (NN + 63) / 64;                                                 \
    const T mean = (T)w_mean, stdev = (T)w_stdev, lo = (T)w_min, hi = (T)w_max, power = (T)w_power;\
    const int64_t max_jobs = (row1 - row0) * (NN + 3);                                            \
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
            nd[k] = 1;                                                                            \
            bits[(i * N + k) / 64] |= 1ULL << ((i * N + k) % 64);                                 \
            bits[(k * N + j) / 64] |= 1ULL << ((k * N + j) % 64);                                 \
        }                                                                                         \
        if (!active[row]) { bits_summary(bits, W, gbefore + row * W, gcount + row, gtop + row); continue; }\
        int32_t genes[MAX_SLOTS + 1];                                                             \
        int64_t n_genes = bits_to_slots(bits, W, genes);                                          \
        if (uniform01(key, b0 + blocks[B_CONN_WANT] + p) < conn_add_prob) {                       \
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
            for (int64_t i = 0; i < N; ++i) {                                                     \
                uint64_t m = (nodes >> i & 1) ? targets & ~out[i] : 0;                            \
                if (feed_forward) m &= ~(into[i] | 1ULL << i); /* no self loop, no path j -> i */ \
                cand[i] = m; n += __builtin_popcountll(m);                                        \
            }                                                                                     \
            if (n > 0) {                                                                          \
                int64_t k = pick_k(uniform01(key, b0 + blocks[B_CONN_PICK] + p), n), i = 0;       \
                while (k >= __builtin_popcountll(cand[i])) k -= __builtin_popcountll(cand[i++]);  \
                const int64_t s = i * N + kth_bit(cand[i], k);                                    \
                job_counter[n_jobs] = b0 + blocks[B_CONN_INIT] + 2 * p; job_row[n_jobs] = (int32_t)crow;\
                job_slot[n_jobs] = (int32_t)s; job_kind[n_jobs++] = JOB_CONN;                     \
                c[s] = 1; e[s] = 1; bits[s / 64] |= 1ULL << (s % 64);                            \
                genes[n_genes++] = (int32_t)s;                                                    \
            }                                                                                     \
        }                                                                                         \
        const int genome_hit = uniform01(key, b0 + blocks[B_W_GENOME] + p) < w_rate;              \
        const uint64_t c_u = b0 + blocks[B_W_U] + p * NN, c_z = b0 + blocks[B_W_NOISE] + 2 * p * NN;\
        if (per_gene || genome_hit) {                                                             \
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
        if (uniform01(key, b0 + blocks[B_S_WANT] + p) < s_rate) {                                 \
            job_counter[n_jobs] = b0 + blocks[B_S_NOISE] + 2 * p; job_row[n_jobs] = (int32_t)crow; \
            job_slot[n_jobs] = 0; job_kind[n_jobs++] = JOB_SIGMA;                                 \
        }                                                                                         \
        const uint64_t c_t = b0 + blocks[B_TOGGLE] + p * NN;                                      \
        uint8_t flip[MAX_SLOTS + 1];                                                              \
        _Pragma("omp simd")                                                                       \
        for (int64_t g = 0; g < n_genes; ++g) flip[g] = uniform01(key, c_t + genes[g]) < toggle_rate; \
        for (int64_t g = 0; g < n_genes; ++g) e[genes[g]] ^= flip[g];                             \
        bits_summary(bits, W, gbefore + row * W, gcount + row, gtop + row);                       \
    }                                                                                             \
    _Pragma("omp simd")                                                                           \
    for (int64_t q = 0; q < n_jobs; ++q) job_z[q] = normal_at(key, job_counter[q]);                \
    for (int64_t q = 0; q < n_jobs; ++q) {                                                        \
        T *w = cw + job_row[q] * NN;                                                              \
        const int64_t s = job_slot[q];                                                            \
        const T zt = (T)job_z[q];                                                                 \
        if (job_kind[q] == JOB_CONN) {                                                            \
            T init = zt * stdev; init = init + mean;                                              \
            w[s] = clampT_##SFX(init, lo, hi);                                                    \
        } else if (job_kind[q] == JOB_SIGMA) {                                                    \
            T step = zt * (T)s_power;                                                             \
            cs[job_row[q]] = clampT_##SFX(cs[job_row[q]] + step, (T)s_min, (T)s_max);             \
        } else {                                                                                  \
            T fresh = zt * stdev; fresh = fresh + mean;                                           \
            T step = zt * power; T pert = w[s] + step;                                            \
            w[s] = clampT_##SFX(job_kind[q] == JOB_REPLACE ? fresh : pert, lo, hi);               \
        }                                                                                         \
    }                                                                                             \
    free(job_counter);                                                                            \
}                                                                                                 \
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
}                                                                                                 \
/* Distances between genome rows a[r, i] and b[r, j] (rows index the sets' flat arrays). */     \
void distances_##SFX(const uint64_t *bits_a, const int64_t *pre_a, const int64_t *cnt_a, const int64_t *top_a,\
                     const T *w_a, const T *sig_a, const int64_t *map_a, const int64_t *rows_a, int64_t Ka,\
                     const uint64_t *bits_b, const int64_t *pre_b, const int64_t *cnt_b, const int64_t *top_b,\
                     const T *w_b, const T *sig_b, const int64_t *map_b, const int64_t *rows_b, int64_t Kb,\
                     int64_t R, int64_t NN, int64_t W, const double *coef, double *out, int threads) { \
    const genes_##SFX a = {bits_a, pre_a, cnt_a, top_a, w_a, sig_a, map_a};                       \
    const genes_##SFX b = {bits_b, pre_b, cnt_b, top_b, w_b, sig_b, map_b};                       \
    _Pragma("omp parallel for schedule(static) num_threads(threads)")                            \
    for (int64_t q = 0; q < R * Ka; ++q) {                                                        \
        const int64_t r = q / Ka;                                                                 \
        for (int64_t jb = 0; jb < Kb; ++jb)                                                       \
            out[q * Kb + jb] = pair_dist_##SFX(a, rows_a[q], b, rows_b[r * Kb + jb], NN, W, coef, INFINITY); \
    }                                                                                             \
}                                                                                                 \
/* The closest living representative of run r within thr for genome rows row0 .. row0 + P of  \
   g (-1: none; first slot on ties): out[0 .. P). */                                            \
static void nearest_reps_##SFX(genes_##SFX g, int64_t row0, int64_t P, genes_##SFX rep, const uint8_t *alive,\
                               int64_t r, int64_t S, int64_t NN, int64_t W, const double *coef, double thr,\
                               int64_t *out) {                                                    \
    int64_t live[S > 0 ? S : 1], n_live = 0;                                                  \
    for (int64_t s = 0; s < S; ++s) if (alive[r * S + s]) live[n_live++] = s;                     \
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
                 int64_t *nearest, int threads) {                                                 \
    const int64_t NN = N * N, words = (NN + 63) / 64;                                             \
    _Pragma("omp parallel for schedule(static) num_threads(threads)")                             \
    for (int64_t r = 0; r < R; ++r) {                                                             \
        const int64_t row0 = r * P, row1 = row0 + P;                                              \
        /* dest_runs: the children overwrite their parents' run dest_runs[r] of the parent arrays \
           (the same arrays as the child ones), so the run's parents are copied aside first. */ \
        const int64_t c0 = (dest_runs ? dest_runs[r] : r) * P;                                    \
        T *cw_r = cw + c0 * NN, *cs_r = cs + c0;                                                  \
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
            pw_r = w; ps_r = sg; pc_r = c; pe_r = e; pn_r = nd; ia = la; ib = lb; idx0 = row0;    \
        }                                                                                         \
        phase1_##SFX(pw_r, pc_r, pe_r, pn_r, ps_r, ia, ib, do_cross, active, cw_r, cc_r, ce_r, cn_r,\
                     cs_r, src, dst, request, keys, base, blocks, R, P, N, inherit_disabled, node_add_prob,\
                     idx0, row0, row1, gbits);                                                    \
        free(aside); free(loc);                                                                   \
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
                     row0, row1, gbits, gbefore, gcount, gtop);                                   \
        if (nearest) { /* speciate's first step, while the run's children are in cache */         \
            const genes_##SFX cg = {gbits, gbefore, gcount, gtop, cw, cs, gmap};                  \
            const genes_##SFX rg = {r_bits, r_pre, r_cnt, r_top, r_w, r_sig, NULL};               \
            nearest_reps_##SFX(cg, row0, P, rg, r_alive, r, S, NN, words, coef, thr, nearest + row0);\
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
                          uint8_t *taken, const int64_t *nearest, int threads) {                  \
    const genes_##SFX g = {g_bits, g_pre, g_cnt, g_top, g_w, g_sig, g_map};                       \
    const genes_##SFX rep = {r_bits, r_pre, r_cnt, r_top, r_w, r_sig, r_map};                     \
    _Pragma("omp parallel for schedule(static) num_threads(threads)")                            \
    for (int64_t r = 0; r < R; ++r) {                                                             \
        int64_t *sp = species + r * P;                                                            \
        uint8_t *tk = taken + r * (S + P);                                                        \
        memset(tk, 0, S + P);                                                                     \
        if (nearest) memcpy(sp, nearest + r * P, P * sizeof(int64_t)); /* found by breed_ */      \
        else nearest_reps_##SFX(g, r * P, P, rep, alive, r, S, NN, W, coef, thr, sp);               \
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

/* Normals at counters c0, c0 + 2, ... of a stream (for the tests). */
void normals_check(uint64_t key, uint64_t c0, int64_t n, double *out) {
    for (int64_t k = 0; k < n; ++k) out[k] = normal_at(key, c0 + 2 * (uint64_t)k);
}
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
"""

_lib: ctypes.CDLL | None = None
_lock = threading.Lock()
MAX_NODES = 64  # the feed-forward closure keeps a row of the adjacency in one 64-bit word


def kernel_available() -> bool:
    """True if the breeding kernels compiled (once per process) and are enabled."""
    global _lib
    with _lock:
        _lib = load_c_library("neat_breed", _SOURCE)
        if _lib is not None and not hasattr(_lib, "_typed"):
            P, L, D, C = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double, ctypes.c_int
            for sfx in ("f32", "f64"):
                f = getattr(_lib, f"breed_{sfx}")
                f.restype = None
                f.argtypes = ([P] * 20 + [L] * 3 + [D] * 2 + [P] * 2 + [L] + [C] * 2 + [D] * 14 + [P, L] + [P] * 5
                               + [P] * 8 + [L, P, D, P, C])
                f = getattr(_lib, f"distances_{sfx}")
                f.restype, f.argtypes = None, [P] * 8 + [L] + [P] * 8 + [L] * 4 + [P, P, C]
                f = getattr(_lib, f"assign_species_{sfx}")
                f.restype, f.argtypes = None, [P] * 15 + [L] * 5 + [P, D] + [P] * 5 + [C]
            _lib.normals_check.restype = None
            _lib.normals_check.argtypes = [ctypes.c_uint64, ctypes.c_uint64, L, P]
            _lib.gene_bits.restype = None
            _lib.gene_bits.argtypes = [P, P, P, L, L, L, P, P, P, P, C]
            _lib.found_species.restype = ctypes.c_int
            _lib.found_species.argtypes = [P, P, L, L, L, L] + [P] * 6
            _lib.put_rows.restype = ctypes.c_int
            _lib.put_rows.argtypes = [P, P, P, L, L, L]
            _lib.touched_nodes.restype = None
            _lib.touched_nodes.argtypes = [P, P, L, L, L, L, P]
            _lib._typed = True
    return _lib is not None


def _unsupported(conn: Tensor, weight: Tensor) -> str | None:
    """Why the kernels cannot take these genes, or None if they can."""
    if conn.device.type != "cpu" or weight.dtype not in (torch.float32, torch.float64) or conn.shape[-1] > MAX_NODES:
        return (f"the C breeding kernels take CPU float32/float64 genomes of at most {MAX_NODES} nodes, "
                f"got {weight.dtype} on {conn.device} with {conn.shape[-1]} nodes")
    return None


def usable_for(g: Genomes) -> bool:
    """The kernels take CPU genomes of float32/float64 with at most ``MAX_NODES`` nodes."""
    return _unsupported(g.conn, g.weight) is None and kernel_available()


def wanted(g: Genomes, fused: bool | None) -> bool:
    """Whether a step on ``g`` runs on the C kernels (these and ``evolution.select_kernel``):
    ``fused`` when given, else wherever they can run."""
    return (usable_for(g) and select_kernel.kernel_available()) if fused is None else fused


def usable_for_species(sp_conn: Tensor, sp_weight: Tensor) -> bool:
    """``usable_for`` for species representatives ``[R, S, N, N]``."""
    return _unsupported(sp_conn, sp_weight) is None and kernel_available()


def _sfx(dtype: torch.dtype) -> str:
    return "f32" if dtype == torch.float32 else "f64"


def _require(conn: Tensor, weight: Tensor) -> None:
    """Refuse, by name, what the kernels cannot take (asked for with ``fused=True``)."""
    if not kernel_available():
        raise RuntimeError("the C breeding kernels are unavailable (no compiler, or SNN_NEAT_FUSED=0); "
                           "use fused=False")
    reason = _unsupported(conn, weight)
    if reason is not None:
        raise ValueError(f"{reason}; use fused=False")


def breed(g: Genomes, first: Tensor, second: Tensor, do_cross: Tensor, active: Tensor, cfg: NEATConfig,
          rng: RunRNG, reserved: Tensor | None, *, runs: Tensor | None = None, in_place: bool = False,
          reps: tuple[GeneBits, Tensor, Tensor] | None = None) -> tuple[Genomes, Tensor, GeneBits]:
    """Children ``[R, P]`` of parents ``first`` / ``second`` (``[R, P]`` genome indices of
    ``g``; ``first`` is the fitter where ``do_cross``), mutated where ``active``: the same as
    ``crossover`` then ``mutate_add_node``, ``mutate_add_connection``, ``mutate_weights``,
    ``mutate_sigma`` and ``mutate_toggle_enabled``, and the same draws. Returns the children,
    ``[R, P]`` bool: splits refused for want of a free node slot, and the children's
    ``GeneBits`` (built as the genes are written, so ``speciate`` need not scan them again;
    valid while the children are unchanged). ``runs[R]``: the parents are those runs of ``g``
    (a larger population), read in place; with ``in_place`` the children overwrite them (each
    run's parents are copied aside first) and ``g`` itself is returned. ``reps``: ``(bits,
    rep_conn, alive)`` of the species representatives ``[R, S]``; each child's closest living
    one within the threshold is then found as the run's children are written (speciate's first
    step, while they are in cache), kept in the returned ``GeneBits`` for ``speciate``."""
    _require(g.conn, g.weight)
    (R, P), N = first.shape, g.num_nodes
    T = g.weight.dtype
    threads = torch.get_num_threads()
    starts, total = breed_blocks(P, N)
    base = rng.take(total)
    keys, blocks = rng.keys.contiguous(), torch.tensor(starts, dtype=torch.int64)
    if in_place and (runs is None or not all(t.is_contiguous() for t in g.tensors().values())):
        raise ValueError("in_place breeding needs runs= and contiguous genome tensors")
    parents = {k: v.contiguous() for k, v in g.tensors().items()}
    rows = (torch.arange(R) if runs is None else runs.to(torch.int64).cpu()).unsqueeze(1) * P
    a_idx, b_idx = (first + rows).contiguous(), (second + rows).contiguous()
    cross, act = do_cross.to(torch.uint8).contiguous(), active.to(torch.uint8).contiguous()
    child = g if in_place else Genomes(**{k: torch.empty((R, P, *t.shape[2:]), dtype=t.dtype)
                                          for k, t in parents.items()})
    dest = runs.to(torch.int64).cpu().contiguous() if in_place else None
    src = torch.empty(R, P, dtype=torch.int64)
    dst = torch.empty(R, P, dtype=torch.int64)
    request = torch.empty(R, P, dtype=torch.uint8)
    new_node = torch.empty(R, P, dtype=torch.int64)
    granted = torch.empty(R, P, dtype=torch.uint8)
    reserved8 = (torch.zeros(R, N, dtype=torch.uint8) if reserved is None
                 else reserved.to(torch.uint8).contiguous())
    words = (N * N + 63) // 64
    genes = GeneBits.__new__(GeneBits)
    genes._bind(child.weight, child.sigma, dest)
    rep_args: list = [None] * 7 + [0, None, 0.0, None]  # reps' bits .. alive, S, coefficients, threshold, out
    if reps is not None:
        rep_bits, rep_conn, alive = reps
        genes.nearest = torch.empty(R, P, dtype=torch.int64)
        genes.nearest_to = (rep_bits, rep_conn, alive.clone())
        alive8, coef = alive.to(torch.uint8).contiguous(), _coefficients(cfg)
        rep_args = [*_genes_args(rep_bits)[:6], alive8.data_ptr(), alive.shape[1], coef.data_ptr(),
                    float(cfg.compatibility_threshold), genes.nearest.data_ptr()]
    bits, before = torch.empty(R * P, words, dtype=torch.int64), torch.empty(R * P, words, dtype=torch.int64)
    count, top = torch.empty(R * P, dtype=torch.int64), torch.empty(R * P, dtype=torch.int64)
    getattr(_lib, f"breed_{_sfx(T)}")(
        parents["weight"].data_ptr(), parents["conn"].data_ptr(), parents["enabled"].data_ptr(),
        parents["node"].data_ptr(), parents["sigma"].data_ptr(), a_idx.data_ptr(), b_idx.data_ptr(),
        cross.data_ptr(), act.data_ptr(), child.weight.data_ptr(), child.conn.data_ptr(),
        child.enabled.data_ptr(), child.node.data_ptr(), child.sigma.data_ptr(), src.data_ptr(),
        dst.data_ptr(), request.data_ptr(), keys.data_ptr(), base.data_ptr(), blocks.data_ptr(), R, P, N,
        float(cfg.disabled_inherit_prob), float(cfg.node_add_prob), new_node.data_ptr(), granted.data_ptr(),
        cfg.first_output, int(cfg.feed_forward), int(cfg.weight_mutate_per_gene), float(cfg.conn_add_prob),
        float(cfg.weight_init_mean), float(cfg.weight_init_stdev), float(cfg.weight_min_value),
        float(cfg.weight_max_value), float(cfg.weight_mutate_rate),
        float(cfg.weight_mutate_rate + cfg.weight_replace_rate), float(cfg.weight_replace_rate),
        float(cfg.weight_mutate_power), float(cfg.sigma_mutate_rate), float(cfg.sigma_mutate_power),
        float(cfg.sigma_min_value), float(cfg.sigma_max_value), float(cfg.enabled_mutate_rate),
        reserved8.data_ptr(), cfg.first_hidden, None if dest is None else dest.data_ptr(), bits.data_ptr(),
        before.data_ptr(), count.data_ptr(), top.data_ptr(), None if genes.map is None else genes.map.data_ptr(),
        *rep_args, threads)
    genes.bits, genes.before, genes.count, genes.top = bits, before, count, top
    return child, request.bool() & ~granted.bool(), genes


class GeneBits:
    """Gene bitsets of a set of genomes ``conn [..., N, N]`` (flattened to rows), with their
    weights and sigmas, for ``gene_distances``. ``runs``: of those runs of ``conn [R, P, N, N]``
    only (the tensors are read in place, not copied). ``alive`` (one flag per row): rows not
    alive (dead species' slots) get no genes, unread."""

    def __init__(self, conn: Tensor, weight: Tensor, sigma: Tensor, runs: Tensor | None = None,
                 alive: Tensor | None = None) -> None:
        _require(conn, weight)
        self._bind(weight, sigma, runs)
        c = conn.reshape(-1, self.nn).contiguous()
        M = self.rows
        live = None if alive is None else alive.reshape(-1).to(torch.uint8).contiguous()
        if live is not None and live.numel() != M:
            raise ValueError(f"alive has {live.numel()} flags for {M} rows")
        self.bits = torch.empty(M, self.words, dtype=torch.int64)
        self.before = torch.empty(M, self.words, dtype=torch.int64)  # genes in the words before
        self.count = torch.empty(M, dtype=torch.int64)
        self.top = torch.empty(M, dtype=torch.int64)
        _lib.gene_bits(c.data_ptr(), None if self.map is None else self.map.data_ptr(),
                       None if live is None else live.data_ptr(), M, self.nn, self.words,
                       self.bits.data_ptr(), self.before.data_ptr(), self.count.data_ptr(), self.top.data_ptr(),
                       torch.get_num_threads())

    def _bind(self, weight: Tensor, sigma: Tensor, runs: Tensor | None) -> None:
        """The genomes' weights and sigmas (``[R, P, N, N]``, ``[R, P]``), and the row map."""
        N = weight.shape[-1]
        self.nn = N * N
        self.words = (self.nn + 63) // 64
        self.weight = weight.reshape(-1, self.nn).contiguous()
        self.sigma = sigma.reshape(-1).to(weight.dtype).contiguous()
        self.map: Tensor | None = None  # the weight and sigma row of each bitset row
        if runs is not None:
            P = weight.shape[1]
            self.map = (runs.to(torch.int64).cpu().unsqueeze(1) * P + torch.arange(P)).flatten().contiguous()
        self.rows = self.weight.shape[0] if self.map is None else self.map.shape[0]
        # breed's closest representatives (``reps=``), and of which: (bits, rep_conn, alive)
        self.nearest: Tensor | None = None
        self.nearest_to: tuple[GeneBits, Tensor, Tensor] | None = None


def found_species(founded: Tensor, n_founded: Tensor, generation: int, alive: Tensor, best_fitness: Tensor,
                  last_improved: Tensor, created: Tensor, ident: Tensor, next_id: Tensor) -> None:
    """Record, in place, the species ``assign_species`` founded (run ``r``'s in slots
    ``founded[r, :n_founded[r]]``, all below ``S``): alive, no best fitness yet, created and
    improved in ``generation``, numbered from the run's ``next_id`` on, which advances. The
    species state tensors (``[R, S]``, ``next_id [R]``) must be contiguous CPU tensors of
    their usual dtypes (bool, float64, int64)."""
    R, S = alive.shape
    state = (alive, best_fitness, last_improved, created, ident, next_id)
    want = (torch.bool, torch.float64, torch.int64, torch.int64, torch.int64, torch.int64)
    if any(t.dtype != d or not t.is_contiguous() or t.device.type != "cpu" for t, d in zip(state, want, strict=True)):
        raise ValueError("found_species takes contiguous CPU species state tensors of their usual dtypes")
    f, n = founded.to(torch.int64).contiguous(), n_founded.to(torch.int64).contiguous()
    if _lib.found_species(f.data_ptr(), n.data_ptr(), R, f.shape[1], S, int(generation),
                          *(t.data_ptr() for t in state)):
        raise ValueError(f"a founded slot is beyond the {S} slots: grow the state first")


def put_rows(dst: Tensor, idx: Tensor, src: Tensor) -> None:
    """``dst[idx] = src`` along the first dimension, whole rows by ``memcpy`` (CPU; ``dst``
    contiguous). Indexed assignment copies element by element, 2x slower on a population's
    representatives."""
    if not kernel_available():
        raise RuntimeError("the C breeding kernels are unavailable; use dst[idx] = src")
    if dst.device.type != "cpu" or not dst.is_contiguous() or src.dtype != dst.dtype:
        raise ValueError(f"put_rows takes a contiguous CPU dst and a src of its dtype, got {dst.dtype} on "
                         f"{dst.device} and {src.dtype}")
    rows = idx.to(torch.int64).cpu().contiguous()
    if tuple(src.shape) != (rows.numel(), *dst.shape[1:]):
        raise ValueError(f"src has shape {tuple(src.shape)}, expected {(rows.numel(), *dst.shape[1:])}")
    s = src.contiguous()
    row_bytes = dst[0].numel() * dst.element_size() if dst.shape[0] else 0
    if _lib.put_rows(dst.data_ptr(), s.data_ptr(), rows.data_ptr(), rows.numel(), dst.shape[0], row_bytes):
        raise IndexError(f"put_rows: an index is outside [0, {dst.shape[0]})")


def touched_nodes(genes: GeneBits, alive: Tensor) -> Tensor:
    """``[R, N]`` bool: node slots touched by a gene of a living row, ``alive[R, S]``, of the
    representatives' bitsets ``genes`` (``R x S`` rows)."""
    R, S = alive.shape
    N = math.isqrt(genes.nn)
    if genes.rows != R * S:
        raise ValueError(f"genes has {genes.rows} rows, alive flags {R} x {S}")
    out = torch.empty(R, N, dtype=torch.bool)
    a = alive.to(torch.uint8).contiguous()
    _lib.touched_nodes(genes.bits.data_ptr(), a.data_ptr(), R, S, genes.words, N, out.data_ptr())
    return out


def _coefficients(cfg: NEATConfig) -> Tensor:
    return torch.tensor([cfg.compatibility_excess_coefficient, cfg.compatibility_disjoint_coefficient,
                         cfg.compatibility_weight_coefficient, cfg.compatibility_sigma_coefficient,
                         cfg.compatibility_normalize_min_genes], dtype=torch.float64)


def _genes_args(g: GeneBits) -> list[int]:
    return [g.bits.data_ptr(), g.before.data_ptr(), g.count.data_ptr(), g.top.data_ptr(), g.weight.data_ptr(),
            g.sigma.data_ptr(), None if g.map is None else g.map.data_ptr()]


def gene_distances(a: GeneBits, rows_a: Tensor, b: GeneBits, rows_b: Tensor, cfg: NEATConfig) -> Tensor:
    """Distances ``[R, Ka, Kb]`` (float64) between rows ``rows_a[R, Ka]`` of ``a`` and
    ``rows_b[R, Kb]`` of ``b`` (flat row indices), as ``evolution.distance.distance``."""
    R, Ka = rows_a.shape
    Kb = rows_b.shape[1]
    out = torch.empty(R, Ka, Kb, dtype=torch.float64)
    if R * Ka * Kb == 0:
        return out
    ra, rb, coef = rows_a.contiguous(), rows_b.contiguous(), _coefficients(cfg)
    getattr(_lib, f"distances_{_sfx(a.weight.dtype)}")(
        *_genes_args(a), ra.data_ptr(), Ka, *_genes_args(b), rb.data_ptr(), Kb, R, a.nn, a.words,
        coef.data_ptr(), out.data_ptr(), torch.get_num_threads())
    return out


def assign_species(genes: GeneBits, reps: GeneBits, alive: Tensor, cfg: NEATConfig,
                   nearest: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor]:
    """``speciate``'s assignment for genomes ``genes`` (``R x P`` rows) and representatives
    ``reps`` (``R x S`` rows, ``alive[R, S]``): the closest living representative within the
    threshold, else a new species founded in genome order (``evolution.speciate``).

    Returns ``(species [R, P], founded [R, P], n_founded [R])``: run ``r``'s new species are
    in slots ``founded[r, :n_founded[r]]``, in founding order; a slot >= S asks for growth.
    ``nearest[R, P]``: each genome's closest representative (-1: none), already found by
    ``breed(..., reps=)``; only the founding is left."""
    R, S = alive.shape
    P = genes.count.shape[0] // R
    species = torch.empty(R, P, dtype=torch.int64)
    founded = torch.zeros(R, P, dtype=torch.int64)
    n_founded = torch.empty(R, dtype=torch.int64)
    taken = torch.empty(R, S + P, dtype=torch.uint8)
    alive8, coef = alive.to(torch.uint8).contiguous(), _coefficients(cfg)
    near = None if nearest is None else nearest.to(torch.int64).contiguous()
    getattr(_lib, f"assign_species_{_sfx(genes.weight.dtype)}")(
        *_genes_args(genes), *_genes_args(reps), alive8.data_ptr(), R, P, S, genes.nn, genes.words,
        coef.data_ptr(), float(cfg.compatibility_threshold), species.data_ptr(), founded.data_ptr(),
        n_founded.data_ptr(), taken.data_ptr(), None if near is None else near.data_ptr(), torch.get_num_threads())
    return species, founded, n_founded
