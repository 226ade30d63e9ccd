/* fjm: the counter-based sensor noise of fjm_runtime/sim/sensor.py (standard_normals), in C.
 * Same unsigned 64-bit wrapping arithmetic; log, sqrt, cos from the C library (numpy's agree to
 * the last bit or one ulp). fjm_noise_row fills the scaled noise of sample k of one run. */
#include <math.h>
#include <stdint.h>
static inline uint64_t fjm_splitmix64(uint64_t x) {
  uint64_t z = x + 0x9E3779B97F4A7C15ULL;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}
static inline double fjm_normal(uint64_t h, uint64_t c) {
  uint64_t a = fjm_splitmix64(h ^ (2ULL * c)), b = fjm_splitmix64(h ^ (2ULL * c + 1ULL));
  double u1 = ((double)(a >> 11) + 0.5) * 0x1p-53;
  double u2 = ((double)(b >> 11) + 0.5) * 0x1p-53;
  return sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2);
}
/* key = fjm_splitmix64(seed); out[j] = levels[j] * N(key, k, chan[j]) (0 where levels[j] == 0) */
static inline void fjm_noise_row(uint64_t key, uint64_t k, int nm, const double* levels,
                                 const long long* chan, double* out) {
  uint64_t h = fjm_splitmix64(key ^ k);
  for (int j = 0; j < nm; ++j)
    out[j] = levels[j] != 0.0 ? levels[j] * fjm_normal(h, (uint64_t)chan[j]) : 0.0;
}
