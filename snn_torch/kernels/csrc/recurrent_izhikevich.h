/* The C kernel of snn_torch.PopulationRecurrentIzhikevich: control steps of many recurrent
   Izhikevich networks. Every function here is exported; snn_torch.kernels.build reads these
   prototypes to declare the ctypes signatures, so this header is the one place they live. */
#include <stdint.h>

/* `substeps` steps of dt ms (Heun, sub-step reset, Heaviside spikes, synchronous recurrence
   with a one-step delay) of `rows` networks of n neurons under a constant external current.
   Row r runs network net[r] (weights w[net[r]][pre][post], already masked and scaled to mV/ms
   per spike); net NULL: row r runs network r. Nodes [0, n_src) are spike sources: their spikes
   in substep q are src[(r * substeps + q) * n_src + i] and their v and u are held; or, with src
   NULL and prob not NULL, Bernoulli draws: source i of row r spikes in substep q when
   uniform01(keys[r], base + q * n_src + i) < prob[r * n_src + i] (counter_rng.h, the same bits
   as snn_torch.functional.counter_rng). v, u, z are updated in place; counts[r][j] receives
   the spikes of the substeps. s not NULL: exponential synapses, s[r][j] the synaptic current
   (updated in place), decaying by syn_k per substep (s <- syn_k s + (1 - syn_k) W z, in T). */
void izh_network_steps_f32(float *v, float *u, float *z, float *counts, const float *w, const int64_t *net,
                           const float *iext, const float *src, const double *prob,
                           const int64_t *keys, int64_t base, int64_t rows, int64_t n, int64_t n_src,
                           int64_t substeps, float dt, float a, float b, float c, float d, float vpeak,
                           float *s, double syn_k, int threads);
void izh_network_steps_f64(double *v, double *u, double *z, double *counts, const double *w, const int64_t *net,
                           const double *iext, const double *src, const double *prob,
                           const int64_t *keys, int64_t base, int64_t rows, int64_t n, int64_t n_src,
                           int64_t substeps, double dt, double a, double b, double c, double d, double vpeak,
                           double *s, double syn_k, int threads);

/* One control step of rate-coded controllers around the networks above (snn_torch's
   CurrentEncoder or BernoulliEncoder -> network -> RateWindow -> weighted readout), for rows
   r of observations x[r][0..n_x) normalised to [0, 1]:
   - encode: keys NULL (current): external current iext[r][j] = gain * x[r][j] + iconst[j] for
     j < n_x, iconst[j] beyond (iconst: the background, plus the bias nodes' current); keys not
     NULL (Bernoulli): nodes [0, n_x) are spike sources with probability (double)(x * gain) per
     substep, drawn from streams keys[r] from counter base, and iext = iconst;
   - the network steps as izh_network_steps (counts[r] receives the step's spikes; s and syn_k
     its synapses);
   - window: history[slot][r] = counts[r] (history [window][rows][n]); rates y = (sum over the
     window) / rate_div (Hz), minus rest[j] where rest is not NULL;
   - readout: drive[r][k] = sum_j y[j] * w_out[net[r]][j][k], each product in T, summed over j
     ascending in double, rounded once to T. */
void izh_rate_control_step_f32(float *v, float *u, float *z, float *counts, const float *w, const int64_t *net,
                               const float *x, int64_t n_x, float gain, const float *iconst, const int64_t *keys,
                               int64_t base, float *history, int64_t window, int64_t slot, float rate_div,
                               const float *w_out, int64_t n_out, const float *rest, float *drive, int64_t rows,
                               int64_t n, int64_t substeps, float dt, float a, float b, float c, float d,
                               float vpeak, float *s, double syn_k, int threads);
void izh_rate_control_step_f64(double *v, double *u, double *z, double *counts, const double *w,
                               const int64_t *net, const double *x, int64_t n_x, double gain,
                               const double *iconst, const int64_t *keys, int64_t base, double *history,
                               int64_t window, int64_t slot, double rate_div, const double *w_out, int64_t n_out,
                               const double *rest, double *drive, int64_t rows, int64_t n, int64_t substeps,
                               double dt, double a, double b, double c, double d, double vpeak, double *s,
                               double syn_k, int threads);

/* The spiking controllers' decoders (evolution.SpikingController._decode) in C: action[r][k] from
   drive[r][k] and the row's gain sigma[r]; decoder 0: sigmoid force, 1: bang-bang at threshold,
   2: linear, clamped to +-action_max (see recurrent_izhikevich.c). */
void rate_decode_f32(const float *drive, const float *sigma, float *action, int64_t rows, int64_t n_out,
                     int64_t decoder, double action_max, double threshold);
void rate_decode_f64(const double *drive, const double *sigma, double *action, int64_t rows, int64_t n_out,
                     int64_t decoder, double action_max, double threshold);
