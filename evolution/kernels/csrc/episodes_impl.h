/* The episode loops for one dtype T (suffix SFX), included twice by episodes.c. */

#define FN(name) PASTE(name, SFX)
#define IZH_LANES PASTE(PASTE(izh_, SFX), _lanes)
#define IZH_DECODE PASTE(SFX, _decode)
#define SIGMOID_ROW PASTE(PASTE(sigmoid_update_, SFX), _row)

/* What every loop shares: the plant, the normalisation and the outputs. */
typedef struct {
    native_step_fn step;
    native_observe_fn observe;
    const double *params;
    const unsigned char *starts;
    int64_t row_bytes, width, start_rows, episodes, n_obs, n_act, max_steps, rows;
    const T *offset, *scale; /* input coding (evolution.input_coding): x = (T(obs) - offset) / scale */
    int64_t coding, clip, n_in; /* coding 0 unit, 1 signed, 2 push-pull; n_in network inputs */
    double *returns;
    int64_t *steps;
} FN(plant_t_);

/* A thread's rows in flight: their plant states, step counts and returns. */
typedef struct {
    unsigned char *state, *next;
    double *obs, *act, reward[LANES];
    uint8_t term[LANES];
    int64_t row[LANES], t[LANES];
    double ret[LANES];
    T x[LANES * MAXN]; /* normalised observations */
} FN(lanes_t_);

static int FN(lanes_alloc_)(FN(lanes_t_) *L, const FN(plant_t_) *p) {
    L->state = (unsigned char *)malloc((size_t)(LANES * p->row_bytes));
    L->next = (unsigned char *)malloc((size_t)(LANES * p->row_bytes));
    L->obs = (double *)malloc((size_t)(LANES * (p->n_obs > 0 ? p->n_obs : 1)) * sizeof(double));
    L->act = (double *)malloc((size_t)(LANES * p->n_act) * sizeof(double));
    return L->state && L->next && L->obs && L->act;
}

static void FN(lanes_free_)(FN(lanes_t_) *L) {
    free(L->state); free(L->next); free(L->obs); free(L->act);
}

static void FN(lanes_load_)(FN(lanes_t_) *L, const FN(plant_t_) *p, int64_t k, int64_t r) {
    memcpy(L->state + k * p->row_bytes, p->starts + (r % p->start_rows) * p->row_bytes, (size_t)p->row_bytes);
    L->row[k] = r;
    L->t[k] = 0;
    L->ret[k] = 0.0;
}

static void FN(lanes_move_)(FN(lanes_t_) *L, const FN(plant_t_) *p, int64_t from, int64_t to) {
    memcpy(L->state + to * p->row_bytes, L->state + from * p->row_bytes, (size_t)p->row_bytes);
    L->row[to] = L->row[from];
    L->t[to] = L->t[from];
    L->ret[to] = L->ret[from];
}

/* Observe and code rows [0, lanes) as evolution.input_coding.code_observations does; 0, or the
   lane whose observation is not finite plus 1. */
static int64_t FN(lanes_observe_)(FN(lanes_t_) *L, const FN(plant_t_) *p, int64_t lanes) {
    p->observe(L->state, L->obs, lanes, p->params);
    for (int64_t k = 0; k < lanes; ++k)
        for (int64_t j = 0; j < p->n_obs; ++j) {
            const double o = L->obs[k * p->n_obs + j];
            if (!isfinite(o)) return k + 1;
            T v = ((T)o - p->offset[j]) / p->scale[j];
            T *x = L->x + k * MAXN;
            if (p->coding == 0) {
                x[j] = v < (T)0 ? (T)0 : (v > (T)1 ? (T)1 : v);
                continue;
            }
            if (p->clip) v = v < (T)-1 ? (T)-1 : (v > (T)1 ? (T)1 : v);
            if (p->coding == 1) {
                x[j] = v;
            } else {
                x[2 * j] = v > (T)0 ? v : (T)0;
                x[2 * j + 1] = v < (T)0 ? -v : (T)0;
            }
        }
    return 0;
}

/* Step the plants of rows [0, lanes) under L->act; 0, or an error kind (error[1..2] set). */
static int64_t FN(lanes_step_)(FN(lanes_t_) *L, const FN(plant_t_) *p, int64_t lanes, int64_t *error) {
    const int code = p->step(L->state, L->act, L->next, L->reward, L->term, lanes, p->params);
    if (code != 0) {
        error[1] = L->row[0];
        error[2] = code;
        return 3;
    }
    for (int64_t k = 0; k < lanes; ++k) {
        if (!isfinite(L->reward[k])) {
            error[1] = L->row[k];
            return 2;
        }
        const unsigned char *next = L->next + k * p->row_bytes;
        int finite = 1;
        if (p->row_bytes == 4 * p->width)
            for (int64_t j = 0; j < p->width; ++j) finite &= isfinite(((const float *)next)[j]) != 0;
        else
            for (int64_t j = 0; j < p->width; ++j) finite &= isfinite(((const double *)next)[j]) != 0;
        if (!finite) {
            error[1] = L->row[k];
            return 5;
        }
        L->ret[k] += L->reward[k];
    }
    unsigned char *swap = L->state;
    L->state = L->next;
    L->next = swap;
    return 0;
}

/* Whether lane k's episode ended in the step just taken; if so its results are written. */
static int FN(lanes_done_)(FN(lanes_t_) *L, const FN(plant_t_) *p, int64_t k) {
    const int64_t t = L->t[k]++;
    if (!L->term[k] && t + 1 < p->max_steps) return 0;
    p->returns[L->row[k]] = L->ret[k];
    p->steps[L->row[k]] = L->term[k] ? t : t + 1;
    return 1;
}

/* ---- spiking controllers ---- */

typedef struct {
    const T *w, *v0, *u0, *z0, *iconst, *w_out, *rest, *sigma;
    const int64_t *keys;
    int64_t n, np, window, substeps, decoder, settle;
    T gain, dt, a, b, c, d, vpeak;
    double period_s, action_max, threshold;
    int64_t syn; /* exponential synapses: the synaptic current decays by syn_k per substep */
    double syn_k;
} FN(spiking_t_);

typedef struct {
    T vv[LANES * MAXN], uu[LANES * MAXN], zz[LANES * MAXN], I[LANES * MAXN], cnt[LANES * MAXN];
    T ss[LANES * MAXN]; /* synaptic currents (exponential synapses only) */
    const T *W[LANES];
    T *wbuf, *hist;
    T *draws; /* a control step's Bernoulli spikes (0 or 1) of each lane, [lane][substep][source] */
} FN(spiking_lanes_t_);

static void FN(spiking_reset_)(FN(spiking_lanes_t_) *S, const FN(spiking_t_) *c, int64_t k, int64_t r);

static void FN(spiking_load_)(FN(spiking_lanes_t_) *S, const FN(spiking_t_) *c, const FN(plant_t_) *p, int64_t k,
                              int64_t r) {
    const int64_t n = c->n, np = c->np, g = r / p->episodes;
    const T *wg = c->w + g * n * n;
    if (np == n) {
        S->W[k] = wg;
    } else {
        T *wk = S->wbuf + k * np * np; /* padding rows and columns stay 0: no synapses */
        for (int64_t i = 0; i < n; ++i) memcpy(wk + i * np, wg + i * n, (size_t)n * sizeof(T));
        S->W[k] = wk;
    }
    FN(spiking_reset_)(S, c, k, r);
}

static void FN(spiking_move_)(FN(spiking_lanes_t_) *S, const FN(spiking_t_) *c, int64_t from, int64_t to) {
    const int64_t np = c->np;
    memcpy(S->vv + to * np, S->vv + from * np, (size_t)np * sizeof(T));
    memcpy(S->uu + to * np, S->uu + from * np, (size_t)np * sizeof(T));
    memcpy(S->zz + to * np, S->zz + from * np, (size_t)np * sizeof(T));
    memcpy(S->ss + to * np, S->ss + from * np, (size_t)np * sizeof(T));
    if (np == c->n) {
        S->W[to] = S->W[from];
    } else {
        memcpy(S->wbuf + to * np * np, S->wbuf + from * np * np, (size_t)(np * np) * sizeof(T));
        S->W[to] = S->wbuf + to * np * np;
    }
    memcpy(S->hist + to * c->window * np, S->hist + from * c->window * np, (size_t)(c->window * np) * sizeof(T));
}

/* One control step of rows [0, lanes), the lane's control step count t[k]: RateControlKernel's
   encode, substeps, window and readout, then the decoder (evolution.SpikingController._decode),
   actions into L->act. */
static void FN(spiking_step_)(FN(spiking_lanes_t_) *S, const FN(spiking_t_) *c, const FN(plant_t_) *p,
                              FN(lanes_t_) *L, int64_t lanes, const int64_t *tt) {
    const int64_t n = c->n, np = c->np, n_x = p->n_in, K = p->n_act, M = c->substeps * n_x;
    const int bern = c->keys != NULL;
    const int64_t n_src = bern ? n_x : 0;
    const T gain = c->gain, dt = c->dt, a = c->a, b = c->b, cc = c->c, d = c->d, vpeak = c->vpeak;
    T *ss = c->syn ? S->ss : NULL;
    const T sk = (T)c->syn_k, sk1 = (T)(1.0 - c->syn_k);
    for (int64_t k = 0; k < lanes; ++k) {
        const T *x = L->x + k * MAXN;
        for (int64_t j = 0; j < np; ++j) {
            S->I[k * np + j] = j >= n ? (T)0 : (!bern && j < n_x) ? gain * x[j] + c->iconst[j] : c->iconst[j];
            S->cnt[k * np + j] = 0;
        }
        if (bern) {
            /* the whole control step's draws at once, counter m = substep * n_x + source; the
               sources' counts are whole numbers, so summing them here equals the substeps' sums */
            const int64_t g = L->row[k] / p->episodes;
            const uint64_t key = (uint64_t)c->keys[g];
            const int64_t base = tt[k] * M;
            T *restrict dk = S->draws + k * M;
            for (int64_t i = 0; i < n_x; ++i) {
                const int64_t below = uniform01_threshold((double)(x[i] * gain));
                int64_t total = 0;
                for (int64_t q = 0; q < c->substeps; ++q) {
                    const int64_t s = uniform01_bits(key, (uint64_t)(base + q * n_x + i)) < below;
                    dk[q * n_x + i] = (T)s;
                    total += s;
                }
                S->cnt[k * np + i] = (T)total;
            }
        }
    }
    for (int64_t q = 0; q < c->substeps; ++q) {
        for (int64_t k = 0; k < lanes && bern; ++k)
            memcpy(S->zz + k * np, S->draws + k * M + q * n_x, (size_t)n_x * sizeof(T));
        LANE_WIDTHS(SIZED(IZH_LANES(S->vv, S->uu, S->zz, S->W, S->I, S->cnt, L_, N_, n_src, n, dt, a, b, cc, d, vpeak,
                                    ss, sk, sk1),
                          IZH_LANES(S->vv, S->uu, S->zz, S->W, S->I, S->cnt, L_, np, n_src, n, dt, a, b, cc, d, vpeak,
                                    ss, sk, sk1)))
    }
    for (int64_t k = 0; k < lanes; ++k) {
        const int64_t t = tt[k], g = L->row[k] / p->episodes, W = c->window;
        T *hk = S->hist + k * W * np;
        T *slot = hk + (t % W) * np;
        for (int64_t j = 0; j < n; ++j) slot[j] = S->cnt[k * np + j];
        const T rate_div = (T)((double)(t + 1 < W ? t + 1 : W) * c->period_s);
        T y[MAXN];
        for (int64_t j = 0; j < n; ++j) {
            T total = hk[j]; /* whole numbers: exact in any order */
            for (int64_t s = 1; s < W; ++s) total += hk[s * np + j];
            y[j] = total / rate_div;
            if (c->rest) y[j] = y[j] - c->rest[j];
        }
        const T *wo = c->w_out + g * n * K;
        for (int64_t o = 0; o < K; ++o) {
            double acc = (double)(y[0] * wo[o]);
            for (int64_t j = 1; j < n; ++j) acc += (double)(y[j] * wo[j * K + o]);
            L->act[k * K + o] = (double)IZH_DECODE((T)acc, c->sigma[g], c->decoder, (T)c->action_max,
                                                   (T)c->threshold);
        }
    }
}

/* Lane k's network and rate window at rest (its row's initial state). */
static void FN(spiking_reset_)(FN(spiking_lanes_t_) *S, const FN(spiking_t_) *c, int64_t k, int64_t r) {
    const int64_t n = c->n, np = c->np;
    for (int64_t j = 0; j < np; ++j) {
        S->vv[k * np + j] = j < n ? c->v0[r * n + j] : (T)0;
        S->uu[k * np + j] = j < n ? c->u0[r * n + j] : (T)0;
        S->zz[k * np + j] = j < n ? c->z0[r * n + j] : (T)0;
        S->ss[k * np + j] = 0; /* no synaptic current at rest (recurrent_init) */
    }
    memset(S->hist + k * c->window * np, 0, (size_t)(c->window * np) * sizeof(T));
}

/* A control step: the network's own (state carried), or with settle > 0 the memoryless map of
   evolution.ablation.StaticMapController: from rest, `settle` control steps on this observation
   (counted 0, 1, ... as a fresh state counts them), the last one's action. */
static void FN(spiking_act_)(FN(spiking_lanes_t_) *S, const FN(spiking_t_) *c, const FN(plant_t_) *p,
                             FN(lanes_t_) *L, int64_t lanes) {
    if (c->settle == 0) {
        FN(spiking_step_)(S, c, p, L, lanes, L->t);
        return;
    }
    int64_t tt[LANES];
    for (int64_t k = 0; k < lanes; ++k) FN(spiking_reset_)(S, c, k, L->row[k]);
    for (int64_t s = 0; s < c->settle; ++s) {
        for (int64_t k = 0; k < lanes; ++k) tt[k] = s;
        FN(spiking_step_)(S, c, p, L, lanes, tt);
    }
}

/* ---- sigmoid controllers ---- */

typedef struct {
    const T *w;
    int64_t n, n_bias, updates, first_output, decoder, settle;
    T slope;
    double action_max;
} FN(sigmoid_t_);

static void FN(sigmoid_act_)(T *values, const FN(sigmoid_t_) *c, const FN(plant_t_) *p, FN(lanes_t_) *L,
                             int64_t lanes, T *yc, double *acc) {
    const int64_t n = c->n, K = p->n_act;
    /* settle > 0: evolution.ablation.StaticMapController's memoryless map: from values 0,
       `settle` control steps on this observation, in a scratch row */
    const int64_t updates = c->settle ? c->settle * c->updates : c->updates;
    for (int64_t k = 0; k < lanes; ++k) {
        T *y = c->settle ? values + LANES * n : values + k * n;
        if (c->settle) memset(y, 0, (size_t)n * sizeof(T));
        SIGMOID_ROW(y, L->x + k * MAXN, c->w + (L->row[k] / p->episodes) * n * n, n, p->n_in, c->n_bias, c->slope,
                    updates, yc, acc);
        const T amax = (T)c->action_max;
        for (int64_t o = 0; o < K; ++o) {
            const T out = y[c->first_output + o];
            const T action = c->decoder == 1 ? (out > (T)0.5 ? amax : -amax) : amax * ((T)2 * out - (T)1);
            L->act[k * K + o] = (double)action;
        }
    }
}

/* ---- the loops ---- */

/* Retire finished lanes (results written), filling their places from the end; the new count. */
#define RETIRE(MOVE_CTRL)                                                                          \
    for (int64_t k = lanes - 1; k >= 0; --k) {                                                    \
        if (!FN(lanes_done_)(&L, p, k)) continue;                                                 \
        if (k != lanes - 1) {                                                                     \
            FN(lanes_move_)(&L, p, lanes - 1, k);                                                 \
            MOVE_CTRL;                                                                            \
        }                                                                                         \
        --lanes;                                                                                  \
    }

static int64_t FN(claim_)(int64_t *next_row, int64_t rows) {
    int64_t r;
    _Pragma("omp atomic capture")
    r = (*next_row)++;
    return r < rows ? r : -1;
}

static int64_t FN(failed_)(const int64_t *error) {
    int64_t kind;
    _Pragma("omp atomic read")
    kind = error[0];
    return kind;
}

static void FN(fail_)(int64_t *error, int64_t kind, int64_t row, int64_t code) {
    _Pragma("omp critical(episodes_error)")
    if (error[0] == 0) {
        error[1] = row;
        error[2] = code;
        _Pragma("omp atomic write")
        error[0] = kind;
    }
}

/* What every loop shares, from the entry point's io. */
static FN(plant_t_) FN(plant_of_)(const episodes_io *io) {
    const FN(plant_t_) plant = {(native_step_fn)io->step_fn, (native_observe_fn)io->observe_fn, io->plant_params,
                                (const unsigned char *)io->starts, io->width * io->plant_bytes, io->width,
                                io->start_rows, io->episodes, io->n_obs, io->n_act, io->max_steps, io->rows,
                                (const T *)io->offset, (const T *)io->scale, io->coding, io->clip, io->n_in,
                                io->returns, io->steps};
    return plant;
}

int64_t FN(episodes_spiking_)(const episodes_io *io, const spiking_params *sp) {
    const FN(plant_t_) plant = FN(plant_of_)(io);
    const FN(spiking_t_) ctrl = {(const T *)sp->w, (const T *)sp->v0, (const T *)sp->u0, (const T *)sp->z0,
                                 (const T *)sp->iconst, (const T *)sp->w_out, (const T *)sp->rest,
                                 (const T *)sp->sigma, sp->keys, sp->n, padded_size(sp->n), sp->window,
                                 sp->substeps, sp->decoder, sp->settle, (T)sp->gain, (T)sp->dt, (T)sp->a, (T)sp->b,
                                 (T)sp->c, (T)sp->d, (T)sp->vpeak, sp->period_s, sp->action_max, sp->threshold,
                                 sp->syn, sp->syn_k};
    const int64_t window = sp->window, substeps = sp->substeps, n_in = io->n_in, rows = io->rows;
    int64_t *error = io->error;
    const int threads = io->threads;
    const FN(plant_t_) *p = &plant;
    int64_t next_row = 0;
    error[0] = error[1] = error[2] = 0;
    _Pragma("omp parallel num_threads(threads)")
    {
        FN(lanes_t_) L;
        FN(spiking_lanes_t_) *S = (FN(spiking_lanes_t_) *)calloc(1, sizeof(FN(spiking_lanes_t_)));
        const int64_t np = ctrl.np;
        int ok = FN(lanes_alloc_)(&L, p) && S != NULL;
        if (ok) {
            S->wbuf = (T *)calloc((size_t)(LANES * np * np), sizeof(T));
            S->hist = (T *)calloc((size_t)(LANES * window * np), sizeof(T));
            S->draws = (T *)malloc((size_t)(LANES * (substeps * n_in > 0 ? substeps * n_in : 1)) * sizeof(T));
            ok = S->wbuf && S->hist && S->draws;
        }
        if (!ok) FN(fail_)(error, 4, -1, 0);
        for (int64_t k = 0; ok && k < LANES; ++k) S->W[k] = S->wbuf + k * np * np;
        int64_t lanes = 0;
        while (ok && !FN(failed_)(error)) {
            for (int64_t r; lanes < LANES && (r = FN(claim_)(&next_row, rows)) >= 0; ++lanes) {
                FN(lanes_load_)(&L, p, lanes, r);
                FN(spiking_load_)(S, &ctrl, p, lanes, r);
            }
            if (lanes == 0) break;
            const int64_t bad = FN(lanes_observe_)(&L, p, lanes);
            if (bad) {
                FN(fail_)(error, 1, L.row[bad - 1], 0);
                break;
            }
            FN(spiking_act_)(S, &ctrl, p, &L, lanes);
            int64_t err[3] = {0, 0, 0};
            const int64_t kind = FN(lanes_step_)(&L, p, lanes, err);
            if (kind) {
                FN(fail_)(error, kind, err[1], err[2]);
                break;
            }
            RETIRE(FN(spiking_move_)(S, &ctrl, lanes - 1, k))
        }
        if (S) { free(S->wbuf); free(S->hist); free(S->draws); }
        free(S);
        FN(lanes_free_)(&L);
    }
    return error[0];
}

int64_t FN(episodes_sigmoid_)(const episodes_io *io, const sigmoid_params *sp) {
    const FN(plant_t_) plant = FN(plant_of_)(io);
    const FN(sigmoid_t_) ctrl = {(const T *)sp->w, sp->n, sp->n_bias, sp->updates, sp->first_output, sp->decoder,
                                 sp->settle, (T)sp->slope, sp->action_max};
    const int64_t n = sp->n, rows = io->rows;
    int64_t *error = io->error;
    const int threads = io->threads;
    const FN(plant_t_) *p = &plant;
    int64_t next_row = 0;
    error[0] = error[1] = error[2] = 0;
    _Pragma("omp parallel num_threads(threads)")
    {
        FN(lanes_t_) L;
        T *values = (T *)malloc((size_t)((LANES + 1) * n) * sizeof(T)); /* and a scratch row */
        T *yc = (T *)malloc((size_t)n * sizeof(T));
        double *acc = (double *)malloc((size_t)n * sizeof(double));
        int ok = FN(lanes_alloc_)(&L, p) && values && yc && acc;
        if (!ok) FN(fail_)(error, 4, -1, 0);
        int64_t lanes = 0;
        while (ok && !FN(failed_)(error)) {
            for (int64_t r; lanes < LANES && (r = FN(claim_)(&next_row, rows)) >= 0; ++lanes) {
                FN(lanes_load_)(&L, p, lanes, r);
                memset(values + lanes * n, 0, (size_t)n * sizeof(T));
            }
            if (lanes == 0) break;
            const int64_t bad = FN(lanes_observe_)(&L, p, lanes);
            if (bad) {
                FN(fail_)(error, 1, L.row[bad - 1], 0);
                break;
            }
            FN(sigmoid_act_)(values, &ctrl, p, &L, lanes, yc, acc);
            int64_t err[3] = {0, 0, 0};
            const int64_t kind = FN(lanes_step_)(&L, p, lanes, err);
            if (kind) {
                FN(fail_)(error, kind, err[1], err[2]);
                break;
            }
            RETIRE(memcpy(values + k * n, values + (lanes - 1) * n, (size_t)n * sizeof(T)))
        }
        free(values); free(yc); free(acc);
        FN(lanes_free_)(&L);
    }
    return error[0];
}

#undef RETIRE
#undef FN
#undef IZH_LANES
#undef IZH_DECODE
#undef SIGMOID_ROW
