  double xi[FLEXCTRL_N_XI + 1];           /* the estimator's memory (deviation estimate) */
  double p[FLEXCTRL_N_P], u_lqr[FLEXCTRL_N_U]; /* this sample's QP parameters, LQR move */
  double q[{nw}], lo[{mr}], hi[{mr}];       /* this sample's QP */
  double x[{nw}], z[{mr}], y[{mr}];         /* ADMM iterates */
  double w[{nw}], y_last[{mr}];             /* the last solution, the last duals */
  double L[{nv} * {nv}];                    /* Cholesky factor at rho */
  double rho;                              /* ADMM step, adapted */
  double plan_u[FLEXCTRL_HORIZON * FLEXCTRL_N_U]; /* planned torques of the last solution, N m */
  int have_w, have_iterate, age;           /* a solution, an iterate; samples since the solution */
  long long iw[FLEXCTRL_PRE_SZ_IW + 1];   /* work arrays of the generated code */
  double cw[FLEXCTRL_PRE_SZ_W + 1];
