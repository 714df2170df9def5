/* The native plant ABI of the task seam (evolution.task.NativeStep): what a task's C source
   defines so that whole episodes run in one native call (evolution/kernels/csrc/episodes.c). For a
   prefix P and each state dtype the task declares (T = float: suffix f32; double: f64):

     int  P_step_f32(const float *state, const double *action, float *next, double *reward,
                     uint8_t *terminated, int64_t rows, const double *params);
     void P_observe_f32(const float *state, double *observation, int64_t rows, const double *params);

   - state [rows][width] and next [rows][width] (width: NativeStep.state_width; next never
     aliases state); action [rows][action_size], in the controller's dtype widened to double
     (exact), the plant rounds it to T as its torch step's `.to(dtype)` does;
   - reward [rows] widened to double (as the rollout's `reward.to(float64)`), terminated [rows] 0/1;
   - observation [rows][observation_size] widened to double;
   - params: NativeStep.params, the task's constants;
   - step returns 0, or a nonzero code of the plant's own (the rollout raises TaskError with it).
   The functions must be pure functions of their arguments (no globals, thread safe): rows are
   stepped in any grouping, on any thread. Build flags: -O3 -ffp-contract=off (no fused
   multiply-add): written as the torch step's operations in its order, the two agree bit for
   bit; sin, cos and exp from portable_math.h, which the torch step takes from
   snn_torch.functional.portable_math. NATIVE_PLANT_DECLARE(P) declares all four, so the compiler
   checks the definitions against the ABI. */
#ifndef SNN_NATIVE_PLANT_H
#define SNN_NATIVE_PLANT_H

#include <stdint.h>

#define NATIVE_PLANT_DECLARE(P)                                                                  \
    int P##_step_f32(const float *state, const double *action, float *next, double *reward,     \
                     uint8_t *terminated, int64_t rows, const double *params);                   \
    int P##_step_f64(const double *state, const double *action, double *next, double *reward,   \
                     uint8_t *terminated, int64_t rows, const double *params);                   \
    void P##_observe_f32(const float *state, double *observation, int64_t rows, const double *params); \
    void P##_observe_f64(const double *state, double *observation, int64_t rows, const double *params);

/* The function pointer types the episode loop calls through (state and next as void *: the
   loop moves rows of either dtype). */
typedef int (*native_step_fn)(const void *state, const double *action, void *next, double *reward,
                              uint8_t *terminated, int64_t rows, const double *params);
typedef void (*native_observe_fn)(const void *state, double *observation, int64_t rows, const double *params);

#endif
