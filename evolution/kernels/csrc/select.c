/* Parent selection, species representatives and offspring allocation (see select.h;
   evolution.kernels.select documents them), a run at a time, with the reference's draws and
   arithmetic, so the results are the same bit for bit. */
#include "select.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "counter_rng.h"

#define RANK_SORT_MAX 512
/* idx[0..n) sorted by f descending, ties in index order (a stable sort). Up to RANK_SORT_MAX
   by counting each element's rank: n * n comparisons, but branch-free vector loops, faster
   than a merge sort's unpredictable branches at a run's few hundred genomes; beyond, a
   merge sort (tmp: n more). */
static void sort_by_fitness(const double *f, int64_t n, int64_t *idx, int64_t *tmp) {
    if (n <= RANK_SORT_MAX) {
        for (int64_t p = 0; p < n; ++p) {
            const double fp = f[p];
            int64_t rank = 0;
            _Pragma("omp simd reduction(+:rank)")
            for (int64_t q = 0; q < n; ++q) rank += (f[q] > fp) | ((f[q] == fp) & (q < p));
            idx[rank] = p;
        }
        return;
    }
    for (int64_t p = 0; p < n; ++p) idx[p] = p;
    for (int64_t width = 1; width < n; width *= 2) {
        for (int64_t lo = 0; lo < n; lo += 2 * width) {
            const int64_t mid = lo + width < n ? lo + width : n, hi = lo + 2 * width < n ? lo + 2 * width : n;
            int64_t i = lo, j = mid, k = lo;
            while (i < mid && j < hi) tmp[k++] = f[idx[j]] > f[idx[i]] ? idx[j++] : idx[i++];
            while (i < mid) tmp[k++] = idx[i++];
            while (j < hi) tmp[k++] = idx[j++];
        }
        memcpy(idx, tmp, n * sizeof(int64_t));
    }
}
static inline int64_t pick_rank(double u, int64_t n) { /* (u * n).long().clamp_max(n - 1).clamp_min(0) */
    int64_t k = (int64_t)(u * (double)n);
    k = k > n - 1 ? n - 1 : k;
    return k < 0 ? 0 : k;
}
/* reproduce's selection, run by run. survivors[R, S], counts[R, S] (offspring per slot). */
void select_parents(const select_params *cfg, const select_parents_io *io) {
    const double *fitness = io->fitness;
    const double survival = cfg->survival, inter_prob = cfg->inter_prob, cross_prob = cfg->cross_prob;
    const int64_t *species = io->species, *counts = io->counts, *keys = io->keys, *base = io->base;
    const uint8_t *survivors = io->survivors, *champions = io->champions;
    const int64_t R = io->R, P = io->P, S = io->S, elitism = cfg->elitism, elitism_min = cfg->elitism_min;
    const int survival_neatc = cfg->survival_neatc, threads = io->threads;
    int64_t *first = io->first, *second = io->second;
    uint8_t *do_cross = io->do_cross, *elite = io->elite;
    _Pragma("omp parallel for schedule(static) num_threads(threads)")
    for (int64_t r = 0; r < R; ++r) {
        const double *f = fitness + r * P;
        const int64_t *sp = species + r * P, *cnt = counts + r * S;
        const uint8_t *sv = survivors + r * S;
        const uint64_t key = (uint64_t)keys[r], b0 = (uint64_t)base[r];
        int64_t *buf = malloc((5 * P + 4 * (S + 1)) * sizeof(int64_t) + 5 * P * sizeof(double));
        int64_t *kspecies = buf, *by_fit = buf + P, *order = buf + 2 * P, *tmp = buf + 3 * P, *parents = buf + 4 * P;
        int64_t *size = buf + 5 * P, *start = size + (S + 1), *npar = start + (S + 1), *fill = npar + (S + 1);
        double *u = (double *)(fill + (S + 1));
        for (int64_t p = 0; p < P; ++p) kspecies[p] = sv[sp[p]] ? sp[p] : S; /* dead species' members last */
        sort_by_fitness(f, P, by_fit, tmp);
        memset(size, 0, (S + 1) * sizeof(int64_t));
        for (int64_t p = 0; p < P; ++p) ++size[kspecies[p]];
        int64_t at = 0;
        for (int64_t s = 0; s <= S; ++s) { fill[s] = at; at += size[s]; }
        for (int64_t q = 0; q < P; ++q) { const int64_t g = by_fit[q]; order[fill[kspecies[g]]++] = g; }
        at = 0;
        for (int64_t s = 0; s < S; ++s) {
            start[s] = at; at += size[s];
            /* torch.ceil(survival * size): float32 arithmetic (a long tensor times a Python float);
               [NEATC] floor(survival * size + 1) in double, at most the species */
            const int64_t n = survival_neatc ? (int64_t)floor((double)size[s] * survival + 1.0)
                                             : (int64_t)ceilf((float)size[s] * (float)survival);
            const int64_t m = survival_neatc ? (n > size[s] ? size[s] : n) : (n < 1 ? 1 : n);
            npar[s] = size[s] > 0 ? m : 0;
        }
        start[S] = 0; npar[S] = 0;
        int64_t n_parents = 0; /* every species' parents, in sorted order, for interspecies mating */
        for (int64_t q = 0; q < P; ++q) {
            const int64_t s = kspecies[order[q]];
            if (q - start[s] < npar[s]) parents[n_parents++] = q;
        }
        const int64_t n_all = n_parents > 0 ? n_parents : 1;
        /* the run's SELECTION_DRAWS blocks of P uniforms, in one vector loop */
        _Pragma("omp simd")
        for (int64_t c = 0; c < 5 * P; ++c) u[c] = uniform01(key, b0 + c);
        int64_t os = 0, end = S > 0 ? cnt[0] : 0;
        for (int64_t k = 0; k < P; ++k) {
            while (os < S - 1 && end <= k) end += cnt[++os]; /* searchsorted(ends, k, right), clamped */
            const int64_t pos = k - (end - cnt[os]), o_start = start[os], o_size = size[os], o_par = npar[os];
            const int64_t row = r * P + k;
            const int is_elite = pos < elitism && pos < o_size && o_size >= elitism_min;
            const double u1 = u[k], u2 = u[P + k], u3 = u[2 * P + k], u4 = u[3 * P + k], u5 = u[4 * P + k];
            const int64_t p1 = is_elite ? order[o_start + pos] : order[o_start + pick_rank(u1, o_par)];
            int64_t p2 = order[o_start + pick_rank(u2, o_par)];
            int64_t pick = (int64_t)(u3 * (double)n_all);
            pick = pick > n_all - 1 ? n_all - 1 : pick;
            const int64_t any_parent = order[n_parents > 0 ? parents[pick] : P - 1];
            if (u4 < inter_prob) p2 = any_parent;
            const int cross = !is_elite && u5 < cross_prob && p1 != p2;
            const int second_fitter = f[p2] > f[p1];
            first[row] = cross && second_fitter ? p2 : p1;
            second[row] = cross ? (second_fitter ? p1 : p2) : p1;
            do_cross[row] = (uint8_t)cross; elite[row] = (uint8_t)is_elite;
            if (champions && champions[r]) { /* delta coding: clones of the champion, the last as it is */
                first[row] = second[row] = order[o_start]; do_cross[row] = 0;
                elite[row] = pos == cnt[os] - 1;
            }
        }
        free(buf);
    }
}
/* speciate's representatives: per species slot, the member with the highest score (the last on
   a tie), its conn/weight/sigma rows copied; slots without members zeroed. runs: the genomes are
   those runs of a larger population. */
#define DEFINE_REPS(T, SFX)                                                                       \
void choose_representatives_##SFX(const reps_io *io) {                                           \
    const int64_t *species = io->species, *runs = io->runs, *keys = io->keys, *base = io->base;  \
    const uint8_t *conn = io->conn;                                                               \
    const T *weight = (const T *)io->weight, *sigma = (const T *)io->sigma;                      \
    const int64_t R = io->R, P = io->P, S = io->S, NN = io->NN;                                   \
    const int threads = io->threads;                                                              \
    uint8_t *alive = io->alive, *rep_conn = io->rep_conn;                                         \
    T *rep_weight = (T *)io->rep_weight, *rep_sigma = (T *)io->rep_sigma;                         \
    _Pragma("omp parallel for schedule(static) num_threads(threads)")                             \
    for (int64_t r = 0; r < R; ++r) {                                                             \
        const uint64_t key = (uint64_t)keys[r], b0 = (uint64_t)base[r];                          \
        double *best = malloc(S * sizeof(double)); int64_t *rep = malloc(S * sizeof(int64_t));   \
        for (int64_t s = 0; s < S; ++s) { best[s] = -1.0; rep[s] = -1; }                          \
        for (int64_t p = 0; p < P; ++p) {                                                         \
            const int64_t s = species[r * P + p];                                                 \
            const double u = uniform01(key, b0 + p);                                              \
            if (u >= best[s]) { best[s] = u; rep[s] = p; }                                        \
        }                                                                                         \
        for (int64_t s = 0; s < S; ++s) {                                                         \
            const int64_t q = r * S + s, g = (runs ? runs[r] : r) * P + rep[s];                   \
            alive[q] = rep[s] >= 0;                                                               \
            if (rep[s] >= 0) {                                                                    \
                memcpy(rep_conn + q * NN, conn + g * NN, NN);                                     \
                memcpy(rep_weight + q * NN, weight + g * NN, NN * sizeof(T));                     \
                rep_sigma[q] = sigma[g];                                                          \
            } else {                                                                              \
                memset(rep_conn + q * NN, 0, NN); memset(rep_weight + q * NN, 0, NN * sizeof(T)); \
                rep_sigma[q] = (T)0;                                                              \
            }                                                                                     \
        }                                                                                         \
        free(best); free(rep);                                                                    \
    }                                                                                             \
}
DEFINE_REPS(float, f32)
DEFINE_REPS(double, f64)

/* The factor allocate_offspring's sums take the run's fitness values by: 1, or where sums of P
   values and differences of two could overflow (|f| > DBL_MAX / 4P), the power of two 2^-e with
   2^e > 4P. A power of two scales exactly, so the quotas are the same as with unbounded
   exponents; 1 leaves every smaller fitness bit for bit as before. */
static double share_scale(const double *f, int64_t P) {
    double top = 0.0;
    for (int64_t p = 0; p < P; ++p) top = fabs(f[p]) > top ? fabs(f[p]) : top;
    int e;
    frexp(4.0 * (double)P, &e);
    return top > DBL_MAX / (4.0 * (double)P) ? ldexp(1.0, -e) : 1.0;
}

/* Each living species' place among the living (reproduce.species_order): its best fitness sf
   descending, ties by slot; -1 for the dead. */
static void rank_living(const uint8_t *al, const double *sf, int64_t S, int64_t *rank) {
    for (int64_t s = 0; s < S; ++s) {
        rank[s] = -1;
        if (!al[s]) continue;
        int64_t k = 0;
        for (int64_t t = 0; t < S; ++t) k += al[t] && (sf[t] > sf[s] || (sf[t] == sf[s] && t < s));
        rank[s] = k;
    }
}
/* reproduce's species_offspring (species_records, allocate_offspring, population_stagnation),
   run by run, with the reference's arithmetic: species' best fitness, obliteration, stagnation,
   the species_elitism best species protected (stable descending order), stagnant species removed
   or penalised, then offspring by explicit fitness sharing and largest remainder, then the run's
   record and delta coding. The shares' total is summed in slot order, as the reference's cumsum. */
void species_offspring(const select_params *cfg, const offspring_io *io) {
    const double *fitness = io->fitness, *best_in = io->best_in, *run_best_in = io->run_best_in;
    const int64_t *species = io->species, *last_in = io->last_in, *created = io->created;
    const int64_t *run_stale_in = io->run_stale_in;
    const uint8_t *alive = io->alive, *obl_in = io->obl_in;
    const int64_t R = io->R, P = io->P, S = io->S, generation = io->generation;
    const int64_t max_stagnation = cfg->max_stagnation, species_elitism = cfg->species_elitism;
    const int64_t obliterate_interval = cfg->obliterate_interval, obliterate_min_age = cfg->obliterate_min_age;
    const int64_t pop_stagnation = cfg->pop_stagnation, clock_before = cfg->clock_before;
    const double penalty = cfg->penalty;
    const int threads = io->threads;
    double *best_out = io->best_out, *run_best_out = io->run_best_out;
    int64_t *last_out = io->last_out, *run_stale_out = io->run_stale_out, *counts = io->counts;
    uint8_t *obl_out = io->obl_out, *survivors = io->survivors, *delta = io->delta;
    _Pragma("omp parallel for schedule(static) num_threads(threads)")
    for (int64_t r = 0; r < R; ++r) {
        const double *f = fitness + r * P;
        const int64_t *sp = species + r * P;
        const uint8_t *al = alive + r * S;
        double *best = best_out + r * S; int64_t *last = last_out + r * S, *cnt = counts + r * S;
        uint8_t *sv = survivors + r * S, *obl = obl_out + r * S;
        double *buf = malloc(6 * S * sizeof(double) + 2 * S);
        double *sf = buf, *size = buf + S, *total_f = buf + 2 * S, *share = buf + 3 * S, *frac = buf + 4 * S;
        int64_t *rank = (int64_t *)(buf + 5 * S); /* among the living: sf descending, ties by slot */
        uint8_t *prot = (uint8_t *)(buf + 6 * S), *pen = prot + S; /* protected; penalised */
        double f_min = INFINITY;
        const double scale = share_scale(f, P);
        for (int64_t s = 0; s < S; ++s) { sf[s] = -INFINITY; size[s] = 0.0; total_f[s] = 0.0; }
        for (int64_t p = 0; p < P; ++p) { /* genome order, as scatter_add */
            const int64_t s = sp[p];
            if (f[p] > sf[s]) sf[s] = f[p];
            size[s] += 1.0; total_f[s] += f[p] * scale;
            if (f[p] < f_min) f_min = f[p];
        }
        f_min *= scale;
        int64_t n_alive = 0;
        for (int64_t s = 0; s < S; ++s) {
            const int improved = al[s] && sf[s] > best_in[r * S + s];
            best[s] = improved ? sf[s] : best_in[r * S + s];
            last[s] = improved ? generation : last_in[r * S + s];
            obl[s] = obl_in[r * S + s];
            n_alive += al[s] != 0;
        }
        if (obliterate_interval > 0 && (generation + 1) % obliterate_interval == 0 && n_alive > 0) {
            rank_living(al, sf, S, rank);
            int64_t pick = -1, at = -1; /* the worst old enough, else the best */
            for (int64_t s = 0; s < S; ++s)
                if (al[s] && (rank[s] == 0 || generation - created[r * S + s] + 1 >= obliterate_min_age) && rank[s] > at) {
                    pick = s; at = rank[s];
                }
            obl[pick] = 1;
        }
        /* protected: the species_elitism first in (alive ? sf : -inf) descending, ties by slot */
        memset(prot, 0, S);
        for (int64_t k = 0; k < species_elitism && k < S; ++k) {
            int64_t pick = -1; double top = 0.0;
            for (int64_t s = 0; s < S; ++s) {
                if (prot[s]) continue;
                const double v = al[s] ? sf[s] : -INFINITY;
                if (pick < 0 || v > top) { pick = s; top = v; }
            }
            prot[pick] = 1;
        }
        int any_share = 0;
        for (int64_t s = 0; s < S; ++s) {
            const int64_t clock = clock_before ? last_in[r * S + s] : last[s]; /* [NEATC]: before the update */
            const int stagnant = al[s] && (generation - clock >= max_stagnation || obl[s]);
            if (penalty > 0.0) { sv[s] = al[s]; pen[s] = stagnant && !prot[s]; }
            else { sv[s] = al[s] && (!stagnant || prot[s]); pen[s] = 0; }
        }
        f_min = f_min > 0.0 ? 0.0 : f_min;
        for (int64_t s = 0; s < S; ++s) {
            double v = sv[s] ? total_f[s] / (size[s] < 1.0 ? 1.0 : size[s]) - f_min : 0.0;
            v = pen[s] ? v * penalty : v;
            share[s] = v < 0.0 ? 0.0 : v;
            any_share |= share[s] > 0.0;
        }
        double total = 0.0, base_sum = 0.0;
        for (int64_t s = 0; s < S; ++s) {
            if (!any_share) share[s] = sv[s] ? 1.0 : 0.0;
            total += share[s];
        }
        total = total < 1e-300 ? 1e-300 : total;
        for (int64_t s = 0; s < S; ++s) {
            const double quota = (double)P * share[s] / total, base = floor(quota);
            base_sum += base; frac[s] = sv[s] ? quota - base : -1.0;
            cnt[s] = (int64_t)base;
        }
        const int64_t remainder = (int64_t)round((double)P - base_sum);
        for (int64_t s = 0; s < S; ++s) {
            if (!sv[s]) { cnt[s] = 0; continue; }
            int64_t k = 0; /* position in frac descending, ties by slot */
            for (int64_t t = 0; t < S; ++t) k += frac[t] > frac[s] || (frac[t] == frac[s] && t < s);
            cnt[s] += k < remainder;
        }
        /* the run's record; delta coding */
        double top = -INFINITY;
        for (int64_t p = 0; p < P; ++p) top = f[p] > top ? f[p] : top;
        const int better = top > run_best_in[r];
        run_best_out[r] = better ? top : run_best_in[r];
        run_stale_out[r] = better ? 0 : run_stale_in[r] + 1;
        delta[r] = pop_stagnation > 0 && run_stale_out[r] >= pop_stagnation;
        if (delta[r]) {
            rank_living(al, sf, S, rank);
            run_stale_out[r] = 0;
            for (int64_t s = 0; s < S; ++s) {
                const int first = al[s] && rank[s] == 0, second = al[s] && rank[s] == 1;
                cnt[s] = first ? (n_alive >= 2 ? P / 2 : P) : (second ? P - P / 2 : 0);
                sv[s] = first || second;
                if (first || second) last[s] = generation;
            }
        }
        free(buf);
    }
}
