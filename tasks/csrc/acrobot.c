/* The native step of tasks.acrobot.AcrobotTask (snn_torch/kernels/csrc/native_plant.h): gymnasium's
   Acrobot-v1 (book dynamics), the torch step's operations in its order (tasks.acrobot:
   acrobot_dsdt, acrobot_step, wrap), sin and cos from portable_math.h. params: dt, dt / 2,
   dt / 6 (s), pi, the velocity bounds (rad/s), the wrap's most turns, then _dsdt's fifteen
   constant factors (tasks.acrobot._DSDT, in order). The constants are rounded to T first, as the
   torch step's 0-dim tensors are. The action is binned as tasks.gym_adapter.discrete_action
   bins it, in double. */
#include <math.h>

#include "native_plant.h"
#include "portable_math.h"

NATIVE_PLANT_DECLARE(acrobot)

/* gymnasium's Discrete(n) action of a continuous output a in [-1, 1] (GymTask's bins) */
static inline double gym_bin(double a, double n) {
    const double k = floor((a + 1.0) / 2.0 * n);
    return k < 0.0 ? 0.0 : (k > n - 1.0 ? n - 1.0 : k);
}

#define DEFINE_ACROBOT(SUFFIX, T)                                                               \
typedef struct { T m1_lc1_sq, m2, l1_sq_lc2_sq, two_l1_lc2, i1, i2, lc2_sq, l1_lc2, m2_lc2_g, half_pi, \
                 c_phi1_a, c_phi1_b, c_phi1_c, c_dd2, c_den; } acrobot_consts_##SUFFIX;        \
static inline T acrobot_cos_##SUFFIX(T x) {                                                    \
    double s64, c64;                                                                            \
    pm_sincos((double)x, &s64, &c64);                                                           \
    return (T)c64;                                                                              \
}                                                                                               \
/* _dsdt: y (4) -> out (4) = (dtheta1, dtheta2, ddtheta1, ddtheta2) */                          \
static inline void acrobot_dsdt_##SUFFIX(const T *y, T torque, const acrobot_consts_##SUFFIX *k, T *out) { \
    const T theta1 = y[0], theta2 = y[1], dtheta1 = y[2], dtheta2 = y[3];                       \
    double s64, c64;                                                                            \
    pm_sincos((double)theta2, &s64, &c64);                                                      \
    const T sin2 = (T)s64, cos2 = (T)c64;                                                       \
    const T cos_phi2 = acrobot_cos_##SUFFIX(theta1 + theta2 - k->half_pi);                      \
    const T cos_phi1 = acrobot_cos_##SUFFIX(theta1 - k->half_pi);                               \
    const T d1 = k->m1_lc1_sq + k->m2 * (k->l1_sq_lc2_sq + k->two_l1_lc2 * cos2) + k->i1 + k->i2; \
    const T d2 = k->m2 * (k->lc2_sq + k->l1_lc2 * cos2) + k->i2;                                \
    const T phi2 = k->m2_lc2_g * cos_phi2;                                                      \
    const T phi1 = k->c_phi1_a * (dtheta2 * dtheta2) * sin2 - k->c_phi1_b * dtheta2 * dtheta1 * sin2 \
                   + k->c_phi1_c * cos_phi1 + phi2;                                             \
    const T ddtheta2 = (torque + d2 / d1 * phi1 - k->c_dd2 * (dtheta1 * dtheta1) * sin2 - phi2) \
                       / (k->c_den - d2 * d2 / d1);                                             \
    out[0] = dtheta1;                                                                           \
    out[1] = dtheta2;                                                                           \
    out[2] = -(d2 * ddtheta2 + phi1) / d1;                                                      \
    out[3] = ddtheta2;                                                                          \
}                                                                                               \
int acrobot_step_##SUFFIX(const T *state, const double *action, T *next, double *reward,       \
                          uint8_t *terminated, int64_t rows, const double *params) {            \
    const T dt = (T)params[0], dt2 = (T)params[1], dt6 = (T)params[2], two = (T)2.0;           \
    const T pi = (T)params[3], neg_pi = (T)(-params[3]), one = (T)1.0;                          \
    const T v1 = (T)params[4], neg_v1 = (T)(-params[4]), v2 = (T)params[5], neg_v2 = (T)(-params[5]); \
    const int64_t turns = (int64_t)params[6];                                                   \
    const T diff = pi - neg_pi;                                                                 \
    const double *c = params + 7;                                                               \
    const acrobot_consts_##SUFFIX k = {(T)c[0], (T)c[1], (T)c[2], (T)c[3], (T)c[4], (T)c[5], (T)c[6], (T)c[7], \
                                       (T)c[8], (T)c[9], (T)c[10], (T)c[11], (T)c[12], (T)c[13], (T)c[14]}; \
    for (int64_t r = 0; r < rows; ++r) {                                                        \
        const T *s = state + 4 * r;                                                             \
        T *o = next + 4 * r;                                                                    \
        const T torque = (T)gym_bin(action[r], 3.0) - one;                                      \
        T k1[4], k2[4], k3[4], k4[4], y[4];                                                     \
        acrobot_dsdt_##SUFFIX(s, torque, &k, k1);                                               \
        for (int i = 0; i < 4; ++i) y[i] = s[i] + dt2 * k1[i];                                  \
        acrobot_dsdt_##SUFFIX(y, torque, &k, k2);                                               \
        for (int i = 0; i < 4; ++i) y[i] = s[i] + dt2 * k2[i];                                  \
        acrobot_dsdt_##SUFFIX(y, torque, &k, k3);                                               \
        for (int i = 0; i < 4; ++i) y[i] = s[i] + dt * k3[i];                                   \
        acrobot_dsdt_##SUFFIX(y, torque, &k, k4);                                               \
        for (int i = 0; i < 4; ++i) y[i] = s[i] + dt6 * (k1[i] + two * k2[i] + two * k3[i] + k4[i]); \
        for (int i = 0; i < 2; ++i) { /* gymnasium's wrap: its loop, at most `turns` each way */ \
            for (int64_t t = 0; t < turns && y[i] > pi; ++t) y[i] = y[i] - diff;                \
            for (int64_t t = 0; t < turns && y[i] < neg_pi; ++t) y[i] = y[i] + diff;            \
        }                                                                                       \
        /* bound: min(max(x, m), M) */                                                          \
        y[2] = y[2] < neg_v1 ? neg_v1 : y[2];                                                   \
        y[2] = y[2] > v1 ? v1 : y[2];                                                           \
        y[3] = y[3] < neg_v2 ? neg_v2 : y[3];                                                   \
        y[3] = y[3] > v2 ? v2 : y[3];                                                           \
        for (int i = 0; i < 4; ++i) o[i] = y[i];                                                \
        const int done = -acrobot_cos_##SUFFIX(y[0]) - acrobot_cos_##SUFFIX(y[1] + y[0]) > one; \
        terminated[r] = (uint8_t)done;                                                          \
        reward[r] = done ? 0.0 : -1.0;                                                          \
    }                                                                                           \
    return 0;                                                                                   \
}                                                                                               \
void acrobot_observe_##SUFFIX(const T *state, double *observation, int64_t rows, const double *params) { \
    (void)params;                                                                               \
    for (int64_t r = 0; r < rows; ++r) {                                                        \
        const T *s = state + 4 * r;                                                             \
        double *ob = observation + 6 * r, s0, c0, s1, c1;                                       \
        pm_sincos((double)s[0], &s0, &c0);                                                      \
        pm_sincos((double)s[1], &s1, &c1);                                                      \
        ob[0] = (double)(float)(T)c0;                                                           \
        ob[1] = (double)(float)(T)s0;                                                           \
        ob[2] = (double)(float)(T)c1;                                                           \
        ob[3] = (double)(float)(T)s1;                                                           \
        ob[4] = (double)(float)s[2];                                                            \
        ob[5] = (double)(float)s[3];                                                            \
    }                                                                                           \
}
DEFINE_ACROBOT(f32, float)
DEFINE_ACROBOT(f64, double)
