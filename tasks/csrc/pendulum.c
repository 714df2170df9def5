/* The native step of tasks.pendulum.PendulumTask (snn_torch/kernels/csrc/native_plant.h): gymnasium's
   Pendulum-v1, the torch step's operations in its order (tasks.pendulum.pendulum_step), sin and
   cos from portable_math.h. params: 3 g / (2 l), 3 / (m l^2), dt (s), max speed (rad/s), max
   torque (N m), the speed and torque cost weights, pi, 2 pi, and 1 if theta_dot is observed. The
   constants are rounded to T first, as the torch step's 0-dim tensors are, and the torque's
   terms are float32 (gymnasium's action dtype); the angle wraps as torch.remainder does (fmod,
   then the divisor's sign). */
#include <math.h>

#include "native_plant.h"
#include "portable_math.h"

NATIVE_PLANT_DECLARE(pendulum)

#define DEFINE_PENDULUM(SUFFIX, T, FMOD)                                                        \
int pendulum_step_##SUFFIX(const T *state, const double *action, T *next, double *reward,      \
                           uint8_t *terminated, int64_t rows, const double *params) {           \
    const T gain = (T)params[0], dt = (T)params[2], speed = (T)params[3], c_speed = (T)params[5]; \
    const float inertia = (float)params[1], torque_max = (float)params[4], c_torque = (float)params[6]; \
    const T pi = (T)params[7], two_pi = (T)params[8];                                           \
    for (int64_t r = 0; r < rows; ++r) {                                                        \
        const T theta = state[2 * r], theta_dot = state[2 * r + 1];                             \
        float u = (float)action[r];                                                             \
        u = u < -torque_max ? -torque_max : (u > torque_max ? torque_max : u);                  \
        const T push = (T)(inertia * u), effort = (T)(c_torque * (u * u));                      \
        T wrapped = FMOD(theta + pi, two_pi);                                                   \
        if (wrapped != 0 && ((wrapped < 0) != (two_pi < 0))) wrapped += two_pi;                 \
        wrapped = wrapped - pi;                                                                 \
        const T cost = wrapped * wrapped + c_speed * (theta_dot * theta_dot) + effort;          \
        double s64, c64;                                                                        \
        pm_sincos((double)theta, &s64, &c64);                                                   \
        T new_dot = theta_dot + (gain * (T)s64 + push) * dt;                                    \
        new_dot = new_dot < -speed ? -speed : (new_dot > speed ? speed : new_dot);              \
        next[2 * r] = theta + new_dot * dt;                                                     \
        next[2 * r + 1] = new_dot;                                                              \
        reward[r] = (double)(-cost);                                                            \
        terminated[r] = 0;                                                                      \
    }                                                                                           \
    return 0;                                                                                   \
}                                                                                               \
void pendulum_observe_##SUFFIX(const T *state, double *observation, int64_t rows, const double *params) { \
    const int64_t n_obs = params[9] != 0.0 ? 3 : 2;                                             \
    for (int64_t r = 0; r < rows; ++r) {                                                        \
        double s64, c64;                                                                        \
        pm_sincos((double)state[2 * r], &s64, &c64);                                            \
        observation[r * n_obs] = (double)(T)c64;                                                \
        observation[r * n_obs + 1] = (double)(T)s64;                                            \
        if (n_obs == 3) observation[r * n_obs + 2] = (double)state[2 * r + 1];                  \
    }                                                                                           \
}
DEFINE_PENDULUM(f32, float, fmodf)
DEFINE_PENDULUM(f64, double, fmod)
