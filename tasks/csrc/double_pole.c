/* The native step of tasks.double_pole.DoublePoleTask (snn_torch/kernels/csrc/native_plant.h): one control
   step of double-pole plants (Runge-Kutta, failure test, steps balanced, Gruau's damping terms and
   fitness). State [rows][7 + window]: x, x_dot, theta1, theta1_dot, theta2, theta2_dot, steps
   balanced, the damping ring. params: gravity, cart mass, pole 1 mass, pole 1 half length, pole 2
   mass, pole 2 half length, hinge friction, RK step (s), x limit (m), angle limit (rad), then RK
   steps per control step, the damping term's variables (0: no damping; 4: x, x_dot, theta1,
   theta1_dot, Gruau's; 6: the short pole's too), max_steps, window, the number of observed variables and
   their state columns. reward: 1 while balanced (no damping), or, with damping, Gruau's fitness on
   the step the episode ends in (failure or max_steps) and 0 otherwise. Built with
   -ffp-contract=off, each expression in the torch function's order, sin and cos from
   portable_math.h, sums in slot order: the torch step's bits. */
#include <string.h>

#include "native_plant.h"
#include "portable_math.h"

NATIVE_PLANT_DECLARE(double_pole)

typedef struct { double g, mc, m1, l1, m2, l2, mu, tau, x_lim, th_lim; } plant_t;

static void derivatives(const double s[6], double force, const plant_t *p, double d[6]) {
    const double g = -p->g;
    double cos1, sin1, cos2, sin2;
    pm_sincos(s[2], &sin1, &cos1);
    pm_sincos(s[4], &sin2, &cos2);
    const double ml1 = p->l1 * p->m1, ml2 = p->l2 * p->m2;
    const double temp1 = (p->mu * s[3]) / ml1, temp2 = (p->mu * s[5]) / ml2;
    const double g_sin1 = g * sin1, g_sin2 = g * sin2;
    const double fi1 = ((ml1 * s[3]) * s[3]) * sin1 + ((0.75 * p->m1) * cos1) * (temp1 + g_sin1);
    const double fi2 = ((ml2 * s[5]) * s[5]) * sin2 + ((0.75 * p->m2) * cos2) * (temp2 + g_sin2);
    const double mi1 = p->m1 * (1.0 - (0.75 * cos1) * cos1);
    const double mi2 = p->m2 * (1.0 - (0.75 * cos2) * cos2);
    const double x_acc = ((force + fi1) + fi2) / ((mi1 + mi2) + p->mc);
    d[0] = s[1];
    d[1] = x_acc;
    d[2] = s[3];
    d[3] = (-0.75 * ((x_acc * cos1 + g_sin1) + temp1)) / p->l1;
    d[4] = s[5];
    d[5] = (-0.75 * ((x_acc * cos2 + g_sin2) + temp2)) / p->l2;
}

int double_pole_step_f64(const double *state, const double *action, double *out, double *reward,
                         uint8_t *terminated, int64_t rows, const double *params) {
    const plant_t p = {params[0], params[1], params[2], params[3], params[4],
                       params[5], params[6], params[7], params[8], params[9]};
    const int64_t rk_steps = (int64_t)params[10], damping = (int64_t)params[11];
    const double max_steps = params[12];
    const int64_t window = (int64_t)params[13], width = 7 + window;
    const double h = p.tau, half = 0.5 * p.tau, h6 = p.tau / 6.0;
    for (int64_t r = 0; r < rows; ++r) {
        const double *in = state + r * width;
        double *o = out + r * width;
        const double force = action[r];
        double s[6], k1[6], k2[6], k3[6], k4[6], t[6];
        memcpy(s, in, sizeof s);
        for (int64_t n = 0; n < rk_steps; ++n) {
            derivatives(s, force, &p, k1);
            for (int i = 0; i < 6; ++i) t[i] = s[i] + half * k1[i];
            derivatives(t, force, &p, k2);
            for (int i = 0; i < 6; ++i) t[i] = s[i] + half * k2[i];
            derivatives(t, force, &p, k3);
            for (int i = 0; i < 6; ++i) t[i] = s[i] + h * k3[i];
            derivatives(t, force, &p, k4);
            for (int i = 0; i < 6; ++i) s[i] = s[i] + h6 * ((k1[i] + k4[i]) + 2.0 * (k2[i] + k3[i]));
        }
        const int fail = fabs(s[0]) > p.x_lim || fabs(s[2]) > p.th_lim || fabs(s[4]) > p.th_lim;
        const double balanced = in[6] + (fail ? 0.0 : 1.0);
        memcpy(o, s, sizeof s);
        o[6] = balanced;
        memcpy(o + 7, in + 7, (size_t)window * sizeof(double));
        terminated[r] = (uint8_t)fail;
        if (!damping) {
            reward[r] = fail ? 0.0 : 1.0;
            continue;
        }
        if (!fail) { /* in index order from 0, as the torch step's ordered_sum (0 + a is a exactly) */
            double jiggle = 0.0;
            for (int64_t i = 0; i < damping; ++i) jiggle += fabs(s[i]);
            o[7 + (int64_t)in[6] % window] = jiggle;
        }
        const int ends = fail ? in[6] < max_steps : balanced == max_steps;
        if (!ends) {
            reward[r] = 0.0;
            continue;
        }
        double total = 0.0; /* slot order from 0, as the torch step's ordered_sum */
        for (int64_t i = 0; i < window; ++i) total += o[7 + i];
        /* DAMPING_TOTAL_FLOOR of tasks/double_pole.py: a plant held exactly at rest pays a finite
           fitness, not 1/0 (NaN stays NaN, as torch's clamp_min leaves it) */
        if (total < 1e-6) total = 1e-6;
        /* torch computes `0.75 / total` (a number over a tensor) as reciprocal(total) * 0.75 */
        const double late = balanced > (double)window ? 0.9 * ((1.0 / total) * 0.75) : 0.0;
        reward[r] = 0.1 * (balanced / 1000.0) + late;
    }
    return 0;
}

void double_pole_observe_f64(const double *state, double *observation, int64_t rows, const double *params) {
    const int64_t width = 7 + (int64_t)params[13], n_obs = (int64_t)params[14];
    for (int64_t r = 0; r < rows; ++r)
        for (int64_t j = 0; j < n_obs; ++j) observation[r * n_obs + j] = state[r * width + (int64_t)params[15 + j]];
}
