/* What realtime.c and designed_controller.c share: the work arrays of the generated calls,
 * FN(suffix) (the generated model's function names), the TRUE plant and the timing helpers.
 *
 * Included after FJM_HEADER (the generated model: NX, NU, NP, f, g), sizes.h (MAX_SZ_*) and the
 * header that defines P_TRUE (the TRUE parameters): the plant is x' = f(x) + g(x) u at p_true,
 * advanced by classical RK4 under a held torque u. */
#ifndef FJM_EXAMPLE_PLANT_H
#define FJM_EXAMPLE_PLANT_H

#include <stdlib.h>
#include <time.h>

#define CAT_(a, b) a##b
#define CAT(a, b) CAT_(a, b)
#define FN(suffix) CAT(FJM_MODEL, suffix)

/* static work arrays, shared by every generated call (the calls never overlap) */
static const casadi_real* arg[MAX_SZ_ARG + 1];
static casadi_real* res[MAX_SZ_RES + 1];
static casadi_int iw[MAX_SZ_IW + 1];
static casadi_real w[MAX_SZ_W + 1];
static casadi_real p_true[NP] = P_TRUE;

/* x' = f(x) + g(x) u (g decoded from its compressed column sparsity) */
static int plant_rhs(const casadi_real* x, const casadi_real* u, casadi_real* dx) {
  casadi_real gv[NX * NU];
  const casadi_int* sp = FN(_g_sparsity_out)(0);
  casadi_int j, k, ncol = sp[1];
  arg[0] = x; arg[1] = p_true; res[0] = dx;
  if (FN(_f)(arg, res, iw, w, 0)) return 1;
  res[0] = gv;
  if (FN(_g)(arg, res, iw, w, 0)) return 1;
  if (sp[2] == 1) { /* dense */
    for (j = 0; j < ncol; ++j)
      for (k = 0; k < NX; ++k) dx[k] += gv[j * NX + k] * u[j];
  } else {
    const casadi_int *colind = sp + 2, *row = sp + 2 + ncol + 1;
    for (j = 0; j < ncol; ++j)
      for (k = colind[j]; k < colind[j + 1]; ++k) dx[row[k]] += gv[k] * u[j];
  }
  return 0;
}

static int plant_rk4(casadi_real* x, const casadi_real* u, double h) {
  casadi_real k1[NX], k2[NX], k3[NX], k4[NX], xt[NX];
  int i;
  if (plant_rhs(x, u, k1)) return 1;
  for (i = 0; i < NX; ++i) xt[i] = x[i] + (casadi_real)(0.5 * h) * k1[i];
  if (plant_rhs(xt, u, k2)) return 1;
  for (i = 0; i < NX; ++i) xt[i] = x[i] + (casadi_real)(0.5 * h) * k2[i];
  if (plant_rhs(xt, u, k3)) return 1;
  for (i = 0; i < NX; ++i) xt[i] = x[i] + (casadi_real)h * k3[i];
  if (plant_rhs(xt, u, k4)) return 1;
  for (i = 0; i < NX; ++i) x[i] += (casadi_real)(h / 6.0) * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
  return 0;
}

static double now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return 1e9 * (double)ts.tv_sec + (double)ts.tv_nsec;
}

static int cmp_double(const void* a, const void* b) {
  const double x = *(const double*)a, y = *(const double*)b;
  return (x > y) - (x < y);
}

/* x at rest (q_m = q, velocities 0) -> the motor angles that hold gravity on the TRUE plant:
 * q_m = q + K^-1 G(q), G = -D ddq at q_m = q; K (N m/rad, NU) the TRUE joint stiffness. */
static inline void hold_gravity(casadi_real* x, const double* K) {
  casadi_real dx[NX], D[NU * NU];
  int i, j;
  arg[0] = x; arg[1] = p_true; res[0] = dx;
  (void)FN(_f)(arg, res, iw, w, 0);
  res[0] = D;
  (void)FN(_inertia)(arg, res, iw, w, 0);
  for (i = 0; i < NU; ++i) {
    double G = 0;
    for (j = 0; j < NU; ++j) G -= (double)D[j * NU + i] * (double)dx[NU + j];
    x[2 * NU + i] = (casadi_real)((double)x[i] + G / K[i]);
  }
}

#endif
