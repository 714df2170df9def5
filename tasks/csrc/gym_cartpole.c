/* The native step of tasks.gym_cartpole.GymCartPoleTask (snn_torch/kernels/csrc/native_plant.h):
   gymnasium's CartPole-v1, the torch step's operations in its order
   (tasks.gym_cartpole.gym_cartpole_step), sin and cos from portable_math.h. params: force
   magnitude (N), pole mass x half length (kg m), total mass (kg), gravity (m/s^2), half length
   (m), pole mass (kg), tau (s), x limit (m), theta limit (rad). The constants are rounded to T
   first, as the torch step's 0-dim tensors are. The action is binned as
   tasks.gym_adapter.discrete_action bins it, in double. */
#include <math.h>

#include "native_plant.h"
#include "portable_math.h"

NATIVE_PLANT_DECLARE(gym_cartpole)

/* gymnasium's Discrete(n) action of a continuous output a in [-1, 1] (GymTask's bins) */
static inline double gym_bin(double a, double n) {
    const double k = floor((a + 1.0) / 2.0 * n);
    return k < 0.0 ? 0.0 : (k > n - 1.0 ? n - 1.0 : k);
}

#define DEFINE_GYM_CARTPOLE(SUFFIX, T)                                                          \
int gym_cartpole_step_##SUFFIX(const T *state, const double *action, T *next, double *reward,  \
                               uint8_t *terminated, int64_t rows, const double *params) {       \
    const T f_mag = (T)params[0], f_neg = (T)(-params[0]), pml = (T)params[1], total = (T)params[2]; \
    const T gravity = (T)params[3], length = (T)params[4], four_thirds = (T)(4.0 / 3.0);       \
    const T m_pole = (T)params[5], tau = (T)params[6], x_lim = (T)params[7], th_lim = (T)params[8]; \
    for (int64_t r = 0; r < rows; ++r) {                                                        \
        const T *s = state + 4 * r;                                                             \
        T *o = next + 4 * r;                                                                    \
        const T force = gym_bin(action[r], 2.0) == 1.0 ? f_mag : f_neg;                         \
        double s64, c64;                                                                        \
        pm_sincos((double)s[2], &s64, &c64);                                                    \
        const T sn = (T)s64, cs = (T)c64;                                                       \
        const T temp = (force + pml * (s[3] * s[3]) * sn) / total;                              \
        const T theta_acc = (gravity * sn - cs * temp) / (length * (four_thirds - m_pole * (cs * cs) / total)); \
        const T x_acc = temp - pml * theta_acc * cs / total;                                    \
        o[0] = s[0] + tau * s[1];                                                               \
        o[1] = s[1] + tau * x_acc;                                                              \
        o[2] = s[2] + tau * s[3];                                                               \
        o[3] = s[3] + tau * theta_acc;                                                          \
        terminated[r] = (uint8_t)(o[0] < -x_lim || o[0] > x_lim || o[2] < -th_lim || o[2] > th_lim); \
        reward[r] = 1.0;                                                                        \
    }                                                                                           \
    return 0;                                                                                   \
}                                                                                               \
void gym_cartpole_observe_##SUFFIX(const T *state, double *observation, int64_t rows, const double *params) { \
    (void)params;                                                                               \
    for (int64_t i = 0; i < 4 * rows; ++i) observation[i] = (double)(T)(float)state[i];         \
}
DEFINE_GYM_CARTPOLE(f32, float)
DEFINE_GYM_CARTPOLE(f64, double)
