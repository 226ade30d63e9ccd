/* fjm: SIMD-across-runs form of the sampled-data batch step (generated, do not edit). */
#define __FAST_MATH__ 1  /* only to expose glibc's vector math declarations (libmvec) */
#include <math.h>
#undef __FAST_MATH__
#include <stdlib.h>
#include <string.h>
#define LANES ${lanes}
typedef double vd __attribute__((vector_size(8 * LANES)));
typedef long long vl __attribute__((vector_size(8 * LANES)));
static const vd V0 = {0};
/* a comparison's mask (-1 or 0 per lane) as 1.0 or 0.0: one AND with the bits of 1.0 (no int-to-double
 * conversion, which AVX2 and SSE2 lack for 64-bit lanes) */
static inline vd v_b(vl m) { return (vd)(m & (vl)(V0 + 1.)); }
static inline vd v_sel(vl m, vd a, vd b) { return (vd)(((vl)a & m) | ((vl)b & ~m)); }
static inline vd v_sign(vd x) { return v_sel(x < 0., V0 - 1., v_sel(x > 0., V0 + 1., x)); }
static inline vd v_sin(vd x) { double a[LANES], r[LANES]; memcpy(a, &x, sizeof x); for (int l = 0; l < LANES; ++l) r[l] = sin(a[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_cos(vd x) { double a[LANES], r[LANES]; memcpy(a, &x, sizeof x); for (int l = 0; l < LANES; ++l) r[l] = cos(a[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_floor(vd x) { double a[LANES], r[LANES]; memcpy(a, &x, sizeof x); for (int l = 0; l < LANES; ++l) r[l] = floor(a[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_ceil(vd x) { double a[LANES], r[LANES]; memcpy(a, &x, sizeof x); for (int l = 0; l < LANES; ++l) r[l] = ceil(a[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_tan(vd x) { double a[LANES], r[LANES]; memcpy(a, &x, sizeof x); for (int l = 0; l < LANES; ++l) r[l] = tan(a[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_exp(vd x) { double a[LANES], r[LANES]; memcpy(a, &x, sizeof x); for (int l = 0; l < LANES; ++l) r[l] = exp(a[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_log(vd x) { double a[LANES], r[LANES]; memcpy(a, &x, sizeof x); for (int l = 0; l < LANES; ++l) r[l] = log(a[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_sqrt(vd x) { double a[LANES], r[LANES]; memcpy(a, &x, sizeof x); for (int l = 0; l < LANES; ++l) r[l] = sqrt(a[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_tanh(vd x) { double a[LANES], r[LANES]; memcpy(a, &x, sizeof x); for (int l = 0; l < LANES; ++l) r[l] = tanh(a[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_atan(vd x) { double a[LANES], r[LANES]; memcpy(a, &x, sizeof x); for (int l = 0; l < LANES; ++l) r[l] = atan(a[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_asin(vd x) { double a[LANES], r[LANES]; memcpy(a, &x, sizeof x); for (int l = 0; l < LANES; ++l) r[l] = asin(a[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_acos(vd x) { double a[LANES], r[LANES]; memcpy(a, &x, sizeof x); for (int l = 0; l < LANES; ++l) r[l] = acos(a[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_pow(vd x, vd y) { double a[LANES], b[LANES], r[LANES]; memcpy(a, &x, sizeof x); memcpy(b, &y, sizeof y); for (int l = 0; l < LANES; ++l) r[l] = pow(a[l], b[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_atan2(vd x, vd y) { double a[LANES], b[LANES], r[LANES]; memcpy(a, &x, sizeof x); memcpy(b, &y, sizeof y); for (int l = 0; l < LANES; ++l) r[l] = atan2(a[l], b[l]); memcpy(&x, r, sizeof x); return x; }
static inline vd v_copysign(vd x, vd y) { double a[LANES], b[LANES], r[LANES]; memcpy(a, &x, sizeof x); memcpy(b, &y, sizeof y); for (int l = 0; l < LANES; ++l) r[l] = copysign(a[l], b[l]); memcpy(&x, r, sizeof x); return x; }
${noise}
${callees}
#define SZ_INV ${n_inv}
static void fjm_prologue(const double* restrict acc, vd* restrict inv) {${prologue}
}
static void fjm_step_soa(const vd* restrict inv, const double** arg, double** res) {
  vd ${declarations};${body}
}

#ifdef _OPENMP
#include <omp.h>
#endif
/* The sampled-data batch: per group of LANES runs, the noise rows of each sample from the runs'
 * seeds (noise.c), then the step on [nacc][LANES] (input 2, the noise, varies per lane). */
int fjm_sampled_batch_soa(int n_groups, int n_samples, int nacc, int nr, int nm, int nf, double* acc,
                          const double* R, const double* FL, const double* levels, const long long* chan,
                          const unsigned long long* seeds, int n_threads, int* threads_used) {
  int used = 1, nt = 1, noisy = 0;
  for (int j = 0; j < nm; ++j) noisy |= levels[j] != 0.0;
#ifdef _OPENMP
  nt = n_threads > 0 ? n_threads : omp_get_max_threads();
#endif
  (void)nt; (void)n_threads;
  #pragma omp parallel num_threads(nt) if (nt > 1)  /* one thread: no team to wake or to wait for */
  {
#ifdef _OPENMP
    #pragma omp single
    used = omp_get_num_threads();
#endif
    #pragma omp for schedule(dynamic, 1)
    for (int g = 0; g < n_groups; ++g) {
      vd* inv = aligned_alloc(64, sizeof(vd) * SZ_INV);
      double* buf = malloc(sizeof(double) * (2 * nacc + nm + 1) * LANES + sizeof(double) * nm);
      double *cur = buf, *nxt = buf + nacc * LANES, *noise = buf + 2 * nacc * LANES;
      double* row = noise + nm * LANES;
      uint64_t key[LANES];
      for (int l = 0; l < LANES; ++l) key[l] = fjm_splitmix64((uint64_t)seeds[(size_t)g * LANES + l]);
      memcpy(cur, acc + (size_t)g * nacc * LANES, sizeof(double) * nacc * LANES);
      memcpy(nxt, cur, sizeof(double) * nacc * LANES);  /* the step never stores a passed-through entry */
      memset(noise, 0, sizeof(double) * nm * LANES);
      fjm_prologue(cur, inv);
      const double* arg[4];
      double* res[1];
      for (int k = 0; k < n_samples; ++k) {
        for (int l = 0; l < LANES && noisy; ++l) {  /* an ideal sensor's rows stay zero */
          fjm_noise_row(key[l], (uint64_t)k, nm, levels, chan, row);
          for (int j = 0; j < nm; ++j) noise[j * LANES + l] = row[j];
        }
        arg[0] = cur; arg[1] = R + (size_t)k * nr; arg[2] = noise; arg[3] = FL + (size_t)k * nf;
        res[0] = nxt;
        fjm_step_soa(inv, arg, res);
        double* t = cur; cur = nxt; nxt = t;
      }
      memcpy(acc + (size_t)g * nacc * LANES, cur, sizeof(double) * nacc * LANES);
      free(inv); free(buf);
    }
  }
  *threads_used = used;
  return 0;
}
