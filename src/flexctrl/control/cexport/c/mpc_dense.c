/* mpc_dense.c -- the linear MPC: the condensed QP solved by a dense ADMM written for it.
 *
 * The condensed QP of the controller's scaled problem (states eliminated), w = [v (NV), s (NS)]:
 *   min 1/2 v'Hv + (F z)'v + l1 1's + l2/2 s's
 *   s.t. G v - s <= c_hi - CP z - dc,   G v + s >= c_lo - CP z - dc,   (soft rows, slacks s)
 *        v_lo - dv <= v <= v_hi - dv,   s >= 0
 * with z the scaled state deviation, dv and dc the reference's shifts of the bounds.  Its rows
 * in OSQP's form l <= Abar w <= u are [G v - s; G v + s; v; s] (MR rows), and
 * Abar'Abar = blockdiag(2 G'G + I, 3 I), so the ADMM's linear system (P + sigma I + rho Abar'Abar)
 * is one NV x NV Cholesky factor (refactored only when rho changes) and a scalar.  The
 * iteration, termination test and adaptive rho are OSQP's (Stellato et al. 2020, Algorithm 1;
 * rho adapted every ADAPT_INTERVAL iterations when it moves by more than 5x), without Ruiz
 * scaling: the MPC scales its variables itself.
 */
#include <math.h>
#include <string.h>
#include "flexctrl_controller.h"
#include "flexctrl_pre.h"

#define NV FLEXCTRL_QP_NV
#define NS FLEXCTRL_QP_NS
#define NW (NV + NS)
#define MR (2 * NS + NV + NS)
#define RHO_MIN 1e-6
#define RHO_MAX 1e6

/* L = chol(H + sigma I + rho (2 G'G + I)), lower triangle, row-major. */
static void factor(double *L, double rho) {
  int i, j, k;
  for (i = 0; i < NV; ++i)
    for (j = 0; j <= i; ++j)
      L[i * NV + j] = flexctrl_qp_H[i * NV + j] + 2.0 * rho * flexctrl_qp_GtG[i * NV + j] +
                      (i == j ? FLEXCTRL_SIGMA + rho : 0.0);
  for (j = 0; j < NV; ++j) {
    double d = L[j * NV + j];
    for (k = 0; k < j; ++k) d -= L[j * NV + k] * L[j * NV + k];
    d = sqrt(d);
    L[j * NV + j] = d;
    for (i = j + 1; i < NV; ++i) {
      double s = L[i * NV + j];
      for (k = 0; k < j; ++k) s -= L[i * NV + k] * L[j * NV + k];
      L[i * NV + j] = s / d;
    }
  }
}

static void solve_factored(const double *L, double *b) {
  int i, k;
  for (i = 0; i < NV; ++i) {
    double s = b[i];
    for (k = 0; k < i; ++k) s -= L[i * NV + k] * b[k];
    b[i] = s / L[i * NV + i];
  }
  for (i = NV - 1; i >= 0; --i) {
    double s = b[i];
    for (k = i + 1; k < NV; ++k) s -= L[k * NV + i] * b[k];
    b[i] = s / L[i * NV + i];
  }
}

/* out = Abar w = [G v - s; G v + s; v; s] */
static void rows_times(const double *w, double *out) {
  int i, j;
  for (i = 0; i < NS; ++i) {
    const double *g = flexctrl_qp_G + i * NV;
    double gv = 0.0;
    for (j = 0; j < NV; ++j) gv += g[j] * w[j];
    out[i] = gv - w[NV + i];
    out[NS + i] = gv + w[NV + i];
  }
  memcpy(out + 2 * NS, w, NW * sizeof(double));
}

/* out = Abar' r */
static void rows_t_times(const double *r, double *out) {
  int i, j;
  memcpy(out, r + 2 * NS, NV * sizeof(double));
  for (i = 0; i < NS; ++i) {
    const double *g = flexctrl_qp_G + i * NV;
    double a = r[i] + r[NS + i];
    if (a != 0.0)
      for (j = 0; j < NV; ++j) out[j] += g[j] * a;
    out[NV + i] = -r[i] + r[NS + i] + r[2 * NS + NV + i];
  }
}

static double norm_inf(const double *a, int n) {
  double m = 0.0;
  int i;
  for (i = 0; i < n; ++i)
    if (fabs(a[i]) > m) m = fabs(a[i]);
  return m;
}

/* OSQP's residuals at (x, z, y) and the norms its relative tolerances scale. */
static void residuals(const flexctrl_controller *c, double *prim, double *dual, double *prim_n,
                      double *dual_n) {
  double ax[MR], px[NW], aty[NW], r[NW];
  int i, j;
  rows_times(c->x, ax);
  *prim = 0.0;
  for (i = 0; i < MR; ++i)
    if (fabs(ax[i] - c->z[i]) > *prim) *prim = fabs(ax[i] - c->z[i]);
  *prim_n = fmax(norm_inf(ax, MR), norm_inf(c->z, MR));
  for (i = 0; i < NV; ++i) {
    double s = 0.0;
    for (j = 0; j < NV; ++j) s += flexctrl_qp_H[i * NV + j] * c->x[j];
    px[i] = s;
  }
  for (i = 0; i < NS; ++i) px[NV + i] = FLEXCTRL_L2 * c->x[NV + i];
  rows_t_times(c->y, aty);
  for (i = 0; i < NW; ++i) r[i] = px[i] + c->q[i] + aty[i];
  *dual = norm_inf(r, NW);
  *dual_n = fmax(fmax(norm_inf(px, NW), norm_inf(aty, NW)), norm_inf(c->q, NW));
}

/* ADMM on this sample's q, lo, hi from the iterates in c; 1 when solved to the tolerance. */
static int admm(flexctrl_controller *c) {
  double rhs[NW], xt[NW], zt[MR], t[MR];
  const double alpha = FLEXCTRL_ALPHA, sigma = FLEXCTRL_SIGMA;
  int it, i;
  rows_times(c->x, c->z); /* OSQP's warm start: z = A x */
  for (it = 1; it <= FLEXCTRL_MAX_ITER; ++it) {
    double slack_diag = FLEXCTRL_L2 + sigma + 3.0 * c->rho;
    for (i = 0; i < MR; ++i) t[i] = c->rho * c->z[i] - c->y[i];
    rows_t_times(t, rhs);
    for (i = 0; i < NW; ++i) rhs[i] += sigma * c->x[i] - c->q[i];
    memcpy(xt, rhs, NV * sizeof(double));
    solve_factored(c->L, xt);
    for (i = 0; i < NS; ++i) xt[NV + i] = rhs[NV + i] / slack_diag;
    rows_times(xt, zt);
    for (i = 0; i < NW; ++i) c->x[i] = alpha * xt[i] + (1.0 - alpha) * c->x[i];
    for (i = 0; i < MR; ++i) {
      double z_relaxed = alpha * zt[i] + (1.0 - alpha) * c->z[i];
      double z_new = fmin(fmax(z_relaxed + c->y[i] / c->rho, c->lo[i]), c->hi[i]);
      c->y[i] += c->rho * (z_relaxed - z_new);
      c->z[i] = z_new;
    }
    if (it % FLEXCTRL_CHECK_EVERY == 0) {
      double prim, dual, prim_n, dual_n;
      residuals(c, &prim, &dual, &prim_n, &dual_n);
      c->last_iterations = it;
      if (prim <= FLEXCTRL_EPS_ABS + FLEXCTRL_EPS_REL * prim_n &&
          dual <= FLEXCTRL_EPS_ABS + FLEXCTRL_EPS_REL * dual_n)
        return 1;
      if (FLEXCTRL_ADAPT_INTERVAL > 0 && it % FLEXCTRL_ADAPT_INTERVAL == 0) {
        double rho = c->rho * sqrt((prim / (prim_n + 1e-30)) / (dual / (dual_n + 1e-30)));
        rho = fmin(fmax(rho, RHO_MIN), RHO_MAX);
        if (rho > 5.0 * c->rho || rho < c->rho / 5.0) {
          c->rho = rho;
          factor(c->L, c->rho);
        }
      }
    }
  }
  c->last_iterations = FLEXCTRL_MAX_ITER;
  return 0;
}

void flexctrl_reset(flexctrl_controller *c) {
  memset(c, 0, sizeof(*c));
  memcpy(c->u_prev, flexctrl_op_u, sizeof(c->u_prev));
  c->rho = FLEXCTRL_RHO0;
  factor(c->L, c->rho);
}

void flexctrl_set_applied(flexctrl_controller *c, const double u_applied[FLEXCTRL_N_U]) {
  memcpy(c->u_prev, u_applied, sizeof(c->u_prev));
}

/* This sample's QP vectors from p = [z, dv, dc]. */
static void qp_vectors(flexctrl_controller *c) {
  const double *z = c->p, *dv = c->p + FLEXCTRL_N_X;
  const double *dc = c->p + FLEXCTRL_N_X + FLEXCTRL_HORIZON * FLEXCTRL_N_U;
  int i, j;
  for (i = 0; i < NV; ++i) {
    double s = 0.0;
    for (j = 0; j < FLEXCTRL_N_X; ++j) s += flexctrl_qp_F[i * FLEXCTRL_N_X + j] * z[j];
    c->q[i] = s;
    c->lo[2 * NS + i] = flexctrl_qp_v_lo[i] - dv[i];
    c->hi[2 * NS + i] = flexctrl_qp_v_hi[i] - dv[i];
  }
  for (i = 0; i < NS; ++i) {
    double s = 0.0;
    for (j = 0; j < FLEXCTRL_N_X; ++j) s += flexctrl_qp_CP[i * FLEXCTRL_N_X + j] * z[j];
    c->q[NV + i] = FLEXCTRL_L1;
    c->lo[i] = -HUGE_VAL;
    c->hi[i] = (flexctrl_qp_c_hi[i] + (-s)) - dc[i];
    c->lo[NS + i] = (flexctrl_qp_c_lo[i] + (-s)) - dc[i];
    c->hi[NS + i] = HUGE_VAL;
    c->lo[2 * NS + NV + i] = 0.0;
    c->hi[2 * NS + NV + i] = HUGE_VAL;
  }
}

/* The solver's start: the last solution shifted a stage (FLEXCTRL_WARM 2), the last iterate
 * as it is (1), or zero (0). */
static void warm_start(flexctrl_controller *c) {
  int i;
  if (FLEXCTRL_WARM == 2 && c->have_w) {
    for (i = 0; i < NW; ++i) c->x[i] = c->w[flexctrl_qp_shift_w[i]];
    for (i = 0; i < MR; ++i) c->y[i] = c->y_last[flexctrl_qp_shift_y[i]];
  } else if (FLEXCTRL_WARM == 0 || !c->have_iterate) {
    memset(c->x, 0, sizeof(c->x));
    memset(c->y, 0, sizeof(c->y));
  }
}

/* The torque when the QP is not solved: the plan shifted, then the LQR move; or the last torque. */
static void fallback(flexctrl_controller *c, double *v) {
  int i;
  c->fallbacks++;
  c->age++;
  if (FLEXCTRL_FALLBACK_HOLD) {
    memcpy(v, c->u_prev, FLEXCTRL_N_U * sizeof(double));
    return;
  }
  if (FLEXCTRL_FALLBACK_SHIFT && c->have_w && c->age < FLEXCTRL_HORIZON)
    memcpy(v, c->plan_u + c->age * FLEXCTRL_N_U, FLEXCTRL_N_U * sizeof(double));
  else
    memcpy(v, c->u_lqr, FLEXCTRL_N_U * sizeof(double));
  if (c->have_w) {
    double shifted[NW];
    for (i = 0; i < NW; ++i) shifted[i] = c->w[flexctrl_qp_shift_w[i]];
    memcpy(c->w, shifted, sizeof(shifted));
  }
}

int flexctrl_step_ref(flexctrl_controller *c, const double *x_ref, const double *u_ref,
                      const double y[FLEXCTRL_N_Y], double u[FLEXCTRL_N_U]) {
  const casadi_real *arg[FLEXCTRL_PRE_SZ_ARG];
  casadi_real *res[FLEXCTRL_PRE_SZ_RES];
  double xi_next[FLEXCTRL_N_XI + 1], p[FLEXCTRL_N_P], u_lqr[FLEXCTRL_N_U], v[FLEXCTRL_N_U];
  int i, j, rc, status = FLEXCTRL_OK;
  for (i = 0; i < FLEXCTRL_N_Y; ++i)
    if (!isfinite(y[i])) return FLEXCTRL_E_MEASUREMENT;
  res[0] = xi_next;
  res[1] = p;
  res[2] = u_lqr;
  if (!c->started) {
    arg[0] = y;
    arg[1] = c->u_prev;
    arg[2] = x_ref;
    arg[3] = u_ref;
    rc = flexctrl_pre_start(arg, res, c->iw, c->cw, 0);
  } else {
    arg[0] = c->xi;
    arg[1] = y;
    arg[2] = c->u_prev;
    arg[3] = x_ref;
    arg[4] = u_ref;
    rc = flexctrl_pre(arg, res, c->iw, c->cw, 0);
  }
  if (rc) return FLEXCTRL_E_INTERNAL;
  for (i = 0; i < FLEXCTRL_N_P; ++i)
    if (!isfinite(p[i])) return FLEXCTRL_E_INTERNAL;
  memcpy(c->xi, xi_next, FLEXCTRL_N_XI * sizeof(double));
  memcpy(c->p, p, sizeof(p));
  memcpy(c->u_lqr, u_lqr, sizeof(u_lqr));
  c->started = 1;
  qp_vectors(c);
  warm_start(c);
  c->have_iterate = 1;
  if (admm(c)) {
    memcpy(c->w, c->x, sizeof(c->w));
    memcpy(c->y_last, c->y, sizeof(c->y_last));
    c->have_w = 1;
    c->age = 0;
    for (j = 0; j < FLEXCTRL_HORIZON; ++j)
      for (i = 0; i < FLEXCTRL_N_U; ++i)
        c->plan_u[j * FLEXCTRL_N_U + i] =
            u_ref[j * FLEXCTRL_N_U + i] + c->w[j * FLEXCTRL_N_U + i] * flexctrl_qp_Su[i];
    memcpy(v, c->plan_u, sizeof(v));
  } else {
    memcpy(c->y_last, c->y, sizeof(c->y_last));
    status = FLEXCTRL_FALLBACK;
    fallback(c, v);
  }
  for (i = 0; i < FLEXCTRL_N_U; ++i) {
    double ui = v[i];
    if (ui > flexctrl_torque_limits[i]) ui = flexctrl_torque_limits[i];
    if (ui < -flexctrl_torque_limits[i]) ui = -flexctrl_torque_limits[i];
    u[i] = ui;
    c->u_prev[i] = ui;
  }
  c->steps++;
  return status;
}

int flexctrl_step(flexctrl_controller *c, long k, const double y[FLEXCTRL_N_Y],
                  double u[FLEXCTRL_N_U]) {
  double xw[FLEXCTRL_REF_WINDOW * FLEXCTRL_N_X], uw[FLEXCTRL_REF_WINDOW * FLEXCTRL_N_U];
  flexctrl_reference_window(k, xw, uw);
  return flexctrl_step_ref(c, xw, uw, y, u);
}
