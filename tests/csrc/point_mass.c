/* Test plants for the native-step seam (tests/evolution/test_native_episodes.py): a unit mass on
   a line, state (x, v, t), the torch PointMass's operations in order. params: dt, mode, where mode
   0 is faithful, 1 drifts from the torch step by a rounding, 2 returns error code 7 once t reaches
   5, 3 pays a NaN reward at t = 30 for rows that start right of 0 (as the torch step does), 4
   crashes (writes through a null pointer) once t reaches 3, 5 returns a NaN velocity at t = 10
   (as the torch step does). */
#include <math.h>

#include "native_plant.h"

NATIVE_PLANT_DECLARE(point_mass)

#define DEFINE_POINT_MASS(SUFFIX, T)                                                            \
int point_mass_step_##SUFFIX(const T *state, const double *action, T *next, double *reward,    \
                             uint8_t *terminated, int64_t rows, const double *params) {         \
    const T dt = (T)params[0];                                                                  \
    const int mode = (int)params[1];                                                            \
    for (int64_t r = 0; r < rows; ++r) {                                                        \
        const T *s = state + 3 * r;                                                             \
        T *o = next + 3 * r;                                                                    \
        const T a = (T)action[r];                                                               \
        if (mode == 2 && s[2] >= (T)5) return 7;                                                \
        if (mode == 4 && s[2] >= (T)3) *(volatile int *)(uintptr_t)params[2] = 1;              \
        const T v = s[1] + dt * (a - (T)0.5 * s[1]);                                            \
        const T x = s[0] + dt * v;                                                              \
        o[0] = mode == 1 ? x + (T)1e-3 * dt : x;                                                \
        o[2] = s[2] + (T)1;                                                                     \
        o[1] = (mode == 5 && o[2] == (T)10) ? (T)NAN : v;                                       \
        const T rew = -(x * x);                                                                 \
        reward[r] = (mode == 3 && o[2] == (T)30 && x > (T)0) ? NAN : (double)rew;               \
        terminated[r] = (x < 0 ? -x : x) > (T)2;                                                \
    }                                                                                           \
    return 0;                                                                                   \
}                                                                                               \
void point_mass_observe_##SUFFIX(const T *state, double *observation, int64_t rows, const double *params) { \
    (void)params;                                                                               \
    for (int64_t r = 0; r < rows; ++r) {                                                        \
        observation[2 * r] = (double)state[3 * r];                                              \
        observation[2 * r + 1] = (double)state[3 * r + 1];                                      \
    }                                                                                           \
}
DEFINE_POINT_MASS(f32, float)
DEFINE_POINT_MASS(f64, double)
