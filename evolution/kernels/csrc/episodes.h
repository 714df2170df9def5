/* Whole episodes in one native call (evolution.kernels.episodes): a controller's C kernel and a task's
   native plant step (snn_torch/kernels/csrc/native_plant.h) in one loop, every control step,
   termination, returns and the dropping of finished rows in C. Every function here is exported;
   snn_torch.kernels.build reads these prototypes to declare the ctypes signatures.

   episodes_io holds what every loop shares (the plant, the input coding, the rows and outputs);
   spiking_params or sigmoid_params the controller's. Each function returns 0, or on the first
   bad row 1 (an observation NaN or inf), 2 (a reward NaN or inf), 3 (the plant step returned
   the nonzero code error[2]) or 5 (a state the plant step returned holds NaN or inf), with
   error[1] the row; the outputs are then incomplete. (4: no memory for the buffers.) */
#ifndef SNN_NEAT_EPISODES_H
#define SNN_NEAT_EPISODES_H

#include <stdint.h>

/* Plant: step_fn and observe_fn (the plant's functions for its state dtype, plant_bytes 4 or 8
   per element), plant_params, width (state columns), starts [start_rows][width] (row r starts
   from starts[r % start_rows] and runs network r / episodes; start_rows is episodes for starts
   shared by every network, or rows for a start per row), n_obs observations, n_act actions,
   max_steps control steps at most. Input coding (evolution.input_coding, as the rollout
   computes it): v = (T(obs) - offset) / scale; coding 0: clamp(v, 0, 1); 1: v, clamped to
   [-1, 1] if clip; 2: the same v as the pair (max(v, 0), max(-v, 0)); n_in network inputs.
   Outputs: returns[r] (sum of the rewards, double, in step order) and steps[r] (control steps
   before the episode terminated, or max_steps). Rows run on `threads` threads, each taking the
   next row when one of its rows finishes: no thread waits for another until the end. offset
   and scale of the entry point's type T (float for _f32, double for _f64). */
typedef struct {
    const void *step_fn;
    const void *observe_fn;
    const double *plant_params;
    int64_t plant_bytes;
    int64_t width;
    const void *starts;
    int64_t start_rows;
    int64_t episodes;
    int64_t n_obs;
    int64_t n_act;
    int64_t max_steps;
    const void *offset;
    const void *scale;
    int64_t coding;
    int64_t clip;
    int64_t n_in;
    int64_t rows;
    double *returns;
    int64_t *steps;
    int64_t *error;              /* [3]: the kind, the row, the plant's code */
    int threads;
} episodes_io;

/* Rate-coded spiking controllers (evolution.SpikingController; RateControlKernel's step, then
   the decoder): networks w [G][n][n] (effective weights), initial state v0, u0, z0 [rows][n],
   constant currents iconst [n], input gain (current: mV/ms at x = 1; Bernoulli: spike
   probability per substep at x = 1), keys [G] (Bernoulli streams) or NULL (current encoder),
   readout w_out [G][n][n_act], rest [n] or NULL, sigma [G], the rate window (control steps,
   period_s each), the neuron and substeps; decoder 0: sigmoid force, 1: bang-bang at threshold,
   2: linear, clamped to +-action_max. settle > 0 (both controllers): each control step is
   evolution.ablation.StaticMapController's memoryless map, `settle` control steps from rest on
   the observation, the last one's action. syn != 0: exponential synapses, the synaptic current
   decaying by syn_k per substep (snn_torch.functional.recurrent.synaptic_decay), 0 at rest.
   Arrays and gain, dt, a, b, c, d, vpeak are of the entry point's type T (the scalars rounded
   to T from these doubles). */
typedef struct {
    const void *w;
    const void *v0;
    const void *u0;
    const void *z0;
    int64_t n;
    const void *iconst;
    double gain;
    const int64_t *keys;
    const void *w_out;
    const void *rest;
    const void *sigma;
    int64_t window;
    double period_s;
    int64_t substeps;
    double dt;
    double a;
    double b;
    double c;
    double d;
    double vpeak;
    int64_t decoder;
    double action_max;
    double threshold;
    int64_t settle;
    int64_t syn;
    double syn_k;
} spiking_params;

/* Recurrent sigmoid controllers (evolution.SigmoidController): networks w [G][n][n] (of type
   T), nodes [0, n_in) clamped to the normalised observations and the next n_bias to 1,
   `updates` synchronous updates of sigmoid(slope * sum_i y_i w_ij) per control step (values
   start at 0; slope rounded to T), actions read from nodes first_output.. by decoder 0
   (a_max (2 y - 1)) or 1 (+-a_max on y > 0.5). */
typedef struct {
    const void *w;
    int64_t n;
    int64_t n_bias;
    double slope;
    int64_t updates;
    int64_t first_output;
    int64_t decoder;
    double action_max;
    int64_t settle;
} sigmoid_params;

int64_t episodes_spiking_f32(const episodes_io *io, const spiking_params *ctrl);
int64_t episodes_spiking_f64(const episodes_io *io, const spiking_params *ctrl);
int64_t episodes_sigmoid_f32(const episodes_io *io, const sigmoid_params *ctrl);
int64_t episodes_sigmoid_f64(const episodes_io *io, const sigmoid_params *ctrl);

#endif
