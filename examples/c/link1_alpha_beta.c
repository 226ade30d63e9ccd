/* Evaluate the feedback-linearizing terms alpha(x) and beta(x) of the generated
 * single-link model (generated/link1/link1.{c,h}) at a state given on the
 * command line, and print them.
 *
 *   usage: link1_alpha_beta q dq q_m dq_m [J_l J_m K M g0 L B_m]
 *
 * The control law is u = alpha(x) + beta(x) nu (gives y4' = nu).
 * Parameters default to the values in generated/link1/manifest.json.
 * The generated functions perform no checks (a NaN in gives a NaN out, a
 * negative stiffness gives a meaningless law): this program, their caller,
 * validates the inputs and exits with status 2 and a one-line message.
 * Build: `make` (see Makefile); works in double (default) and, with
 * CFLAGS+=-Dcasadi_real=float, in single precision.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "link1.h"

#define NX 4 /* x = [q; dq; q_m; dq_m] */
#define NP 7 /* p = [J_l, J_m, K, M, g0, L, B_m] */

static const char* const PARAM_NAMES[NP] = {"J_l", "J_m", "K", "M", "g0", "L", "B_m"};
/* J_l, J_m, K, M, L must be > 0; g0 and B_m >= 0 (the runtime's rules, fjm_runtime.validation) */
static const int PARAM_POSITIVE[NP] = {1, 1, 1, 1, 0, 1, 0};

/* Call one generated function in CasADi's calling convention:
 * query the work sizes, allocate, check out a memory slot, evaluate, release. */
typedef int (*casadi_fn)(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, int mem);
typedef int (*casadi_work_fn)(casadi_int* sz_arg, casadi_int* sz_res, casadi_int* sz_iw, casadi_int* sz_w);
typedef int (*casadi_checkout_fn)(void);
typedef void (*casadi_release_fn)(int mem);

static int evaluate(casadi_fn fn, casadi_work_fn work, casadi_checkout_fn checkout, casadi_release_fn release,
                    const casadi_real* x, const casadi_real* p, casadi_real* out) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  const casadi_real** arg;
  casadi_real** res;
  casadi_int* iw;
  casadi_real* w;
  int mem, flag;
  if (work(&sz_arg, &sz_res, &sz_iw, &sz_w)) return 1;
  arg = malloc((size_t)(sz_arg > 2 ? sz_arg : 2) * sizeof(*arg));
  res = malloc((size_t)(sz_res > 1 ? sz_res : 1) * sizeof(*res));
  iw = malloc((size_t)(sz_iw > 0 ? sz_iw : 1) * sizeof(*iw));
  w = malloc((size_t)(sz_w > 0 ? sz_w : 1) * sizeof(*w));
  if (!arg || !res || !iw || !w) {
    flag = 1;
  } else {
    arg[0] = x;
    arg[1] = p;
    res[0] = out;
    mem = checkout();
    flag = fn(arg, res, iw, w, mem);
    release(mem);
  }
  free(arg);
  free(res);
  free(iw);
  free(w);
  return flag;
}

int main(int argc, char** argv) {
  casadi_real x[NX];
  casadi_real p[NP] = {1.0, 2.0, 150.0, 1.0, 9.8, 1.0, 0.0}; /* paper Table 1, K mid-range */
  casadi_real alpha[1], beta[1];
  int i;
  if (argc != 1 + NX && argc != 1 + NX + NP) {
    fprintf(stderr, "usage: %s q dq q_m dq_m [J_l J_m K M g0 L B_m]\n", argv[0]);
    return 2;
  }
  for (i = 0; i < argc - 1; ++i) {
    char* end;
    double v = strtod(argv[i + 1], &end);
    if (end == argv[i + 1] || *end != '\0') {
      fprintf(stderr, "argument %d (%s): not a number\n", i + 1, argv[i + 1]);
      return 2;
    }
    if (!isfinite(v)) {
      fprintf(stderr, "argument %d (%s): expected a finite number\n", i + 1, argv[i + 1]);
      return 2;
    }
    if (i >= NX && (PARAM_POSITIVE[i - NX] ? !(v > 0) : !(v >= 0))) {
      fprintf(stderr, "argument %d: %s = %s: expected %s\n", i + 1, PARAM_NAMES[i - NX], argv[i + 1],
              PARAM_POSITIVE[i - NX] ? "> 0" : ">= 0");
      return 2;
    }
    if (i < NX) x[i] = (casadi_real)v;
    else p[i - NX] = (casadi_real)v;
  }
  /* alpha is 1x1 and beta is 1x1 (n = 1); see link1_*_sparsity_out for the general layout */
  if (evaluate(link1_alpha, link1_alpha_work, link1_alpha_checkout, link1_alpha_release, x, p, alpha) ||
      evaluate(link1_beta, link1_beta_work, link1_beta_checkout, link1_beta_release, x, p, beta)) {
    fprintf(stderr, "evaluation failed\n");
    return 1;
  }
  printf("alpha = %.17g\n", (double)alpha[0]);
  printf("beta = %.17g\n", (double)beta[0]);
  return 0;
}
