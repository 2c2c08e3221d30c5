/* law.c -- a fixed law with memory (LQR, LQG): the generated estimator and law, then the clip.
 *
 * flexctrl_law_start ((y, u_prev, r) -> (xi, u): the first sample after a reset, where the
 * estimator starts from the measurement) and flexctrl_law ((xi, y, u_prev, r) -> (xi_next, u))
 * are CasADi's code generation of the controller's own law (flexctrl_law.c).
 */
#include <math.h>
#include <string.h>
#include "flexctrl_controller.h"
#include "flexctrl_law.h"

void flexctrl_reset(flexctrl_controller *c) {
  memset(c, 0, sizeof(*c));
  memcpy(c->u_prev, flexctrl_op_u, sizeof(c->u_prev));
}

void flexctrl_set_applied(flexctrl_controller *c, const double u_applied[FLEXCTRL_N_U]) {
  memcpy(c->u_prev, u_applied, sizeof(c->u_prev));
}

int flexctrl_step_ref(flexctrl_controller *c, const double *x_ref, const double *u_ref,
                      const double y[FLEXCTRL_N_Y], double u[FLEXCTRL_N_U]) {
  const casadi_real *arg[FLEXCTRL_LAW_SZ_ARG];
  casadi_real *res[FLEXCTRL_LAW_SZ_RES];
  double r[FLEXCTRL_N_X + FLEXCTRL_N_U], xi_next[FLEXCTRL_N_XI + 1], v[FLEXCTRL_N_U];
  int i, rc;
  for (i = 0; i < FLEXCTRL_N_Y; ++i)
    if (!isfinite(y[i])) return FLEXCTRL_E_MEASUREMENT;
  memcpy(r, x_ref, FLEXCTRL_N_X * sizeof(double));
  memcpy(r + FLEXCTRL_N_X, u_ref, FLEXCTRL_N_U * sizeof(double));
  res[0] = xi_next;
  res[1] = v;
  if (!c->started) {
    arg[0] = y;
    arg[1] = c->u_prev;
    arg[2] = r;
    rc = flexctrl_law_start(arg, res, c->iw, c->w, 0);
  } else {
    arg[0] = c->xi;
    arg[1] = y;
    arg[2] = c->u_prev;
    arg[3] = r;
    rc = flexctrl_law(arg, res, c->iw, c->w, 0);
  }
  if (rc) return FLEXCTRL_E_INTERNAL;
  for (i = 0; i < FLEXCTRL_N_U; ++i)
    if (!isfinite(v[i])) return FLEXCTRL_E_INTERNAL;
  memcpy(c->xi, xi_next, FLEXCTRL_N_XI * sizeof(double));
  c->started = 1;
  for (i = 0; i < FLEXCTRL_N_U; ++i) {
    double ui = v[i];
#if FLEXCTRL_SATURATE
    if (ui > flexctrl_torque_limits[i]) ui = flexctrl_torque_limits[i];
    if (ui < -flexctrl_torque_limits[i]) ui = -flexctrl_torque_limits[i];
#endif
    u[i] = ui;
    c->u_prev[i] = ui;
  }
  c->steps++;
  c->last_iterations = 0;
  return FLEXCTRL_OK;
}

int flexctrl_step(flexctrl_controller *c, long k, const double y[FLEXCTRL_N_Y],
                  double u[FLEXCTRL_N_U]) {
  double xw[FLEXCTRL_REF_WINDOW * FLEXCTRL_N_X], uw[FLEXCTRL_REF_WINDOW * FLEXCTRL_N_U];
  flexctrl_reference_window(k, xw, uw);
  return flexctrl_step_ref(c, xw, uw, y, u);
}
