
void flexctrl_reference_window(long k, double *x_ref, double *u_ref) {
  long j, i, row;
  for (j = 0; j < FLEXCTRL_REF_WINDOW; ++j) {
    row = k + j;
    if (row < 0) row = 0;
    if (row > FLEXCTRL_REF_ROWS - 1) row = FLEXCTRL_REF_ROWS - 1;
    for (i = 0; i < FLEXCTRL_N_X; ++i)
      x_ref[j * FLEXCTRL_N_X + i] = flexctrl_ref_x[row * FLEXCTRL_N_X + i];
    for (i = 0; i < FLEXCTRL_N_U; ++i)
      u_ref[j * FLEXCTRL_N_U + i] = flexctrl_ref_u[row * FLEXCTRL_N_U + i];
  }
}
