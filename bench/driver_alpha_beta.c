/* Timing driver: alpha and beta (CasADi calling convention) in a tight loop, either as two calls
 * (ALPHA then BETA, given with -D) or as one call of CORE (-DCORE=..., outputs y_hat, alpha, beta:
 * a law's core, which forms them together). Compiled with the same flags into one shared object
 * with either the generated sources or the peer's. No LTO: the functions live in another
 * translation unit, so nothing is inlined or hoisted. */
#include <stdlib.h>
#include <time.h>

typedef long long int casadi_int;
#define CAT2(a, b) a##b
#define CAT(a, b) CAT2(a, b)
#ifdef CORE
int CORE(const double** arg, double** res, casadi_int* iw, double* w, int mem);
int CAT(CORE, _work)(casadi_int*, casadi_int*, casadi_int*, casadi_int*);
#else
int ALPHA(const double** arg, double** res, casadi_int* iw, double* w, int mem);
int BETA(const double** arg, double** res, casadi_int* iw, double* w, int mem);
int CAT(ALPHA, _work)(casadi_int*, casadi_int*, casadi_int*, casadi_int*);
int CAT(BETA, _work)(casadi_int*, casadi_int*, casadi_int*, casadi_int*);
#endif

typedef struct {
  const double** arg; double** res; casadi_int* iw; double* w;
} work_t;

/* Work arrays, arg and res included, as large as the called functions ask (F_work): a function that
 * calls another uses the entries after its own inputs and outputs as scratch. Free with free_work. */
static work_t alloc_work(void) {
  casadi_int sa, sr, siw, sw;
#ifdef CORE
  CAT(CORE, _work)(&sa, &sr, &siw, &sw);
#else
#define MAX_LL(a, b) ((a) > (b) ? (a) : (b))
  casadi_int s2a, s2r, s2iw, s2w;
  CAT(ALPHA, _work)(&sa, &sr, &siw, &sw);
  CAT(BETA, _work)(&s2a, &s2r, &s2iw, &s2w);
  sa = MAX_LL(sa, s2a); sr = MAX_LL(sr, s2r); siw = MAX_LL(siw, s2iw); sw = MAX_LL(sw, s2w);
#endif
  work_t k;
  k.arg = calloc(sa + 1, sizeof(double*));
  k.res = calloc(sr + 1, sizeof(double*));
  k.iw = malloc(sizeof(casadi_int) * (siw + 1));
  k.w = malloc(sizeof(double) * (sw + 1));
  return k;
}

static void free_work(work_t* k) { free(k->arg); free(k->res); free(k->iw); free(k->w); }

/* alpha (n) and beta (n*n, column-major) at x, p into the given buffers; y_hat (4n) is CORE's scratch. */
static int eval(work_t* k, const double* x, const double* p, double* y_hat, double* alpha, double* beta) {
  k->arg[0] = x; k->arg[1] = p;
#ifdef CORE
  k->res[0] = y_hat; k->res[1] = alpha; k->res[2] = beta;
  return CORE(k->arg, k->res, k->iw, k->w, 0);
#else
  (void)y_hat;
  k->res[0] = alpha;
  int flag = ALPHA(k->arg, k->res, k->iw, k->w, 0);
  k->arg[0] = x; k->arg[1] = p;
  k->res[0] = beta;
  return flag | BETA(k->arg, k->res, k->iw, k->w, 0);
#endif
}

/* One evaluation (for correctness checks): alpha (n) and beta (n*n, column-major). */
int eval_alpha_beta(const double* x, const double* p, double* alpha, double* beta) {
  work_t k = alloc_work();
  double y_hat[256];
  int flag = eval(&k, x, p, y_hat, alpha, beta);
  free_work(&k);
  return flag;
}

/* Seconds per (alpha + beta) evaluation over `iters` calls; `checksum` defeats dead-code elimination. */
double time_alpha_beta(long iters, int nx, const double* x0, const double* p, double* checksum) {
  work_t k = alloc_work();
  double x[256], y_hat[256], alpha[64], beta[4096];
  for (int i = 0; i < nx; ++i) x[i] = x0[i];
  double acc = 0.0;
  struct timespec t0, t1;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  for (long i = 0; i < iters; ++i) {
    x[0] = x0[0] + 1e-9 * (double)(i & 7);  /* inputs change every call */
    eval(&k, x, p, y_hat, alpha, beta);
    acc += alpha[0] + beta[0];
  }
  clock_gettime(CLOCK_MONOTONIC, &t1);
  *checksum = acc;
  free_work(&k);
  return ((t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec)) / (double)iters;
}
