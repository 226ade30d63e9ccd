/* The controller `fjm design` verified, as the library `fjm export controller` writes, in a closed loop.
 *
 * The controller is the exported library of a design file (default: the Panda's shipped design,
 * fjm_runtime/control/designed/panda_ismc_tau_1000hz_d1.json: torque-sensed integral SMC at 1 kHz with
 * the gains `fjm design` found, the dtau_J filter, one sample of delay with the nominal-model
 * prediction, the torque limits with anti-windup). This program only does what a robot does around it:
 *
 *   - the plant: the generated model, x' = f(x; p_true) + g(x; p_true) u, RK4 with PLANT_SUBSTEPS steps
 *     per period (the design's substeps), u held over the period; p_true = the defaults with every
 *     stiffness x K_TRUE_SCALE (make K_TRUE=...), unknown to the controller; it starts at rest holding
 *     gravity;
 *   - the sensor: the raw reading [q; dq; tau_J; dtau_J; dq_m] (torque sensing) or [q; dq; q_m; dq_m],
 *     tau_J = K_true (q_m - q), with the design's white noise on every slot (its own generator here,
 *     not fjm's sequence), encoder quantization and a tau_J offset when the design's sensor has them;
 *   - every period: status = CTRL_STEP(&ctrl, m, r, u). The delay is the library's: it uses the reading
 *     of the previous period and predicts it forward (as fjm's sample step); u is applied at once.
 *
 *   designed_controller run [u.bin]   the design's task (10 s): the design's figures against its
 *                                     thresholds (one JSON line), exit 0 when they hold
 *   designed_controller bench [steps] time `steps` calls of CTRL_STEP inside the closed loop
 *                                     (clock_gettime around the call): median, 99.9th percentile, max
 *
 * Built by the Makefile (make designed / designed-bench): design.h and the library come from
 * export_design.py (fjm export controller). -std=c99 -Wall -Wextra -Werror -pedantic.
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "design.h"   /* the library's header (aliases CTRL_*), the task, the sensor, the plant parameters */
#include FJM_HEADER   /* the generated plant model: f, g, inertia */
#include "sizes.h"    /* work sizes of the generated model functions (work_sizes.c) */
#include "plant.h"    /* work arrays, FN(), the TRUE plant on RK4 substeps, timing (shared with realtime.c) */

#if CTRL_N != NU
#error "design.h: the design's model is not FJM_MODEL"
#endif
#define N_BENCH_MAX 1000000L

static const double K_TRUE[NU] = K_TRUE_VALUES, U_MAX_[NU] = U_MAX;
static const double NOISE[CTRL_NM] = NOISE_LEVELS, TAU_OFFSET[NU] = TAU_OFFSET_SIGMA;
static const double REF_C[NU] = REF_CENTER, REF_A[NU] = REF_AMPL, REF_W[NU] = REF_OMEGA;

static void reference(double t, double* r) {
  int i, d;
  for (i = 0; i < NU; ++i) {
    const double a = REF_A[i], om = REF_W[i], ph = om * t + REF_PHASE, s = sin(ph), co = cos(ph);
    const double v[5] = {REF_C[i] + a * s, a * om * co, -a * om * om * s, -a * om * om * om * co,
                         a * om * om * om * om * s};
    for (d = 0; d < 5; ++d) r[d * NU + i] = v[d];
  }
}

/* At rest holding gravity on the TRUE plant at q = q_d(0): q_m = q + K^-1 G(q), G = -D ddq at q_m = q. */
static void rest_state(casadi_real* x) {
  double r[5 * NU];
  int i;
  memset(x, 0, sizeof(casadi_real) * NX);
  reference(0.0, r);
  for (i = 0; i < NU; ++i) x[i] = x[2 * NU + i] = r[i];
  hold_gravity(x, K_TRUE);
}

/* ---- the sensor: white noise (xorshift64* + Box-Muller), quantization, tau_J offset ---- */
static unsigned long long rng_state = 0x9E3779B97F4A7C15ULL ^ NOISE_SEED;
static double uniform01(void) {
  rng_state ^= rng_state >> 12; rng_state ^= rng_state << 25; rng_state ^= rng_state >> 27;
  return ((double)((rng_state * 2685821657736338717ULL) >> 11) + 0.5) * (1.0 / 9007199254740992.0);
}
static double gaussian(void) {
  return sqrt(-2.0 * log(uniform01())) * cos(6.283185307179586 * uniform01());
}
static double quantize(double v, double step) { return step > 0 ? step * floor(v / step + 0.5) : v; }

static double tau_offset[NU];

/* The raw reading of state x (noisy = 0: the exact reading of a rest state, for CTRL_RESET). */
static void reading(const casadi_real* x, int noisy, CTRL_REAL* m) {
  double v[CTRL_NM];
  int i;
  for (i = 0; i < NU; ++i) {
    v[i] = x[i];
    v[NU + i] = x[NU + i];
#if SENSING_TORQUE
    v[2 * NU + i] = K_TRUE[i] * (x[2 * NU + i] - x[i]);
    v[3 * NU + i] = K_TRUE[i] * (x[3 * NU + i] - x[NU + i]);
    v[4 * NU + i] = MOTOR_ANGLE_IN_DQM ? x[2 * NU + i] : x[3 * NU + i];
#else
    v[2 * NU + i] = x[2 * NU + i];
    v[3 * NU + i] = x[3 * NU + i];
#endif
  }
  if (noisy) {
    for (i = 0; i < CTRL_NM; ++i) v[i] += NOISE[i] > 0 ? NOISE[i] * gaussian() : 0.0;
    for (i = 0; i < NU; ++i) {
      v[i] = quantize(v[i], Q_QUANT);
#if SENSING_TORQUE
      v[2 * NU + i] += tau_offset[i];
      if (MOTOR_ANGLE_IN_DQM) v[4 * NU + i] = quantize(v[4 * NU + i], Q_M_QUANT);
#else
      v[2 * NU + i] = quantize(v[2 * NU + i], Q_M_QUANT);
#endif
    }
  }
  for (i = 0; i < CTRL_NM; ++i) m[i] = (CTRL_REAL)v[i];
}

static double U[N_RUN + 1][NU], E[N_RUN + 1][NU], step_ns[N_BENCH_MAX];
static long n_status[4];

/* One run of the task from rest: U, E filled; step times into step_ns[offset..] when timing. */
static int run_task(CTRL_T* ctrl, long samples, double* times) {
  casadi_real x[NX];
  CTRL_REAL m[CTRL_NM], rr[5 * NU], u[NU];
  double r[5 * NU], t0 = 0;
  casadi_real uu[NU];
  long k;
  int i, j, st;
  rest_state(x);
  reading(x, 0, m);
  for (i = 0; i < NU; ++i) tau_offset[i] = TAU_OFFSET[i] > 0 ? TAU_OFFSET[i] * gaussian() : 0.0;
  if (CTRL_RESET(ctrl, m) != CTRL_OK) { fprintf(stderr, "reset refused the rest reading\n"); return 1; }
  for (k = 0; k < samples; ++k) {
    reference((double)k / RATE_HZ, r);
    for (i = 0; i < 5 * NU; ++i) rr[i] = (CTRL_REAL)r[i];
    reading(x, 1, m);
    if (times) t0 = now_ns();
    st = CTRL_STEP(ctrl, m, rr, u);
    if (times) times[k] = now_ns() - t0;
    if (st != CTRL_OK && st != CTRL_SATURATED && st != CTRL_INPUT_NOT_FINITE) {
      fprintf(stderr, "step refused its arguments (status %d)\n", (int)st);
      return 1;
    }
    ++n_status[st];
    for (i = 0; i < NU; ++i) {
      uu[i] = u[i];
      if (k <= N_RUN) { U[k][i] = uu[i]; E[k][i] = x[i] - r[i]; }
    }
    for (i = 0; i < NX; ++i)
      if (!(fabs(x[i]) < 1e6)) { fprintf(stderr, "diverged at t = %g s\n", (double)k / RATE_HZ); return 1; }
    for (j = 0; j < PLANT_SUBSTEPS; ++j)
      if (plant_rk4(x, uu, 1.0 / (RATE_HZ * PLANT_SUBSTEPS))) return 1;
  }
  return 0;
}

static int run(const char* path) {
  CTRL_T ctrl;
  double rms[NU], at_limit[NU], jitter[NU], worst_rms = 0, worst_lim = 0, worst_jit = 0;
  const long N = N_RUN, half = (N + 1) / 2, h = (long)(0.5 * 0.02 * RATE_HZ + 0.5), width = 2 * h + 1;
  long k, count;
  int i, holds;
  if (CTRL_INIT(&ctrl, NULL, NULL) != CTRL_OK) { fprintf(stderr, "init failed\n"); return 1; }
  if (run_task(&ctrl, N + 1, NULL)) return 1;
  for (i = 0; i < NU; ++i) {  /* fjm.sim.metrics: rms_second_half, time_at_limit, torque_jitter */
    double s2 = 0, lim = 0, sum = 0, sj = 0, sj2 = 0;
    for (k = half; k <= N; ++k) s2 += E[k][i] * E[k][i];
    rms[i] = sqrt(s2 / (double)(N + 1 - half));
    for (k = 0; k < N; ++k) lim += fabs(U[k][i]) >= U_MAX_[i] * (1.0 - 1e-9);
    at_limit[i] = lim / (double)N;
    for (k = 0; k < width; ++k) sum += U[k][i];          /* centred moving mean over the applied u_0..u_{N-1} */
    for (k = h, count = 0; k < N - h; ++k, ++count) {
      const double d = U[k][i] - sum / (double)width;
      sj += d; sj2 += d * d;
      if (k + h + 1 < N) sum += U[k + h + 1][i] - U[k - h][i];
    }
    jitter[i] = sqrt(sj2 / (double)count - (sj / (double)count) * (sj / (double)count));
    if (rms[i] > worst_rms) worst_rms = rms[i];
    if (at_limit[i] > worst_lim) worst_lim = at_limit[i];
    if (i < JITTER_JOINTS && jitter[i] > worst_jit) worst_jit = jitter[i];
  }
  holds = worst_rms <= MAX_RMS && worst_lim <= MAX_AT_LIMIT && worst_jit <= MAX_JITTER;
  if (path) {
    FILE* out = fopen(path, "wb");
    if (!out) { perror(path); return 1; }
    fwrite(U, sizeof(double), (size_t)(N + 1) * NU, out);
    fclose(out);
  }
  printf("{\"design\": \"%s\", \"real\": \"%s\", \"rate_hz\": %g, \"seconds\": %g, \"k_true\": %g, "
         "\"rms_second_half\": [", DESIGN_NAME, sizeof(CTRL_REAL) == 4 ? "float" : "double", RATE_HZ, DURATION,
         K_TRUE_SCALE);
  for (i = 0; i < NU; ++i) printf("%s%.4g", i ? ", " : "", rms[i]);
  printf("], \"time_at_limit\": [");
  for (i = 0; i < NU; ++i) printf("%s%.4g", i ? ", " : "", at_limit[i]);
  printf("], \"torque_jitter\": [");
  for (i = 0; i < NU; ++i) printf("%s%.4g", i ? ", " : "", jitter[i]);
  printf("], \"worst_rms\": %.4g, \"worst_at_limit\": %.4g, \"worst_jitter_1_%d\": %.4g, \"max_rms\": %g, "
         "\"max_at_limit\": %g, \"max_jitter\": %g, \"status_ok\": %ld, \"status_saturated\": %ld, "
         "\"status_not_finite\": %ld, \"holds\": %s}\n", worst_rms, worst_lim, JITTER_JOINTS, worst_jit, MAX_RMS,
         MAX_AT_LIMIT, MAX_JITTER, n_status[0], n_status[1], n_status[2], holds ? "true" : "false");
  return holds ? 0 : 3;
}

static int bench(long steps) {
  CTRL_T ctrl;
  long k, done;
  if (steps < 1 || steps > N_BENCH_MAX) { fprintf(stderr, "steps: 1 .. %ld\n", N_BENCH_MAX); return 2; }
  if (CTRL_INIT(&ctrl, NULL, NULL) != CTRL_OK) return 1;
  for (done = 0; done < steps; done += k) {  /* the task again and again, from rest */
    k = steps - done < N_RUN ? steps - done : N_RUN;
    if (run_task(&ctrl, k, step_ns + done)) return 1;
  }
  qsort(step_ns, (size_t)steps, sizeof(double), cmp_double);
  printf("{\"design\": \"%s\", \"real\": \"%s\", \"steps\": %ld, \"step_median_ns\": %.1f, \"step_p999_ns\": %.1f, "
         "\"step_max_ns\": %.1f, \"period_ns\": %.1f}\n", DESIGN_NAME, sizeof(CTRL_REAL) == 4 ? "float" : "double",
         steps, step_ns[steps / 2], step_ns[(long)(0.999 * (double)(steps - 1))], step_ns[steps - 1],
         1e9 / RATE_HZ);
  return 0;
}

int main(int argc, char** argv) {
  if (argc >= 2 && strcmp(argv[1], "run") == 0) return run(argc >= 3 ? argv[2] : NULL);
  if (argc >= 2 && strcmp(argv[1], "bench") == 0) return bench(argc >= 3 ? atol(argv[2]) : 100000L);
  fprintf(stderr, "usage: %s run [u.bin] | bench [steps]\n", argv[0]);
  return 2;
}
