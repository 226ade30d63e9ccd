/* Timing driver: calls ALPHA then BETA (CasADi calling convention) in a tight loop.
 * Compiled with the same flags into one shared object with either the generated
 * sources or the peer's; ALPHA and BETA are given with -D. No LTO: the functions
 * live in another translation unit, so nothing is inlined or hoisted. */
#include <stdlib.h>
#include <time.h>

typedef long long int casadi_int;
int ALPHA(const double** arg, double** res, casadi_int* iw, double* w, int mem);
int BETA(const double** arg, double** res, casadi_int* iw, double* w, int mem);
#define CAT2(a, b) a##b
#define CAT(a, b) CAT2(a, b)
int CAT(ALPHA, _work)(casadi_int*, casadi_int*, casadi_int*, casadi_int*);
int CAT(BETA, _work)(casadi_int*, casadi_int*, casadi_int*, casadi_int*);

/* Work arrays large enough for both ALPHA and BETA (free both with free()). */
static void alloc_work(double** w, casadi_int** iw) {
  casadi_int sa, sr, siw, sw, s2a, s2r, s2iw, s2w;
  CAT(ALPHA, _work)(&sa, &sr, &siw, &sw);
  CAT(BETA, _work)(&s2a, &s2r, &s2iw, &s2w);
  if (s2w > sw) sw = s2w;
  if (s2iw > siw) siw = s2iw;
  *w = malloc(sizeof(double) * (sw + 1));
  *iw = malloc(sizeof(casadi_int) * (siw + 1));
}

/* One evaluation (for correctness checks): alpha (n) and beta (n*n, column-major). */
int eval_alpha_beta(const double* x, const double* p, double* alpha, double* beta) {
  double* w; casadi_int* iw;
  alloc_work(&w, &iw);
  const double* arg[8] = {x, p}; double* res[4] = {alpha};
  int flag = ALPHA(arg, res, iw, w, 0);
  res[0] = beta;
  flag |= BETA(arg, res, iw, w, 0);
  free(w); free(iw);
  return flag;
}

/* Seconds per (alpha + beta) pair over `iters` calls; `checksum` defeats dead-code elimination. */
double time_alpha_beta(long iters, int nx, const double* x0, const double* p, double* checksum) {
  double* w; casadi_int* iw;
  alloc_work(&w, &iw);
  double x[256], alpha[64], beta[4096];
  for (int i = 0; i < nx; ++i) x[i] = x0[i];
  const double* arg[8] = {x, p}; double* res[4] = {alpha};
  double acc = 0.0;
  struct timespec t0, t1;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  for (long k = 0; k < iters; ++k) {
    x[0] = x0[0] + 1e-9 * (double)(k & 7);  /* inputs change every call */
    res[0] = alpha; ALPHA(arg, res, iw, w, 0);
    res[0] = beta;  BETA(arg, res, iw, w, 0);
    acc += alpha[0] + beta[0];
  }
  clock_gettime(CLOCK_MONOTONIC, &t1);
  *checksum = acc;
  free(w); free(iw);
  return ((t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec)) / (double)iters;
}
