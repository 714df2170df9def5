/* The breeding step and species assignment for one dtype T (suffix SFX), included once per
   dtype by breed.c (see there, and breed.h for the entry points). */

#define FN(name) PASTE(name, SFX)

/* A run's parents as phase 1 reads them: the population's, or the run's copied aside
   (in place); a_idx, b_idx index its rows from row idx0. */
typedef struct {
    const T *w, *s, *m;
    const uint8_t *c, *e, *n;
    const int64_t *a_idx, *b_idx;
    int64_t idx0;
} FN(parents_);
/* A run's block of the children's arrays. */
typedef struct {
    T *w, *s, *m;
    uint8_t *c, *e, *n;
} FN(brood_);

static inline T FN(clampT_)(T x, T lo, T hi) { x = x < lo ? lo : x; return x > hi ? hi : x; }
/* A gene set's arrays, typed. */
static inline FN(genes_) FN(genes_of_)(const gene_set *s) {
    const FN(genes_) g = {s->bits, s->before, s->count, s->top, (const T *)s->weight, (const T *)s->sigma, s->map};
    return g;
}
/* Phase 1: crossover (or a copy of the first parent), then the add-node choice. */
static inline void FN(phase1_)(const breed_params *cfg, const breed_io *io, const FN(parents_) *par,
                               const FN(brood_) *ch, int64_t row0, int64_t row1) {
    const T *pw = par->w, *ps = par->s, *pm = par->m;
    const uint8_t *pc = par->c, *pe = par->e, *pn = par->n;
    const int64_t *a_idx = par->a_idx, *b_idx = par->b_idx, idx0 = par->idx0;
    T *cw = ch->w, *cs = ch->s, *cm = ch->m;
    uint8_t *cc = ch->c, *ce = ch->e, *cn = ch->n;
    const uint8_t *do_cross = io->do_cross, *active = io->active;
    int64_t *src = io->src, *dst = io->dst;
    uint8_t *request = io->request;
    const int64_t *keys = io->keys, *base = io->base, *blocks = io->blocks, P = io->P, N = io->N;
    uint64_t *gbits = io->gbits;
    const double inherit_disabled = cfg->inherit_disabled, node_add_prob = cfg->node_add_prob;
    const int64_t split_first_bias = cfg->split_first_bias, first_output = cfg->first_output;
    const int64_t NN = N * N, W = (NN + 63) / 64;
    for (int64_t row = row0; row < row1; ++row) {
        const int64_t r = row / P, p = row % P, crow = row - row0; /* child arrays: the run's block */
        const uint64_t key = (uint64_t)keys[r], b0 = (uint64_t)base[r];
        /* parents: rows of pw (a_idx, b_idx indexed from row idx0) */
        const int64_t a = a_idx[row - idx0], b = b_idx[row - idx0];
        const T *fw = pw + a * NN, *ow = pw + b * NN;
        const uint8_t *fc = pc + a * NN, *fe = pe + a * NN, *oc = pc + b * NN, *oe = pe + b * NN;
        T *w = cw + crow * NN; uint8_t *c = cc + crow * NN, *e = ce + crow * NN;
        memcpy(c, fc, NN); memcpy(cn + crow * N, pn + a * N, N);
        memcpy(w, fw, NN * sizeof(T)); /* no gene: weight 0 in every genome */
        /* mutation_num ([NEATC]), where carried: inherited as the weights are */
        const T *fm = pm ? pm + a * NN : NULL, *om = pm ? pm + b * NN : NULL;
        T *m = cm ? cm + crow * NN : NULL;
        if (m) memcpy(m, fm, NN * sizeof(T));
        uint64_t *bits = gbits + row * W; /* the child's genes: the first parent's */
        pack_bits(fc, NN, W, bits);
        int32_t genes[MAX_SLOTS];
        if (do_cross[row]) {
            const uint64_t c_from = b0 + blocks[B_FROM_OTHER] + p * NN;
            const uint64_t c_stay = b0 + blocks[B_STAYS] + p * NN;
            memset(e, 0, NN);
            const int64_t n = bits_to_slots(bits, W, genes);
            double u_from[MAX_SLOTS], u_stay[MAX_SLOTS];
            _Pragma("omp simd")
            for (int64_t g = 0; g < n; ++g) {
                u_from[g] = uniform01(key, c_from + genes[g]);
                u_stay[g] = uniform01(key, c_stay + genes[g]);
            }
            const int avg = do_cross[row] == 2; /* [NEATC] mate_multipoint_avg */
            for (int64_t g = 0; g < n; ++g) {
                const int64_t s = genes[g];
                const int matching = oc[s] != 0;
                if (matching && avg) w[s] = (T)(fw[s] + ow[s]) / (T)2;
                else if (matching && u_from[g] < 0.5) w[s] = ow[s];
                if (m && matching && avg) m[s] = (T)(fm[s] + om[s]) / (T)2;
                else if (m && matching && u_from[g] < 0.5) m[s] = om[s];
                const int dip = !fe[s] || (matching && !oe[s]);
                e[s] = !(dip && u_stay[g] < inherit_disabled);
            }
            cs[crow] = uniform01(key, b0 + blocks[B_SIGMA_PICK] + p) < 0.5 ? ps[b] : ps[a];
        } else {
            memcpy(e, fe, NN); cs[crow] = ps[a];
        }
        request[row] = 0; src[row] = 0; dst[row] = 0;
        if (active[row] && !(active[row] & 8) && uniform01(key, b0 + blocks[B_NODE_WANT] + p) < node_add_prob
            && split_first_bias >= 0) { /* [NEATC]'s choice */
            const int64_t s = split_neatc(c, e, N, uniform01(key, b0 + blocks[B_NODE_PICK] + p), split_first_bias,
                                          first_output);
            if (s >= 0) { src[row] = s / N; dst[row] = s % N; request[row] = 1; }
        } else if (active[row] && !(active[row] & 8) && uniform01(key, b0 + blocks[B_NODE_WANT] + p) < node_add_prob) {
            uint64_t on[MAX_SLOTS / 64];
            pack_bits(e, NN, W, on);
            const int64_t n = bits_to_slots(on, W, genes);
            if (n > 0) {
                const int64_t s = genes[pick_k(uniform01(key, b0 + blocks[B_NODE_PICK] + p), n)];
                src[row] = s / N; dst[row] = s % N; request[row] = 1;
            }
        }
    }
}
/* Phase 2, in place: the granted splits, add-connection, weights, sigma, enabled flags. The
   normals are drawn for the whole run at once: pass 1 makes every decision and lists each
   normal's counter with what it is for (a job), pass 2 computes them in one vector loop (a
   child has a few genes, too few to fill a vector), pass 3 applies them child by child in the
   reference's order (a new connection's initial weight before the weight mutation). */
static inline void FN(phase2_)(const breed_params *cfg, const breed_io *io, const FN(brood_) *ch, int64_t row0,
                               int64_t row1) {
    T *cw = ch->w, *cs = ch->s, *cm = ch->m;
    uint8_t *cc = ch->c, *ce = ch->e, *cn = ch->n;
    const int64_t *new_node = io->new_node, *src = io->src, *dst = io->dst;
    const uint8_t *granted = io->granted, *active = io->active;
    const int64_t *keys = io->keys, *base = io->base, *blocks = io->blocks, P = io->P, N = io->N;
    uint64_t *gbits = io->gbits;
    int64_t *gbefore = io->gbefore, *gcount = io->gcount, *gtop = io->gtop;
    const int64_t first_output = cfg->first_output, first_hidden = cfg->first_hidden, conn_tries = cfg->conn_tries;
    const int feed_forward = cfg->feed_forward, per_gene = cfg->per_gene, exclusive = cfg->exclusive;
    const int neatc = cfg->neatc, recur_split = cfg->recur_split, one_on = cfg->one_on;
    const int w_uniform = cfg->w_uniform, shared_link = cfg->shared_link;
    const double conn_add_prob = cfg->conn_add_prob, node_add_prob = cfg->node_add_prob;
    const double w_mean = cfg->w_mean, w_stdev = cfg->w_stdev, w_min = cfg->w_min, w_max = cfg->w_max;
    const double w_rate = cfg->w_rate, w_rate_sum = cfg->w_rate_sum, w_replace = cfg->w_replace;
    const double w_power = cfg->w_power, s_rate = cfg->s_rate, s_power = cfg->s_power;
    const double s_min = cfg->s_min, s_max = cfg->s_max, toggle_rate = cfg->toggle_rate;
    const double one_prob = cfg->one_prob, re_prob = cfg->re_prob, clone_link_prob = cfg->clone_link_prob;
    const int64_t NN = N * N, W = (NN + 63) / 64;
    const T mean = (T)w_mean, stdev = (T)w_stdev, lo = (T)w_min, hi = (T)w_max, power = (T)w_power;
    /* weight_init_uniform: [NP]'s bounds, mean +- 2 stdev within [min, max], in double */
    const double u_lo = fmax(w_min, w_mean - 2.0 * w_stdev), u_hi = fmin(w_max, w_mean + 2.0 * w_stdev);
    const int64_t max_jobs = (row1 - row0) * (NN + 3);
    /* conn_add_shared_weight: the run's first JOB_CONN of each slot (x2: drawn recurrent or not) */
    /* (and with mutation_num: a later one records 0) */
    int64_t *first_link = shared_link || cm ? malloc(2 * NN * sizeof(int64_t)) : NULL;
    uint8_t *w_mut = cm ? calloc(row1 - row0, 1) : NULL; /* the children whose weights mutated */
    if (first_link) for (int64_t f = 0; f < 2 * NN; ++f) first_link[f] = -1;
    uint64_t *job_counter = malloc(max_jobs * (sizeof(uint64_t) + sizeof(double) + 2 * sizeof(int32_t) + 1));
    double *job_z = (double *)(job_counter + max_jobs);
    int32_t *job_row = (int32_t *)(job_z + max_jobs), *job_slot = job_row + max_jobs;
    uint8_t *job_kind = (uint8_t *)(job_slot + max_jobs);
    int64_t n_jobs = 0;
    const uint64_t key = (uint64_t)keys[row0 / P]; /* rows row0..row1 are one run */
    for (int64_t row = row0; row < row1; ++row) {
        const int64_t r = row / P, p = row % P, crow = row - row0;
        const uint64_t b0 = (uint64_t)base[r];
        T *w = cw + crow * NN; uint8_t *c = cc + crow * NN, *e = ce + crow * NN, *nd = cn + crow * N;
        uint64_t *bits = gbits + row * W; /* = c */
        if (granted[row]) {
            const int64_t i = src[row], j = dst[row], k = new_node[row];
            const T old = w[i * N + j];
            e[i * N + j] = 0;
            w[i * N + k] = (T)1; c[i * N + k] = 1; e[i * N + k] = 1;
            w[k * N + j] = old; c[k * N + j] = 1; e[k * N + j] = 1;
            if (cm) { cm[crow * NN + i * N + k] = 0; cm[crow * NN + k * N + j] = 0; } /* [NEATC] */
            nd[k] = 1;
            bits[(i * N + k) / 64] |= 1ULL << ((i * N + k) % 64);
            bits[(k * N + j) / 64] |= 1ULL << ((k * N + j) % 64);
        }
        if (!active[row]) { bits_summary(bits, W, gbefore + row * W, gcount + row, gtop + row); continue; }
        int32_t genes[MAX_SLOTS + 1];
        int64_t n_genes = bits_to_slots(bits, W, genes);
        /* [NEATC] exclusive: add-node (its draw), else add-connection, else the rest */
        const int clone = (active[row] & 8) != 0; /* delta coding: a new link, else every weight */
        const int node_drawn = exclusive && !clone && uniform01(key, b0 + blocks[B_NODE_WANT] + p) < node_add_prob;
        const int conn_drawn = !node_drawn &&
            uniform01(key, b0 + blocks[B_CONN_WANT] + p) < (clone ? clone_link_prob : conn_add_prob);
        if (conn_drawn) {
            /* rows as bitsets: out[i] = genes i -> j; into[j] = i with a path i -> j (closure) */
            uint64_t out[MAX_ROWS] = {0}, into[MAX_ROWS] = {0}, nodes = 0, ends = 0;
            for (int64_t j = 0; j < N; ++j) nodes |= (uint64_t)(nd[j] != 0) << j;
            for (int64_t g = 0; g < n_genes; ++g) {
                const int64_t i = genes[g] / N, j = genes[g] % N;
                out[i] |= 1ULL << j; into[j] |= 1ULL << i; ends |= 1ULL << i | 1ULL << j;
            }
            if (feed_forward) /* Warshall over the genes' end nodes only (the rest have no path) */
                for (uint64_t ks = ends; ks; ks &= ks - 1) {
                    const int64_t k = __builtin_ctzll(ks);
                    const uint64_t via = into[k];
                    for (uint64_t js = ends; js; js &= js - 1) {
                        const int64_t j = __builtin_ctzll(js);
                        into[j] |= via & (0 - (into[j] >> k & 1));
                    }
                }
            const uint64_t targets = nodes & ~((1ULL << first_output) - 1); /* not into inputs */
            uint64_t cand[MAX_ROWS];
            int64_t n = 0;
            uint64_t reach[MAX_ROWS] = {0}; /* [NEATC]: reach[i] = j with a path j -> i of enabled genes */
            const uint64_t outputs = (first_hidden >= 64 ? ~0ULL : (1ULL << first_hidden) - 1) & ~((1ULL << first_output) - 1);
            const int want_rec = (active[row] & 4) != 0;
            if (recur_split) {
                uint64_t on_ends = 0;
                for (int64_t g = 0; g < n_genes; ++g) {
                    if (!e[genes[g]]) continue;
                    const int64_t i = genes[g] / N, j = genes[g] % N;
                    reach[j] |= 1ULL << i; on_ends |= 1ULL << i | 1ULL << j;
                }
                for (uint64_t ks = on_ends; ks; ks &= ks - 1) {
                    const int64_t k = __builtin_ctzll(ks);
                    const uint64_t via = reach[k];
                    for (uint64_t js = on_ends; js; js &= js - 1) {
                        const int64_t j = __builtin_ctzll(js);
                        reach[j] |= via & (0 - (reach[j] >> k & 1));
                    }
                }
            }
            for (int64_t i = 0; i < N; ++i) {
                uint64_t m = (nodes >> i & 1) ? targets & ~out[i] : 0;
                if (feed_forward) m &= ~(into[i] | 1ULL << i); /* no self loop, no path j -> i */
                if (recur_split) { /* i -> j recurrent: j == i, a path j -> i, or an output end */
                    const uint64_t rec = (outputs >> i & 1) ? ~0ULL : (reach[i] | 1ULL << i | outputs);
                    m &= want_rec ? rec : ~rec;
                }
                cand[i] = m; n += __builtin_popcountll(m);
            }
            int64_t s = -1;
            if (n > 0 && conn_tries > 0) { /* [NEATC] tries: mutate.py's _pick_by_tries, op by op */
                const int loops = recur_split && want_rec;
                const int64_t nn = __builtin_popcountll(nodes), nt = __builtin_popcountll(targets);
                int64_t total = 0;
                for (int64_t i = 0; i < N; ++i)
                    total += __builtin_popcountll(cand[i]) + (loops ? (int64_t)(cand[i] >> i & 1) * nn : 0);
                const int64_t pairs = nn * nt * (loops ? 2 : 1);
                int64_t k = tries_law(uniform01(key, b0 + blocks[B_CONN_PICK] + p), total, pairs, conn_tries);
                if (k >= 0) {
                    for (int64_t i = 0; i < N && s < 0; ++i)
                        for (uint64_t m = cand[i]; m; m &= m - 1) {
                            const int64_t j = __builtin_ctzll(m);
                            const int64_t share = 1 + (loops && j == i ? nn : 0);
                            if (k < share) { s = i * N + j; break; }
                            k -= share;
                        }
                }
            } else if (n > 0) {
                int64_t k = pick_k(uniform01(key, b0 + blocks[B_CONN_PICK] + p), n), i = 0;
                while (k >= __builtin_popcountll(cand[i])) k -= __builtin_popcountll(cand[i++]);
                s = i * N + kth_bit(cand[i], k);
            }
            if (s >= 0) {
                job_counter[n_jobs] = b0 + blocks[B_CONN_INIT] + 2 * p; job_row[n_jobs] = (int32_t)crow;
                int later = 0;
                if (first_link) { /* shared_link: a later one draws the first one's weight (its counter) */
                    int64_t *first = first_link + (recur_split && want_rec) * NN + s;
                    later = *first >= 0;
                    if (!later) *first = n_jobs;
                    else if (shared_link) job_counter[n_jobs] = job_counter[*first];
                }
                job_slot[n_jobs] = (int32_t)s; job_kind[n_jobs++] = later ? JOB_CONN_LATER : JOB_CONN;
                c[s] = 1; e[s] = 1; bits[s / 64] |= 1ULL << (s % 64);
                genes[n_genes++] = (int32_t)s;
            }
        }
        if (clone ? !conn_drawn : (!exclusive || (!node_drawn && !conn_drawn))) {
        const int genome_hit = uniform01(key, b0 + blocks[B_W_GENOME] + p) < w_rate || clone;
        const uint64_t c_u = b0 + blocks[B_W_U] + p * NN, c_z = b0 + blocks[B_W_NOISE] + 2 * p * NN;
        if (w_mut) w_mut[crow] = neatc ? genome_hit : (per_gene || genome_hit);
        if (neatc && genome_hit) { /* [NEATC] mutate_link_weights: genes in slot order */
            n_genes = bits_to_slots(bits, W, genes);
            const int severe = (active[row] & 2) != 0;
            const double cnt = (double)n_genes;
            for (int64_t g = 0; g < n_genes; ++g) {
                const double choice = uniform01(key, c_u + genes[g]);
                const double half = uniform01(key, c_z + 2 * (uint64_t)genes[g] + 1);
                const int tail = cnt >= 10.0 && (double)g > cnt * 0.8;
                const double gauss = severe ? 0.3 : (tail ? 0.5 : 0.0);
                const double cold = severe ? 0.1 : (tail ? 0.3 : (half > 0.5 ? -0.1 : 0.0));
                job_counter[n_jobs] = c_z + 2 * (uint64_t)genes[g]; job_row[n_jobs] = (int32_t)crow;
                job_slot[n_jobs] = genes[g]; job_kind[n_jobs] = choice > gauss ? JOB_NC_PERTURB : JOB_NC_REPLACE;
                n_jobs += choice > cold;
            }
        } else if (per_gene || genome_hit) {
            /* which genes change, and how */
            double u[MAX_SLOTS + 1];
            _Pragma("omp simd")
            for (int64_t g = 0; g < n_genes; ++g) u[g] = uniform01(key, c_u + genes[g]);
            for (int64_t g = 0; g < n_genes; ++g) {
                int h, rep;
                if (per_gene) { const int perturb = u[g] < w_rate;
                                rep = !perturb && u[g] < w_rate_sum; h = perturb || rep; }
                else { rep = u[g] < w_replace; h = 1; }
                job_counter[n_jobs] = c_z + 2 * (uint64_t)genes[g]; job_row[n_jobs] = (int32_t)crow;
                job_slot[n_jobs] = genes[g]; job_kind[n_jobs] = rep ? JOB_REPLACE : JOB_PERTURB;
                n_jobs += h;
            }
        }
        if (!clone && uniform01(key, b0 + blocks[B_S_WANT] + p) < s_rate) {
            job_counter[n_jobs] = b0 + blocks[B_S_NOISE] + 2 * p; job_row[n_jobs] = (int32_t)crow;
            job_slot[n_jobs] = 0; job_kind[n_jobs++] = JOB_SIGMA;
        }
        const uint64_t c_t = b0 + blocks[B_TOGGLE] + p * NN;
        uint8_t flip[MAX_SLOTS + 1];
        _Pragma("omp simd")
        for (int64_t g = 0; g < n_genes; ++g) flip[g] = uniform01(key, c_t + genes[g]) < toggle_rate;
        for (int64_t g = 0; g < n_genes; ++g) e[genes[g]] ^= flip[g] & !clone;
        if (one_on && !clone) { /* [NEATC] toggle one gene, then re-enable the first disabled one */
            int32_t sorted[MAX_SLOTS + 1];
            const int64_t n_sorted = bits_to_slots(bits, W, sorted);
            if (uniform01(key, b0 + blocks[B_ONE_WANT] + p) < one_prob && n_sorted > 0) {
                const int64_t s = sorted[pick_k(uniform01(key, b0 + blocks[B_ONE_PICK] + p), n_sorted)];
                if (!e[s]) e[s] = 1;
                else {
                    const int64_t i = s / N;
                    int others = 0;
                    for (int64_t j = 0; j < N; ++j) others += i * N + j != s && c[i * N + j] && e[i * N + j];
                    if (others) e[s] = 0;
                }
            }
            if (uniform01(key, b0 + blocks[B_REENABLE] + p) < re_prob)
                for (int64_t g = 0; g < n_sorted; ++g) if (!e[sorted[g]]) { e[sorted[g]] = 1; break; }
        }
        }
        bits_summary(bits, W, gbefore + row * W, gcount + row, gtop + row);
    }
    _Pragma("omp simd")
    for (int64_t q = 0; q < n_jobs; ++q) job_z[q] = normal_at(key, job_counter[q]);
    for (int64_t q = 0; q < n_jobs; ++q) {
        T *w = cw + job_row[q] * NN;
        const int64_t s = job_slot[q];
        const T zt = (T)job_z[q];
        if (job_kind[q] <= JOB_CONN_LATER) {
            T init = zt * stdev; init = init + mean;
            if (w_uniform) init = (T)(u_lo + (u_hi - u_lo) * uniform01(key, job_counter[q]));
            w[s] = FN(clampT_)(init, lo, hi);
            if (cm) cm[job_row[q] * NN + s] = job_kind[q] == JOB_CONN ? w[s] : (T)0;
        } else if (job_kind[q] == JOB_SIGMA) {
            T step = zt * (T)s_power;
            cs[job_row[q]] = FN(clampT_)(cs[job_row[q]] + step, (T)s_min, (T)s_max);
        } else if (job_kind[q] >= JOB_NC_PERTURB) { /* a step uniform in +-power */
            const T step = (T)((2.0 * uniform01(key, job_counter[q]) - 1.0) * w_power);
            w[s] = FN(clampT_)(job_kind[q] == JOB_NC_PERTURB ? w[s] + step : step, lo, hi);
        } else {
            T fresh = zt * stdev; fresh = fresh + mean;
            if (w_uniform) fresh = (T)(u_lo + (u_hi - u_lo) * uniform01(key, job_counter[q]));
            T step = zt * power; T pert = w[s] + step;
            w[s] = FN(clampT_)(job_kind[q] == JOB_REPLACE ? fresh : pert, lo, hi);
        }
    }
    /* [NEATC] mutate_link_weights: every gene's mutation_num is its weight (0 where no gene) */
    if (w_mut)
        for (int64_t crow = 0; crow < row1 - row0; ++crow)
            if (w_mut[crow]) memcpy(cm + crow * NN, cw + crow * NN, NN * sizeof(T));
    free(job_counter); free(first_link); free(w_mut);
}
/* The closest living representative of run r within thr for genome rows row0 .. row0 + P of
   g (-1: none; first slot on ties): out[0 .. P). With ident (the species' numbers [R, S]):
   [NEATC]'s rule instead, the first within thr in the order the species were founded. */
static void FN(nearest_reps_)(FN(genes_) g, int64_t row0, int64_t P, FN(genes_) rep, const uint8_t *alive,
                               int64_t r, int64_t S, int64_t NN, int64_t W, const double *coef, double thr,
                               int64_t *out, const int64_t *ident) {
    int64_t live[S > 0 ? S : 1], n_live = 0;
    for (int64_t s = 0; s < S; ++s) if (alive[r * S + s]) live[n_live++] = s;
    if (ident) /* oldest first: insertion sort by species number (stable: slot order on ties) */
        for (int64_t q = 1; q < n_live; ++q)
            for (int64_t k = q; k > 0 && ident[r * S + live[k - 1]] > ident[r * S + live[k]]; --k) {
                const int64_t t = live[k]; live[k] = live[k - 1]; live[k - 1] = t;
            }
    /* The living representatives, one array per field (and per bitset word), so that the
       terms of a genome against all of them are vector loops; pair_terms's arithmetic. */
    const int64_t L = n_live > 0 ? n_live : 1;
    char *soa = malloc(L * (2 * W * sizeof(uint64_t) + 2 * sizeof(int64_t) + 4 * sizeof(double)));
    uint64_t *rbits = (uint64_t *)soa; int64_t *rbefore = (int64_t *)(rbits + W * L);
    int64_t *rtop = rbefore + W * L, *mt = rtop + L; /* mt: matching genes */
    double *rcnt = (double *)(mt + L), *rsig = rcnt + L, *st = rsig + L, *sg = st + L;
    for (int64_t q = 0; q < n_live; ++q) {
        const int64_t rq = r * S + live[q];
        for (int64_t k = 0; k < W; ++k) {
            rbits[k * L + q] = rep.bits[rq * W + k]; rbefore[k * L + q] = rep.before[rq * W + k];
        }
        rtop[q] = rep.top[rq]; rcnt[q] = (double)rep.cnt[rq];
        rsig[q] = (double)rep.sig[rep.map ? rep.map[rq] : rq];
    }
    for (int64_t p = 0; p < P; ++p) {
        /* Every representative's terms first (vector loops), then the choice in slot order,
           adding the weight term only where it can still matter: pair_dist's result, one
           representative at a time. */
        const int64_t ra = row0 + p, ta = g.top[ra];
        const uint64_t *A = g.bits + ra * W; const int64_t *Abefore = g.before + ra * W;
        const double na = (double)g.cnt[ra], sa = (double)g.sig[g.map ? g.map[ra] : ra];
        if (n_live < VECTOR_REPS) { /* too few for vectors: pair_terms itself */
            for (int64_t q = 0; q < n_live; ++q) {
                const FN(terms_) t = FN(pair_terms_)(g, ra, rep, r * S + live[q], W, coef);
                st[q] = t.structure; sg[q] = t.sigma; mt[q] = t.match;
            }
        } else {
            for (int64_t q = 0; q < n_live; ++q) mt[q] = 0;
            for (int64_t k = 0; k < W; ++k) {
                const uint64_t a = A[k], *col = rbits + k * L;
                for (int64_t q = 0; q < n_live; ++q) mt[q] += __builtin_popcountll(a & col[q]);
            }
            const int64_t wa = ta < 0 ? 0 : ta / 64;
            const uint64_t ma = ta < 0 ? 0 : upto_mask(ta);
            const uint64_t *bw = rbits + wa * L; const int64_t *bb = rbefore + wa * L;
            for (int64_t q = 0; q < n_live; ++q) {
                const int64_t tb = rtop[q], wb = tb < 0 ? 0 : tb / 64;
                const int64_t a_upto = tb < 0 ? 0 : Abefore[wb] + __builtin_popcountll(A[wb] & upto_mask(tb));
                const int64_t b_upto = ta < 0 ? 0 : bb[q] + __builtin_popcountll(bw[q] & ma);
                st[q] = structure_term(na, rcnt[q], a_upto, b_upto, mt[q], coef);
                sg[q] = coef[3] * fabs(sa - rsig[q]);
            }
        }
        if (ident) { /* first fit: the weight term only where the rest is below thr */
            out[p] = -1;
            for (int64_t q = 0; q < n_live; ++q) {
                if (st[q] + sg[q] >= thr) continue;
                const FN(terms_) t = {st[q], sg[q], mt[q]};
                if (FN(pair_full_)(g, ra, rep, r * S + live[q], NN, W, coef, t) < thr) { out[p] = live[q]; break; }
            }
            continue;
        }
        double best = INFINITY; int64_t bk = -1;
        for (int64_t q = 0; q < n_live; ++q) {
            const double bound = best < thr ? best : thr, partial = st[q] + sg[q];
            if (partial >= bound) { if (partial < best) { best = partial; bk = live[q]; } continue; }
            const FN(terms_) t = {st[q], sg[q], mt[q]};
            const double d = FN(pair_full_)(g, ra, rep, r * S + live[q], NN, W, coef, t);
            if (d < best) { best = d; bk = live[q]; }
        }
        out[p] = best < thr ? bk : -1;
    }
    free(soa);
}
/* One breeding step, a run at a time (its children stay in cache between the phases):
   phase 1 for the run, its node registry (as evolution.innovation.assign_split_nodes:
   distinct splits ranked in slot order take the free hidden slots in ascending order),
   phase 2. */
void FN(breed_)(const breed_params *cfg, const breed_io *io) {
    const T *pw = (const T *)io->pw, *ps = (const T *)io->ps, *pm = (const T *)io->pm;
    const uint8_t *pc = io->pc, *pe = io->pe, *pn = io->pn, *reserved = io->reserved;
    const int64_t *a_idx = io->a_idx, *b_idx = io->b_idx, *dest_runs = io->dest_runs;
    T *cw = (T *)io->cw, *cs = (T *)io->cs, *cm = (T *)io->cm;
    uint8_t *cc = io->cc, *ce = io->ce, *cn = io->cn, *granted = io->granted;
    const int64_t *src = io->src, *dst = io->dst;
    const uint8_t *request = io->request;
    int64_t *new_node = io->new_node, *nearest = io->nearest;
    const int64_t R = io->R, P = io->P, N = io->N, S = io->S, first_hidden = cfg->first_hidden;
    const int threads = io->threads;
    const int64_t NN = N * N, words = (NN + 63) / 64;
    _Pragma("omp parallel for schedule(static) num_threads(threads)")
    for (int64_t r = 0; r < R; ++r) {
        const int64_t row0 = r * P, row1 = row0 + P;
        /* dest_runs: the children overwrite their parents' run dest_runs[r] of the parent arrays
           (the same arrays as the child ones), so the run's parents are copied aside first. */
        const int64_t c0 = (dest_runs ? dest_runs[r] : r) * P;
        T *cw_r = cw + c0 * NN, *cs_r = cs + c0, *cm_r = cm ? cm + c0 * NN : NULL;
        const T *pm_r = pm; T *m_aside = NULL;
        uint8_t *cc_r = cc + c0 * NN, *ce_r = ce + c0 * NN, *cn_r = cn + c0 * N;
        const T *pw_r = pw, *ps_r = ps; const uint8_t *pc_r = pc, *pe_r = pe, *pn_r = pn;
        int64_t idx0 = 0; char *aside = NULL; int64_t *loc = NULL;
        const int64_t *ia = a_idx, *ib = b_idx;
        if (dest_runs) { /* only the parents (a fifth of the run, say) are copied aside */
            loc = malloc(3 * P * sizeof(int64_t));
            int64_t *la = loc, *lb = loc + P, *slot = loc + 2 * P, n_used = 0;
            for (int64_t q = 0; q < P; ++q) slot[q] = -1;
            for (int64_t row = row0; row < row1; ++row) {
                const int64_t a = a_idx[row] - c0, b = b_idx[row] - c0;
                if (slot[a] < 0) slot[a] = n_used++;
                if (slot[b] < 0) slot[b] = n_used++;
                la[row - row0] = slot[a]; lb[row - row0] = slot[b];
            }
            aside = malloc(n_used * (NN * (sizeof(T) + 2) + N + sizeof(T)));
            T *w = (T *)aside, *sg = w + n_used * NN;
            uint8_t *c = (uint8_t *)(sg + n_used), *e = c + n_used * NN, *nd = e + n_used * NN;
            for (int64_t q = 0; q < P; ++q) {
                const int64_t k = slot[q], from = c0 + q;
                if (k < 0) continue;
                memcpy(w + k * NN, pw + from * NN, NN * sizeof(T)); sg[k] = ps[from];
                memcpy(c + k * NN, pc + from * NN, NN); memcpy(e + k * NN, pe + from * NN, NN);
                memcpy(nd + k * N, pn + from * N, N);
            }
            if (pm) { /* the parents' mutation_num aside too */
                m_aside = malloc(n_used * NN * sizeof(T));
                for (int64_t q = 0; q < P; ++q)
                    if (slot[q] >= 0) memcpy(m_aside + slot[q] * NN, pm + (c0 + q) * NN, NN * sizeof(T));
                pm_r = m_aside;
            }
            pw_r = w; ps_r = sg; pc_r = c; pe_r = e; pn_r = nd; ia = la; ib = lb; idx0 = row0;
        }
        const FN(parents_) par = {pw_r, ps_r, pm_r, pc_r, pe_r, pn_r, ia, ib, idx0};
        const FN(brood_) ch = {cw_r, cs_r, cm_r, cc_r, ce_r, cn_r};
        FN(phase1_)(cfg, io, &par, &ch, row0, row1);
        free(aside); free(loc); free(m_aside);
        uint8_t used[MAX_ROWS]; int64_t free_slots[MAX_ROWS], n_free = 0;
        for (int64_t j = 0; j < N; ++j) used[j] = reserved[r * N + j];
        for (int64_t q = 0; q < P; ++q)
            for (int64_t j = 0; j < N; ++j) used[j] |= cn_r[q * N + j];
        for (int64_t j = first_hidden; j < N; ++j) if (!used[j]) free_slots[n_free++] = j;
        uint64_t wanted[MAX_SLOTS / 64] = {0};
        for (int64_t row = row0; row < row1; ++row)
            if (request[row]) { const int64_t f = src[row] * N + dst[row]; wanted[f / 64] |= 1ULL << (f % 64); }
        int64_t before[MAX_SLOTS / 64], n = 0;
        for (int64_t k = 0; k < words; ++k) { before[k] = n; n += __builtin_popcountll(wanted[k]); }
        for (int64_t row = row0; row < row1; ++row) {
            granted[row] = 0; new_node[row] = 0;
            if (!request[row]) continue;
            const int64_t f = src[row] * N + dst[row];
            const int64_t k = before[f / 64] + __builtin_popcountll(wanted[f / 64] & ((1ULL << (f % 64)) - 1));
            if (k < n_free) { granted[row] = 1; new_node[row] = free_slots[k]; }
        }
        FN(phase2_)(cfg, io, &ch, row0, row1);
        if (io->reps) { /* speciate's first step, while the run's children are in cache */
            const FN(genes_) cg = {io->gbits, io->gbefore, io->gcount, io->gtop, cm ? cm : cw, cs, io->gmap}; /* the distance's weights */
            const FN(genes_) rg = FN(genes_of_)(io->reps);
            FN(nearest_reps_)(cg, row0, P, rg, io->r_alive, r, S, NN, words, cfg->coef, cfg->thr, nearest + row0,
                              io->r_ident);
        }
    }
}
/* Species of genomes g[R, P] (speciate's rule): the closest living representative of rep[R, S]
   within thr, first slot on ties; the rest found species in genome order, each in the lowest
   slot without members (slots >= S mean the caller must grow), and every genome still without
   a species within thr of a founder joins it. founded[r, k]: run r's k-th new slot. */
void FN(assign_species_)(const breed_params *cfg, const gene_set *genes, const gene_set *reps,
                         const assign_io *io) {
    const FN(genes_) g = FN(genes_of_)(genes), rep = FN(genes_of_)(reps);
    const uint8_t *alive = io->alive;
    const int64_t R = io->R, P = io->P, S = io->S, NN = io->NN, W = io->W;
    const int64_t *nearest = io->nearest, *r_ident = io->r_ident;
    int64_t *species = io->species, *founded = io->founded, *n_founded = io->n_founded;
    uint8_t *taken = io->taken;
    const double *coef = cfg->coef, thr = cfg->thr;
    const int threads = io->threads;
    _Pragma("omp parallel for schedule(static) num_threads(threads)")
    for (int64_t r = 0; r < R; ++r) {
        int64_t *sp = species + r * P;
        uint8_t *tk = taken + r * (S + P);
        memset(tk, 0, S + P);
        if (nearest) memcpy(sp, nearest + r * P, P * sizeof(int64_t)); /* found by breed_ */
        else FN(nearest_reps_)(g, r * P, P, rep, alive, r, S, NN, W, coef, thr, sp, r_ident);
        for (int64_t p = 0; p < P; ++p) {
            if (sp[p] >= 0) tk[sp[p]] = 1;
        }
        int64_t n = 0, free_slot = 0;
        for (int64_t p = 0; p < P; ++p) {
            if (sp[p] >= 0) continue;
            while (tk[free_slot]) ++free_slot;
            const int64_t slot = free_slot;
            tk[slot] = 1; sp[p] = slot; founded[r * P + n++] = slot;
            for (int64_t q = p + 1; q < P; ++q)
                if (sp[q] < 0 && FN(pair_dist_)(g, r * P + q, g, r * P + p, NN, W, coef, thr) < thr) sp[q] = slot;
        }
        n_founded[r] = n;
    }
}

#undef FN
