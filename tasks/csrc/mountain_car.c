/* The native steps of tasks.mountain_car (snn_torch/kernels/csrc/native_plant.h): gymnasium's
   MountainCar-v0 (prefix mountain_car) and MountainCarContinuous-v0 (prefix
   mountain_car_continuous), the torch steps' operations in their order
   (tasks.mountain_car.mountain_car_step, mountain_car_continuous_step), cos from
   portable_math.h. The constants are rounded to the arithmetic's type first, as the torch
   steps' 0-dim tensors are; the discrete action is binned as tasks.gym_adapter.discrete_action
   bins it, in double.

   mountain_car params: force per action step, gravity term, max speed, min and max position,
   goal position.
   mountain_car_continuous params: power, gravity term, max speed, min and max position, goal
   position, goal reward, action cost weight. Its state is (x, v, 1 until the first step); a
   first step of a double state runs in double (numpy's from gymnasium's float64 start), every
   other step in float (numpy's on gymnasium's float32 state and action). */
#include <math.h>

#include "native_plant.h"
#include "portable_math.h"

NATIVE_PLANT_DECLARE(mountain_car)
NATIVE_PLANT_DECLARE(mountain_car_continuous)

/* gymnasium's Discrete(n) action of a continuous output a in [-1, 1] (GymTask's bins) */
static inline double gym_bin(double a, double n) {
    const double k = floor((a + 1.0) / 2.0 * n);
    return k < 0.0 ? 0.0 : (k > n - 1.0 ? n - 1.0 : k);
}

#define DEFINE_MOUNTAIN_CAR(SUFFIX, T)                                                          \
int mountain_car_step_##SUFFIX(const T *state, const double *action, T *next, double *reward,  \
                               uint8_t *terminated, int64_t rows, const double *params) {       \
    const T force = (T)params[0], neg_gravity = (T)(-params[1]), speed = (T)params[2];         \
    const T neg_speed = (T)(-params[2]), low = (T)params[3], high = (T)params[4], goal = (T)params[5]; \
    const T three = (T)3.0, one = (T)1.0, zero = (T)0.0;                                        \
    for (int64_t r = 0; r < rows; ++r) {                                                        \
        T position = state[2 * r], velocity = state[2 * r + 1];                                 \
        const T push = ((T)gym_bin(action[r], 3.0) - one) * force;                              \
        double s64, c64;                                                                        \
        pm_sincos((double)(three * position), &s64, &c64);                                      \
        velocity = velocity + (push + (T)c64 * neg_gravity);                                    \
        velocity = velocity < neg_speed ? neg_speed : (velocity > speed ? speed : velocity);    \
        position = position + velocity;                                                         \
        position = position < low ? low : (position > high ? high : position);                 \
        if (position == low && velocity < zero) velocity = zero;                                \
        next[2 * r] = position;                                                                 \
        next[2 * r + 1] = velocity;                                                             \
        terminated[r] = (uint8_t)(position >= goal && velocity >= zero);                        \
        reward[r] = -1.0;                                                                       \
    }                                                                                           \
    return 0;                                                                                   \
}                                                                                               \
void mountain_car_observe_##SUFFIX(const T *state, double *observation, int64_t rows, const double *params) { \
    (void)params;                                                                               \
    for (int64_t i = 0; i < 2 * rows; ++i) observation[i] = (double)(T)(float)state[i];         \
}
DEFINE_MOUNTAIN_CAR(f32, float)
DEFINE_MOUNTAIN_CAR(f64, double)

/* One Continuous_MountainCarEnv step on a state of type W, numpy's types followed op by op (W op
   a Python float: in W; W op float32: in the wider), as tasks.mountain_car._continuous. */
#define DEFINE_CONTINUOUS_PATH(W)                                                               \
static inline int mcc_path_##W(W *position, W *velocity, float a32, const double *params) {    \
    const float one32 = 1.0f, power32 = (float)params[0];                                       \
    const W three = (W)3.0, speed = (W)params[2], neg_speed = (W)(-params[2]);                  \
    const W low = (W)params[3], high = (W)params[4], goal = (W)params[5], zero = (W)0.0;        \
    double s64, c64;                                                                            \
    pm_sincos((double)(three * *position), &s64, &c64);                                         \
    const double c = params[1] * c64;                                                           \
    W inc;                                                                                      \
    if (a32 >= -one32 && a32 <= one32) inc = (W)(a32 * power32 - (float)c);                     \
    else inc = (W)((a32 > one32 ? params[0] : -params[0]) - c);                                 \
    W v = *velocity + inc;                                                                      \
    v = v < neg_speed ? neg_speed : (v > speed ? speed : v);                                    \
    W p = *position + v;                                                                        \
    p = p < low ? low : (p > high ? high : p);                                                  \
    if (p == low && v < zero) v = zero;                                                         \
    *position = p;                                                                              \
    *velocity = v;                                                                              \
    return p >= goal && v >= zero;                                                              \
}
DEFINE_CONTINUOUS_PATH(double)
DEFINE_CONTINUOUS_PATH(float)

#define DEFINE_MOUNTAIN_CAR_CONTINUOUS(SUFFIX, T)                                               \
int mountain_car_continuous_step_##SUFFIX(const T *state, const double *action, T *next,       \
                                          double *reward, uint8_t *terminated, int64_t rows,    \
                                          const double *params) {                               \
    for (int64_t r = 0; r < rows; ++r) {                                                        \
        const T *s = state + 3 * r;                                                             \
        const float a32 = (float)action[r];                                                     \
        int done;                                                                               \
        float p32, v32;                                                                         \
        if (sizeof(T) == sizeof(double) && s[2] != 0) { /* the first step from a double start */ \
            double p = (double)s[0], v = (double)s[1];                                          \
            done = mcc_path_double(&p, &v, a32, params);                                        \
            p32 = (float)p;                                                                     \
            v32 = (float)v;                                                                     \
        } else {                                                                                \
            p32 = (float)s[0];                                                                  \
            v32 = (float)s[1];                                                                  \
            done = mcc_path_float(&p32, &v32, a32, params);                                     \
        }                                                                                       \
        next[3 * r] = (T)p32;                                                                   \
        next[3 * r + 1] = (T)v32;                                                               \
        next[3 * r + 2] = (T)0.0;                                                               \
        terminated[r] = (uint8_t)done;                                                          \
        const double a64 = (double)a32;                                                         \
        reward[r] = (double)(T)((done ? params[6] : 0.0) - a64 * a64 * params[7]);              \
    }                                                                                           \
    return 0;                                                                                   \
}                                                                                               \
void mountain_car_continuous_observe_##SUFFIX(const T *state, double *observation, int64_t rows, \
                                              const double *params) {                           \
    (void)params;                                                                               \
    for (int64_t r = 0; r < rows; ++r) {                                                        \
        observation[2 * r] = (double)(T)(float)state[3 * r];                                    \
        observation[2 * r + 1] = (double)(T)(float)state[3 * r + 1];                            \
    }                                                                                           \
}
DEFINE_MOUNTAIN_CAR_CONTINUOUS(f32, float)
DEFINE_MOUNTAIN_CAR_CONTINUOUS(f64, double)
