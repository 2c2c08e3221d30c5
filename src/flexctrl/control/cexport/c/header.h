/* flexctrl_controller.h -- a controller exported by flexctrl (generated; do not edit).
 *
 * Controller: {controller}  (computed in C by route "{route}")
 * Designed on: {design}
 * Replay recorded from: {recorded}
 *
 * Call flexctrl_step() every FLEXCTRL_SAMPLE_TIME seconds, right after sampling the sensors,
 * and hold the returned torques until the next call (zero-order hold).
 *
 * Measurement vector y (FLEXCTRL_N_Y entries, in this order, SI units):
{measurements}
 * Torque vector u (FLEXCTRL_N_U entries, one per joint):
{torques}
 * Torques are clipped to the limits inside the step when FLEXCTRL_SATURATE is 1.
 *
 * Reference: x_ref (FLEXCTRL_N_X states in the order
 *   {states}
 * joint angles in rad, elastic coordinates, then their rates) and u_ref (feed-forward torque,
 * N m) per sample.  flexctrl_step(c, k, ...) reads rows k .. k+FLEXCTRL_REF_WINDOW-1 of the
 * exported table (sample k at t = k FLEXCTRL_SAMPLE_TIME from the start of the move; rows past
 * the table repeat its last row, the target at rest); flexctrl_step_ref() takes the rows from
 * the caller instead (another move at run time).
 *
 * {law}
 *
 * Memory: all mutable state lives in the flexctrl_controller struct (no malloc, no writable
 * globals): one struct per controller, any number of them.
 */
#ifndef FLEXCTRL_CONTROLLER_H
#define FLEXCTRL_CONTROLLER_H

#ifdef __cplusplus
extern "C" {{
#endif

{defines}

/* Return codes of the step functions. */
#define FLEXCTRL_OK 0               /* the law was evaluated (the QP solved) */
#define FLEXCTRL_FALLBACK 1         /* the QP was not solved in time: a fallback torque */
#define FLEXCTRL_E_MEASUREMENT (-1) /* a measurement is not finite: nothing changed, u untouched */
#define FLEXCTRL_E_INTERNAL (-2)    /* the generated code failed: nothing changed, u untouched */

extern const char *const flexctrl_measurement_names[FLEXCTRL_N_Y];
extern const char *const flexctrl_measurement_units[FLEXCTRL_N_Y];
extern const double flexctrl_torque_limits[FLEXCTRL_N_U]; /* N m */
extern const double flexctrl_op_x[FLEXCTRL_N_X];          /* design operating point (state) */
extern const double flexctrl_op_u[FLEXCTRL_N_U];          /* its holding torque, N m */
extern const double flexctrl_ref_x[FLEXCTRL_REF_ROWS * FLEXCTRL_N_X]; /* reference, row-major */
extern const double flexctrl_ref_u[FLEXCTRL_REF_ROWS * FLEXCTRL_N_U];
{declarations}
typedef struct flexctrl_controller {{
  double u_prev[FLEXCTRL_N_U]; /* torque held during the sample that just ended, N m */
  int started;                 /* 0 until the first measurement (the estimator starts from it) */
  long steps;                  /* steps since the reset */
  long fallbacks;              /* steps that returned FLEXCTRL_FALLBACK */
  int last_iterations;         /* solver iterations of the last step (0 for a fixed law) */
{members}
}} flexctrl_controller;

/* Forget everything since the design (estimate, warm start); u_prev = the holding torque. */
void flexctrl_reset(flexctrl_controller *c);
/* Torques u (N m) for the measurement y taken at sample k; the reference from the table. */
int flexctrl_step(flexctrl_controller *c, long k, const double y[FLEXCTRL_N_Y],
                  double u[FLEXCTRL_N_U]);
/* The same with the reference rows given: x_ref[FLEXCTRL_REF_WINDOW][FLEXCTRL_N_X],
 * u_ref[FLEXCTRL_REF_WINDOW][FLEXCTRL_N_U], row-major. */
int flexctrl_step_ref(flexctrl_controller *c, const double *x_ref, const double *u_ref,
                      const double y[FLEXCTRL_N_Y], double u[FLEXCTRL_N_U]);
/* The torque actually applied over the last sample (after a clip or an override elsewhere);
 * the estimator uses it at the next step.  Optional: by default the last returned u. */
void flexctrl_set_applied(flexctrl_controller *c, const double u_applied[FLEXCTRL_N_U]);
/* Rows k .. k+FLEXCTRL_REF_WINDOW-1 of the exported reference table (clamped at its ends). */
void flexctrl_reference_window(long k, double *x_ref, double *u_ref);

#ifdef __cplusplus
}}
#endif
#endif /* FLEXCTRL_CONTROLLER_H */
