/* A fixed-rate controller on the generated control law, in a closed loop with the generated plant.
 *
 * Every control period the step reads the measurement and one reference sample r (5n: y_d and
 * its four derivatives), calls the emitted integral sliding-mode law and writes the torques u (n)
 * and advances the controller state z by forward Euler over the period. link1: the state law
 * <model>_control_ismc(x, z, r, p_nom, gains) on the plant state x (4n). panda (-DFJM_TORQUE=1):
 * the torque-sensed law <model>_control_ismc_tau(m, z, r, p_nom, gains) on what a torque-sensed
 * arm measures, m = [q; dq; tau_J; dtau_J; dq_m] (5n), tau_J = K (q_m - q) and dtau_J = K (dq_m - dq)
 * formed here from the simulated plant with its TRUE stiffness (the sensor measures the real
 * spring; the law itself never sees K); generated/<model>/<model>.h documents every layout. All work arrays are static, sized at compile time
 * from the generated _work() functions (sizes.h, written by work_sizes.c): the step allocates
 * nothing. The plant is the generated model, x' = f(x; p_true) + g(x; p_true) u, integrated by
 * RK4 (PLANT_SUBSTEPS steps per control period) with the torque held.
 *
 *   realtime run [u.bin]      10 s closed loop: summary on stdout, u trajectory (doubles) to u.bin
 *   realtime bench [steps]    time `steps` controller steps (default 10^6) inside the closed loop,
 *                             and one alpha + beta call at the same states: median, worst case
 *   realtime compare a.bin b.bin   max |u_a - u_b| (float vs double build of the same run)
 *
 * Build: see Makefile (-DFJM_MODEL=link1 -DFJM_HEADER='"link1.h"', -Dcasadi_real=float for
 * single precision); -std=c99 -Wall -Wextra -Werror -pedantic.
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include FJM_HEADER
#include "sizes.h"
#include "params.h"
#include "plant.h" /* work arrays, FN(), the TRUE plant on RK4 substeps, timing (shared with designed_controller.c) */

/* ---- configuration per model (gains are runtime inputs of the law: no re-derive to retune) ---- */
#if NU == 7 /* panda: torque-sensed, sines about Franka's ready pose, 1 kHz, effort limits with anti-windup */
/* hand-found gains (fjm_runtime.control.defaults.PANDA_ISMC_TAU_START), not the result of a search;
 * the controller `fjm design` verified (its gains, noise, delay) is designed_controller.c */
#define RATE_HZ 1000.0
#define LAMBDA 80.0
#define K_S 2000.0
#define DELTA 10.0
#define K_LIN 400.0
#define PLANT_SUBSTEPS 10 /* 1e-4 s: the wrist's ~670 rad/s mode needs it (the runtime's substep rule) */
static const double REF_CENTER[NU] = {0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785};
static const double REF_AMPL[NU] = {0.3, 0.25, 0.3, 0.3, 0.4, 0.3, 0.4};
static const double REF_OMEGA[NU] = {1.0, 1.2, 0.9, 1.1, 1.5, 1.3, 1.7};
static const double U_MAX[NU] = {87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0};
#define USE_LIMIT 1.0
#elif NU == 1 /* link1: the paper's 0.5 sin t at 1 kHz */
#define RATE_HZ 1000.0
#define LAMBDA 8.0
#define K_S 1000.0
#define DELTA 5.0
static const double REF_CENTER[NU] = {0.0};
static const double REF_AMPL[NU] = {0.5};
static const double REF_OMEGA[NU] = {1.0};
static const double U_MAX[NU] = {100.0};
#define USE_LIMIT 0.0
#define K_LIN 0.0
#define PLANT_SUBSTEPS 4
#else
#error "realtime.c: add a configuration block for this number of joints"
#endif
#ifndef FJM_TORQUE
#define FJM_TORQUE 0
#endif
#if FJM_TORQUE
#define LAW_FN _control_ismc_tau
static const double K_SENSOR[NU] = K_TRUE_VALUES; /* the TRUE stiffness: the torque sensor's spring */
#else
#define LAW_FN _control_ismc
#endif
#define DURATION 10.0
#define N_RUN ((long)(DURATION * RATE_HZ + 0.5))
#define N_BENCH_MAX 1000000L

static casadi_real p_nom[NP] = P_NOMINAL;

typedef struct {
  casadi_real z[NZ + 1];      /* controller state: integral of e1 (n) */
  casadi_real gains[NGAINS];  /* layout: control_ismc in the header of <model>.h */
  casadi_real dt;             /* control period, s */
} controller_t;

/* Pack the gains of control_ismc: c (4), k_s (n), delta (n), sign, k_lin (n), u_max (n), limit,
 * anti_windup, use_beta_hat, beta_hat (n*n). Returns 0 if the layout matches NGAINS. */
static int controller_init(controller_t* c) {
  int i, k = 0;
  const double lam = LAMBDA;
  const double coef[4] = {lam * lam * lam * lam, 4 * lam * lam * lam, 6 * lam * lam, 4 * lam};
  memset(c, 0, sizeof *c);
  c->dt = (casadi_real)(1.0 / RATE_HZ);
  for (i = 0; i < 4; ++i) c->gains[k++] = (casadi_real)coef[i];
  for (i = 0; i < NU; ++i) c->gains[k++] = (casadi_real)K_S;
  for (i = 0; i < NU; ++i) c->gains[k++] = (casadi_real)DELTA;
  c->gains[k++] = 0;                                   /* sign: 0 = sat(s / delta) */
  for (i = 0; i < NU; ++i) c->gains[k++] = (casadi_real)K_LIN;
  for (i = 0; i < NU; ++i) c->gains[k++] = (casadi_real)U_MAX[i];
  c->gains[k++] = (casadi_real)USE_LIMIT;
  c->gains[k++] = 1;                                   /* anti_windup */
  c->gains[k++] = 0;                                   /* use_beta_hat: 0 = beta(x; p_nom) */
  for (i = 0; i < NU * NU; ++i) c->gains[k++] = 0;     /* beta_hat (unused) */
  return k == NGAINS ? 0 : 1;
}

/* What the controller reads: x itself (state law) or m = [q; dq; tau_J; dtau_J; dq_m] (torque-sensed). */
#if FJM_TORQUE
#define NMEAS (5 * NU)
static void measure(const casadi_real* x, casadi_real* m) {
  int i;
  for (i = 0; i < NU; ++i) {
    m[i] = x[i];
    m[NU + i] = x[NU + i];
    m[2 * NU + i] = (casadi_real)(K_SENSOR[i] * ((double)x[2 * NU + i] - (double)x[i]));
    m[3 * NU + i] = (casadi_real)(K_SENSOR[i] * ((double)x[3 * NU + i] - (double)x[NU + i]));
    m[4 * NU + i] = x[3 * NU + i];
  }
}
#else
#define NMEAS NX
static void measure(const casadi_real* x, casadi_real* m) { memcpy(m, x, sizeof(casadi_real) * NX); }
#endif

/* One control period: u from (x, r); z advanced by forward Euler. No allocation. */
static int controller_step(controller_t* c, const casadi_real* x, const casadi_real* r, casadi_real* u) {
  casadi_real zdot[NZ + 1], m[NMEAS];
  int i, flag;
  measure(x, m);
  arg[0] = m; arg[1] = c->z; arg[2] = r; arg[3] = p_nom; arg[4] = c->gains;
  res[0] = u; res[1] = 0; res[2] = zdot; res[3] = 0; res[4] = 0; /* s, u_cmd, y_hat not needed */
  flag = FN(LAW_FN)(arg, res, iw, w, 0);
  for (i = 0; i < NZ; ++i) c->z[i] += c->dt * zdot[i];
  return flag;
}

static void reference(double t, casadi_real* r) {
  int i, d;
  for (i = 0; i < NU; ++i) {
    const double a = REF_AMPL[i], om = REF_OMEGA[i], ph = om * t - 0.5 * 3.14159265358979323846;
    const double s = sin(ph), co = cos(ph);
    const double v[5] = {REF_CENTER[i] + a * s, a * om * co, -a * om * om * s, -a * om * om * om * co,
                         a * om * om * om * om * s};
    for (d = 0; d < 5; ++d) r[d * NU + i] = (casadi_real)v[d];
  }
}

static void initial_state(casadi_real* x) {
  casadi_real r[5 * NU];
  int i;
  memset(x, 0, sizeof(casadi_real) * NX);
  reference(0.0, r);
  for (i = 0; i < NU; ++i) x[i] = x[2 * NU + i] = r[i]; /* at rest, springs relaxed */
#if FJM_TORQUE
  hold_gravity(x, K_SENSOR); /* at rest holding gravity on the TRUE plant */
#endif
}

static double step_ns[N_BENCH_MAX], ab_ns[N_BENCH_MAX];

static int run(const char* path) {
  controller_t c;
  casadi_real x[NX], r[5 * NU], u[NU];
  double sum_e2 = 0, max_u = 0, max_e = 0;
  long k;
  int i, j;
  FILE* out = NULL;
  if (controller_init(&c)) { fprintf(stderr, "gains layout does not match NGAINS\n"); return 1; }
  if (path && !(out = fopen(path, "wb"))) { perror(path); return 1; }
  initial_state(x);
  for (k = 0; k <= N_RUN; ++k) {
    const double t = (double)k / RATE_HZ;
    reference(t, r);
    if (controller_step(&c, x, r, u)) { fprintf(stderr, "control law failed\n"); return 1; }
    for (i = 0; i < NU; ++i) {
      const double e = (double)x[i] - (double)r[i], ud = (double)u[i];
      sum_e2 += e * e;
      if (fabs(ud) > max_u) max_u = fabs(ud);
      if (k == N_RUN && fabs(e) > max_e) max_e = fabs(e);
      if (out) fwrite(&ud, sizeof ud, 1, out);
    }
    for (i = 0; i < NX; ++i)
      if (!(fabs((double)x[i]) < 1e6)) { fprintf(stderr, "diverged at t = %g s\n", t); return 1; }
    if (k == N_RUN) break;
    for (j = 0; j < PLANT_SUBSTEPS; ++j)
      if (plant_rk4(x, u, 1.0 / (RATE_HZ * PLANT_SUBSTEPS))) return 1;
  }
  if (out) fclose(out);
  printf("{\"model\": \"%s\", \"real\": \"%s\", \"rate_hz\": %g, \"seconds\": %g, \"final_error\": %.6g, "
         "\"rms_error\": %.6g, \"max_abs_u\": %.6g}\n", FJM_MODEL_STR, sizeof(casadi_real) == 4 ? "float" : "double",
         RATE_HZ, DURATION, max_e, sqrt(sum_e2 / ((double)(N_RUN + 1) * NU)), max_u);
  return 0;
}

static int bench(long steps) {
  controller_t c;
  casadi_real x[NX], r[5 * NU], u[NU], alpha[NU], beta[NU * NU];
  long k;
  int j;
  double t0, med, ab_med;
  if (steps < 1 || steps > N_BENCH_MAX) { fprintf(stderr, "steps: 1 .. %ld\n", N_BENCH_MAX); return 2; }
  if (controller_init(&c)) return 1;
  initial_state(x);
  for (k = 0; k < steps; ++k) {
    reference(fmod((double)k / RATE_HZ, DURATION), r);
    t0 = now_ns();
    if (controller_step(&c, x, r, u)) return 1;
    step_ns[k] = now_ns() - t0;
    /* the reference cost: one alpha and one beta call at the same state */
    t0 = now_ns();
    arg[0] = x; arg[1] = p_nom; res[0] = alpha;
    if (FN(_alpha)(arg, res, iw, w, 0)) return 1;
    res[0] = beta;
    if (FN(_beta)(arg, res, iw, w, 0)) return 1;
    ab_ns[k] = now_ns() - t0;
    for (j = 0; j < PLANT_SUBSTEPS; ++j)
      if (plant_rk4(x, u, 1.0 / (RATE_HZ * PLANT_SUBSTEPS))) return 1;
    if ((k + 1) % N_RUN == 0) { initial_state(x); memset(c.z, 0, sizeof c.z); } /* restart the run */
  }
  qsort(step_ns, (size_t)steps, sizeof(double), cmp_double);
  qsort(ab_ns, (size_t)steps, sizeof(double), cmp_double);
  med = step_ns[steps / 2];
  ab_med = ab_ns[steps / 2];
  printf("{\"model\": \"%s\", \"real\": \"%s\", \"steps\": %ld, \"step_median_ns\": %.1f, \"step_max_ns\": %.1f, "
         "\"step_p999_ns\": %.1f, \"alpha_beta_median_ns\": %.1f, \"alpha_beta_max_ns\": %.1f, "
         "\"ratio_median\": %.3f, \"period_ns\": %.1f}\n",
         FJM_MODEL_STR, sizeof(casadi_real) == 4 ? "float" : "double", steps, med, step_ns[steps - 1],
         step_ns[(long)(0.999 * (double)(steps - 1))], ab_med, ab_ns[steps - 1], med / ab_med, 1e9 / RATE_HZ);
  return 0;
}

static int compare(const char* a, const char* b) {
  FILE *fa = fopen(a, "rb"), *fb = fopen(b, "rb");
  double va, vb, dev = 0, scale = 0;
  long count = 0;
  if (!fa || !fb) { fprintf(stderr, "cannot open %s or %s\n", a, b); return 1; }
  while (fread(&va, sizeof va, 1, fa) == 1 && fread(&vb, sizeof vb, 1, fb) == 1) {
    if (fabs(va - vb) > dev) dev = fabs(va - vb);
    if (fabs(vb) > scale) scale = fabs(vb);
    ++count;
  }
  fclose(fa);
  fclose(fb);
  printf("{\"model\": \"%s\", \"samples\": %ld, \"max_abs_u_deviation\": %.6g, \"max_abs_u\": %.6g, "
         "\"relative\": %.6g}\n", FJM_MODEL_STR, count, dev, scale, scale > 0 ? dev / scale : dev);
  return count > 0 ? 0 : 1;
}

int main(int argc, char** argv) {
  if (argc >= 2 && strcmp(argv[1], "run") == 0) return run(argc >= 3 ? argv[2] : NULL);
  if (argc >= 2 && strcmp(argv[1], "bench") == 0) return bench(argc >= 3 ? atol(argv[2]) : N_BENCH_MAX);
  if (argc == 4 && strcmp(argv[1], "compare") == 0) return compare(argv[2], argv[3]);
  fprintf(stderr, "usage: %s run [u.bin] | bench [steps] | compare a.bin b.bin\n", argv[0]);
  return 2;
}
