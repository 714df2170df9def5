/* The native step of tasks.cartpole.CartPoleTask (snn_torch/kernels/csrc/native_plant.h): Qiu et al.'s
   frictionless cart-pole, one explicit Euler step per control step, the torch step's operations
   in its order (tasks.cartpole.cartpole_step), sin and cos from portable_math.h.
   params: gravity, cart mass, pole mass, half length, x limit, theta limit, tau (s), then the
   number of observed variables and their state columns. The constants are rounded to T first,
   as the torch step's 0-dim tensors are. */
#include "native_plant.h"
#include "portable_math.h"

NATIVE_PLANT_DECLARE(cartpole)

#define DEFINE_CARTPOLE(SUFFIX, T)                                                              \
int cartpole_step_##SUFFIX(const T *state, const double *action, T *next, double *reward,      \
                           uint8_t *terminated, int64_t rows, const double *params) {           \
    const double total = params[1] + params[2];                                                 \
    const T mpl = (T)(params[2] * params[3]), neg_total = (T)(-total), pos_total = (T)total;   \
    const T gravity = (T)params[0], half_length = (T)params[3], four_thirds = (T)(4.0 / 3.0);   \
    const T mass_ratio = (T)(params[2] / total), tau = (T)params[6];                            \
    const T x_lim = (T)params[4], th_lim = (T)params[5];                                        \
    for (int64_t r = 0; r < rows; ++r) {                                                        \
        const T *s = state + 4 * r;                                                             \
        T *o = next + 4 * r;                                                                    \
        const T force = (T)action[r];                                                           \
        double s64, c64;                                                                        \
        pm_sincos((double)s[2], &s64, &c64);                                                    \
        const T sn = (T)s64, cs = (T)c64;                                                       \
        const T w2_sin = (s[3] * s[3]) * sn;                                                    \
        const T temp = (force + mpl * w2_sin) / neg_total;                                      \
        const T theta_acc = (gravity * sn + cs * temp) / (half_length * (four_thirds - mass_ratio * (cs * cs))); \
        const T x_acc = (force + mpl * (w2_sin - theta_acc * cs)) / pos_total;                  \
        o[0] = s[0] + s[1] * tau;                                                               \
        o[1] = s[1] + x_acc * tau;                                                              \
        o[2] = s[2] + s[3] * tau;                                                               \
        o[3] = s[3] + theta_acc * tau;                                                          \
        const int fail = (o[0] < 0 ? -o[0] : o[0]) > x_lim || (o[2] < 0 ? -o[2] : o[2]) > th_lim; \
        terminated[r] = (uint8_t)fail;                                                          \
        reward[r] = fail ? 0.0 : 1.0;                                                           \
    }                                                                                           \
    return 0;                                                                                   \
}                                                                                               \
void cartpole_observe_##SUFFIX(const T *state, double *observation, int64_t rows, const double *params) { \
    const int64_t n_obs = (int64_t)params[7];                                                   \
    for (int64_t r = 0; r < rows; ++r)                                                          \
        for (int64_t j = 0; j < n_obs; ++j) observation[r * n_obs + j] = (double)state[4 * r + (int64_t)params[8 + j]]; \
}
DEFINE_CARTPOLE(f32, float)
DEFINE_CARTPOLE(f64, double)
