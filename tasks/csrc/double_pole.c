/* Double-pole plant steps (see double_pole.h). Built with -ffp-contract=off: every product is
   rounded before it is added, as torch does, and each expression keeps the torch function's order. */
#include <math.h>
#include <string.h>
#include "double_pole.h"

typedef struct { double g, mc, m1, l1, m2, l2, mu, tau, x_lim, th_lim; } plant_t;

static void derivatives(const double s[6], double force, const plant_t *p, double d[6]) {
    const double g = -p->g;
    const double cos1 = cos(s[2]), sin1 = sin(s[2]), cos2 = cos(s[4]), sin2 = sin(s[4]);
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

void double_pole_step_f64(const double *state, const double *force, double *out, double *reward, uint8_t *failed,
                          int64_t rows, int64_t window, const double *params, int64_t rk_steps, int64_t damping,
                          int64_t max_steps, int threads) {
    const plant_t p = {params[0], params[1], params[2], params[3], params[4],
                       params[5], params[6], params[7], params[8], params[9]};
    const int64_t width = 7 + window;
    const double h = p.tau, half = 0.5 * p.tau, h6 = p.tau / 6.0;
    #pragma omp parallel for num_threads(threads) schedule(static) if (rows > 256)
    for (int64_t r = 0; r < rows; ++r) {
        const double *in = state + r * width;
        double *o = out + r * width;
        double s[6], k1[6], k2[6], k3[6], k4[6], t[6];
        memcpy(s, in, sizeof s);
        for (int64_t n = 0; n < rk_steps; ++n) {
            derivatives(s, force[r], &p, k1);
            for (int i = 0; i < 6; ++i) t[i] = s[i] + half * k1[i];
            derivatives(t, force[r], &p, k2);
            for (int i = 0; i < 6; ++i) t[i] = s[i] + half * k2[i];
            derivatives(t, force[r], &p, k3);
            for (int i = 0; i < 6; ++i) t[i] = s[i] + h * k3[i];
            derivatives(t, force[r], &p, k4);
            for (int i = 0; i < 6; ++i) s[i] = s[i] + h6 * ((k1[i] + k4[i]) + 2.0 * (k2[i] + k3[i]));
        }
        const int fail = fabs(s[0]) > p.x_lim || fabs(s[2]) > p.th_lim || fabs(s[4]) > p.th_lim;
        const double balanced = in[6] + (fail ? 0.0 : 1.0);
        memcpy(o, s, sizeof s);
        o[6] = balanced;
        memcpy(o + 7, in + 7, (size_t)window * sizeof(double));
        failed[r] = (uint8_t)fail;
        if (!damping) {
            reward[r] = fail ? 0.0 : 1.0;
            continue;
        }
        if (!fail) o[7 + (int64_t)in[6] % window] = ((fabs(s[0]) + fabs(s[1])) + fabs(s[2])) + fabs(s[3]);
        const int ends = fail ? in[6] < (double)max_steps : balanced == (double)max_steps;
        if (!ends) {
            reward[r] = 0.0;
            continue;
        }
        double total = 0.0;
        for (int64_t i = 0; i < window; ++i) total += o[7 + i];
        const double late = balanced > (double)window ? 0.9 * (0.75 / total) : 0.0;
        reward[r] = 0.1 * (balanced / 1000.0) + late;
    }
}
