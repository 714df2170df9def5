/* The C kernel of tasks.double_pole.DoublePoleTask.step on the CPU: one control step of many
   double-pole plants (Runge-Kutta, failure test, steps balanced, Gruau's damping terms and
   fitness) in one call. Every function here is exported; snn_torch._cbuild reads these
   prototypes to declare the ctypes signatures. */
#include <stdint.h>

/* Rows r of state [rows][7 + window] (x, x_dot, theta1, theta1_dot, theta2, theta2_dot, steps
   balanced, the damping ring): `rk_steps` Runge-Kutta steps under force[r] (N), written to out
   (which may not alias state). params: gravity, cart mass, pole 1 mass, pole 1 half length,
   pole 2 mass, pole 2 half length, hinge friction, RK step (s), x limit (m), angle limit (rad).
   reward[r]: 1 while balanced (damping 0), or, with damping, Gruau's fitness on the step the
   episode ends in (failure or max_steps) and 0 otherwise; failed[r]: 1 where the plant failed.
   The operations and their order are the torch function's; only sin and cos are libm's. */
void double_pole_step_f64(const double *state, const double *force, double *out, double *reward, uint8_t *failed,
                          int64_t rows, int64_t window, const double *params, int64_t rk_steps, int64_t damping,
                          int64_t max_steps, int threads);
