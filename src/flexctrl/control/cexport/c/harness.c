/* harness.c -- replays a closed loop recorded in Python and compares the C torques with Python's.
 *
 * usage: ./harness [replay.csv [repeats]]
 *
 * replay.csv: one row per controller sample k: k, t, y[N_Y], u_prev[N_U], x_ref[N_X], u_ref[N_U],
 * u[N_U] (u_prev the torque held during the sample that just ended, u Python's torque).
 *
 * Passes over the recording:
 *   A  reference from the exported table; before each step the recorded applied torque is given
 *      (flexctrl_set_applied), so every step sees exactly the inputs Python's step saw.  [checked]
 *   B  as A without flexctrl_set_applied: the controller feeds its own torque back to its
 *      estimator; with the plant absent that is the controller's own dynamics.  [reported]
 *   C  reference rows given at run time (flexctrl_step_ref) from the recording.   [checked]
 *   D  as A with a NaN measurement offered before sample K/2: it must be rejected
 *      (FLEXCTRL_E_MEASUREMENT) and change nothing (torques equal to pass A's bit for bit).
 *   T  pass A repeated `repeats` times (default 20), every flexctrl_step timed.
 * Check per joint i: max_k |u_C - u_py| <= CHECK_REL * max_k |u_py,i| + check_abs[i].
 * With exact.csv beside replay.csv (an optimising controller: u*, the same QPs solved to a tight
 * tolerance on the recorded inputs) also max_k |u_C - u*| <= EXACT_FACTOR * max_k |u_py - u*|:
 * the C solver is no farther from the QP's solution than Python's.
 * Exit status 0 when every check passes, 1 when one fails, 2 on unreadable input.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "flexctrl_controller.h"
#include "harness_check.h"

#define NCOL (2 + FLEXCTRL_N_Y + FLEXCTRL_N_U + FLEXCTRL_N_X + FLEXCTRL_N_U + FLEXCTRL_N_U)
#define C_Y 2
#define C_UPREV (C_Y + FLEXCTRL_N_Y)
#define C_XREF (C_UPREV + FLEXCTRL_N_U)
#define C_UREF (C_XREF + FLEXCTRL_N_X)
#define C_U (C_UREF + FLEXCTRL_N_U)

static double *rows; /* K x NCOL */
static long K;
static double *exact; /* K x N_U, or NULL without exact.csv */

/* Reads a CSV with a header line and `ncol` numbers a row into a growing array. */
static double *read_csv(const char *path, int ncol, long *count, int required) {
  FILE *f = fopen(path, "r");
  char *line = NULL;
  size_t cap = 0, n_alloc = 1024;
  double *data;
  *count = 0;
  if (!f) {
    if (required) perror(path);
    return NULL;
  }
  data = malloc(n_alloc * ncol * sizeof(double));
  if (getline(&line, &cap, f) < 0) { fclose(f); free(data); return NULL; }
  while (getline(&line, &cap, f) > 0) {
    char *p = line, *end;
    int j;
    if (*count == (long)n_alloc) {
      n_alloc *= 2;
      data = realloc(data, n_alloc * ncol * sizeof(double));
    }
    for (j = 0; j < ncol; ++j) {
      data[*count * ncol + j] = strtod(p, &end);
      if (end == p) {
        fprintf(stderr, "%s: row %ld column %d unreadable\n", path, *count + 1, j + 1);
        exit(2);
      }
      p = (*end == ',') ? end + 1 : end;
    }
    (*count)++;
  }
  free(line);
  fclose(f);
  return data;
}

static double now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int by_value(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* One pass ('A', 'B', 'C' or 'D'); torques into U (K x N_U); returns the steps that failed. */
static long run_pass(char mode, double *U, int *iterations, double *times) {
  static flexctrl_controller c;
  double xw[FLEXCTRL_REF_WINDOW * FLEXCTRL_N_X], uw[FLEXCTRL_REF_WINDOW * FLEXCTRL_N_U];
  long k, failed = 0;
  int j, i, rc;
  flexctrl_reset(&c);
  for (k = 0; k < K; ++k) {
    const double *r = rows + k * NCOL;
    double t0 = 0.0;
    if (mode != 'B') flexctrl_set_applied(&c, r + C_UPREV);
    if (mode == 'D' && k == K / 2) {
      double y_bad[FLEXCTRL_N_Y], u_untouched[FLEXCTRL_N_U] = {0};
      memcpy(y_bad, r + C_Y, sizeof(y_bad));
      y_bad[FLEXCTRL_N_Y - 1] = NAN;
      if (flexctrl_step(&c, k, y_bad, u_untouched) != FLEXCTRL_E_MEASUREMENT) failed++;
      for (i = 0; i < FLEXCTRL_N_U; ++i) failed += u_untouched[i] != 0.0;
    }
    if (mode == 'C') {
      for (j = 0; j < FLEXCTRL_REF_WINDOW; ++j) {
        long row = k + j < K ? k + j : K - 1;
        for (i = 0; i < FLEXCTRL_N_X; ++i) xw[j * FLEXCTRL_N_X + i] = rows[row * NCOL + C_XREF + i];
        for (i = 0; i < FLEXCTRL_N_U; ++i) uw[j * FLEXCTRL_N_U + i] = rows[row * NCOL + C_UREF + i];
      }
      rc = flexctrl_step_ref(&c, xw, uw, r + C_Y, U + k * FLEXCTRL_N_U);
    } else {
      if (times) t0 = now();
      rc = flexctrl_step(&c, k, r + C_Y, U + k * FLEXCTRL_N_U);
      if (times) times[k] = now() - t0;
    }
    if (rc < 0) failed++;
    if (iterations) iterations[k] = c.last_iterations;
  }
  return failed;
}

/* Largest difference per joint from Python's torques against the bound; 1 when within it. */
static int compare(const char *what, const double *U, int checked) {
  int i, ok = 1;
  long k;
  printf("%s\n", what);
  for (i = 0; i < FLEXCTRL_N_U; ++i) {
    double scale = 0.0, worst = 0.0, bound;
    long at = 0;
    for (k = 0; k < K; ++k) {
      double up = rows[k * NCOL + C_U + i], d = fabs(U[k * FLEXCTRL_N_U + i] - up);
      if (fabs(up) > scale) scale = fabs(up);
      if (!(d <= worst)) { worst = d; at = k; } /* a NaN counts as the worst */
    }
    bound = CHECK_REL * scale + check_abs[i];
    printf("  tau%d: max |u_C - u_py| = %.3e N m at sample %ld, %.3e of max |u_py| = %.4g N m;"
           " bound %.3e N m %s\n", i + 1, worst, at, scale > 0 ? worst / scale : worst, scale,
           bound, checked ? (worst <= bound ? "ok" : "FAIL") : "(not checked)");
    if (checked && !(worst <= bound)) ok = 0;
  }
  return ok;
}

static int compare_exact(const double *U) {
  int i, ok = 1;
  long k;
  printf("distance from the QP's solution u* (exact.csv), pass A:\n");
  for (i = 0; i < FLEXCTRL_N_U; ++i) {
    double dc_max = 0.0, dp_max = 0.0;
    for (k = 0; k < K; ++k) {
      double us = exact[k * FLEXCTRL_N_U + i];
      double dc = fabs(U[k * FLEXCTRL_N_U + i] - us), dp = fabs(rows[k * NCOL + C_U + i] - us);
      if (!(dc <= dc_max)) dc_max = dc;
      if (dp > dp_max) dp_max = dp;
    }
    printf("  tau%d: C %.3e N m, Python %.3e N m; bound %.3g x Python's %s\n", i + 1, dc_max,
           dp_max, EXACT_FACTOR, dc_max <= EXACT_FACTOR * dp_max ? "ok" : "FAIL");
    if (!(dc_max <= EXACT_FACTOR * dp_max)) ok = 0;
  }
  return ok;
}

static void write_torques(const double *U, const int *iterations) {
  FILE *out = fopen("c_torques.csv", "w");
  long k;
  int i;
  if (!out) return;
  fprintf(out, "k,iterations");
  for (i = 0; i < FLEXCTRL_N_U; ++i) fprintf(out, ",u%d", i + 1);
  fprintf(out, "\n");
  for (k = 0; k < K; ++k) {
    fprintf(out, "%ld,%d", k, iterations[k]);
    for (i = 0; i < FLEXCTRL_N_U; ++i) fprintf(out, ",%.17g", U[k * FLEXCTRL_N_U + i]);
    fprintf(out, "\n");
  }
  fclose(out);
}

static void report_times(int repeats, double *U, const int *iterations) {
  double *all = malloc((size_t)K * repeats * sizeof(double)), *times = all;
  long k, n = (long)K * repeats, it_sum = 0;
  int r;
  for (r = 0; r < repeats; ++r, times += K) run_pass('A', U, NULL, times);
  qsort(all, n, sizeof(double), by_value);
  for (k = 0; k < K; ++k) it_sum += iterations[k];
  printf("C step time over %d x %ld steps: median %.2f us, p95 %.2f us, max %.2f us"
         " (mean solver iterations %.1f)\n", repeats, K, 1e6 * all[n / 2],
         1e6 * all[(long)(0.95 * (n - 1))], 1e6 * all[n - 1], (double)it_sum / K);
  free(all);
}

int main(int argc, char **argv) {
  const char *path = argc > 1 ? argv[1] : "replay.csv";
  int repeats = argc > 2 ? atoi(argv[2]) : 20, ok = 1, *iterations;
  double *UA, *UB, *UC, *UD;
  long failed, n_exact = 0;
  char exact_path[4096];
  const char *slash = strrchr(path, '/');
  rows = read_csv(path, NCOL, &K, 1);
  if (!rows || K == 0) {
    fprintf(stderr, "%s: no recorded samples (export with a replay to check)\n", path);
    return 2;
  }
  snprintf(exact_path, sizeof exact_path, "%.*sexact.csv", slash ? (int)(slash - path + 1) : 0,
           path);
  exact = read_csv(exact_path, 1 + FLEXCTRL_N_U, &n_exact, 0);
  if (exact) { /* drop the k column */
    long k;
    int i;
    if (n_exact != K) {
      fprintf(stderr, "%s: %ld rows; expected %ld\n", exact_path, n_exact, K);
      return 2;
    }
    for (k = 0; k < K; ++k)
      for (i = 0; i < FLEXCTRL_N_U; ++i)
        exact[k * FLEXCTRL_N_U + i] = exact[k * (1 + FLEXCTRL_N_U) + 1 + i];
  }
  UA = malloc(K * FLEXCTRL_N_U * sizeof(double));
  UB = malloc(K * FLEXCTRL_N_U * sizeof(double));
  UC = malloc(K * FLEXCTRL_N_U * sizeof(double));
  UD = malloc(K * FLEXCTRL_N_U * sizeof(double));
  iterations = malloc(K * sizeof(int));
  printf("replay %s: %ld samples, Ts = %g s, %d measurements, %d torques\n", path, K,
         FLEXCTRL_SAMPLE_TIME, FLEXCTRL_N_Y, FLEXCTRL_N_U);
  printf("check: %s\n", CHECK_DOC);
  failed = run_pass('A', UA, iterations, NULL);
  run_pass('B', UB, NULL, NULL);
  failed += run_pass('C', UC, NULL, NULL);
  {
    long failed_d = run_pass('D', UD, NULL, NULL);
    int same = memcmp(UA, UD, K * FLEXCTRL_N_U * sizeof(double)) == 0;
    printf("pass D (a NaN measurement offered before sample %ld): %s, torques %s pass A's\n",
           K / 2, failed_d ? "NOT rejected cleanly" : "rejected",
           same ? "equal to" : "DIFFER from");
    if (failed_d || !same) ok = 0;
  }
  ok &= compare("pass A (table reference, recorded applied torque):", UA, 1);
  ok &= compare("pass B (table reference, own torque fed back):", UB, 0);
  ok &= compare("pass C (reference rows given at run time):", UC, 1);
  if (exact) ok &= compare_exact(UA);
  if (failed) {
    printf("steps that returned an error: %ld\n", failed);
    ok = 0;
  }
  write_torques(UA, iterations);
  if (repeats > 0) report_times(repeats, UB, iterations);
  printf("%s\n", ok ? "CHECK PASSED" : "CHECK FAILED");
  return ok ? 0 : 1;
}
