/* Hand-written C of the link1 closed loop the generated code runs (the bench's peer): the sampled-data
 * loop's sample step with one RK4 substep, an ideal sensor, no delay and the stateless SMC law.
 *
 * Plant (TRUE parameters p):  J_l q'' + M g0 L sin q + K (q - q_m) = 0,
 *                              J_m q_m'' + B_m q_m' - K (q - q_m) = u.
 * Controller (NOMINAL parameters pn), paper's SMC with boundary layer, at t_k from x_k:
 *   y = T(x; pn), e = y - r[0..3], s = c1 e1 + c2 e2 + c3 e3 + e4,
 *   nu = r4 - (c1 e2 + c2 e3 + c3 e4) - k_s sat(s / delta),
 *   u = alpha(x; pn) + beta_hat nu   (beta_hat > 0 constant; beta_hat <= 0: beta(x; pn)).
 * Zero-order hold over each sample, one classical RK4 step. Parameters in param_names
 * order: J_l, J_m, K, M, g0, L, B_m. Reference R row-major (N, 5), row k at t_k.
 * Outputs: W (N, 4) state after each sample, AUX (N, 6) = [u, s, y1..y4].
 */
#include <math.h>

typedef struct { double iJl, iJm, K, MgL, Bm; } Plant;

static inline void plant(const double* x, double u, const Plant* P, double* dx) {
  const double spring = P->K * (x[0] - x[2]);
  dx[0] = x[1];
  dx[1] = -(P->MgL * sin(x[0]) + spring) * P->iJl;
  dx[2] = x[3];
  dx[3] = (spring - P->Bm * x[3] + u) * P->iJm;
}

int hand_loop(int N, double dt, const double* p, const double* pn, const double* c,
              double k_s, double delta, double beta_hat, const double* R, const double* w0,
              double* W, double* AUX) {
  const double Jl = pn[0], Jm = pn[1], K = pn[2], MgL = pn[3] * pn[4] * pn[5], Bm = pn[6];
  const double iJl = 1.0 / Jl, iJm = 1.0 / Jm, beta = Jl * Jm / K;  /* hoisted constants */
  const Plant P = {1.0 / p[0], 1.0 / p[1], p[2], p[3] * p[4] * p[5], p[6]};
  double x[4] = {w0[0], w0[1], w0[2], w0[3]};
  for (int k = 0; k < N; ++k) {
    const double* r = R + 5 * k;
    const double q0 = x[0], dq0 = x[1];
    const double sq = sin(x[0]), cq = cos(x[0]);
    const double spring = K * (x[0] - x[2]);
    const double y3 = -(MgL * sq + spring) * iJl;
    const double y4 = -(MgL * cq * x[1] + K * (x[1] - x[3])) * iJl;
    const double ddqm = (spring - Bm * x[3]) * iJm;
    const double a = -(-MgL * sq * x[1] * x[1] + MgL * cq * y3 + K * (y3 - ddqm)) * iJl;
    const double alpha = -beta * a;
    const double e1 = x[0] - r[0], e2 = x[1] - r[1], e3 = y3 - r[2], e4 = y4 - r[3];
    const double s = c[0] * e1 + c[1] * e2 + c[2] * e3 + e4;
    double sat = s / delta;
    sat = sat > 1.0 ? 1.0 : (sat < -1.0 ? -1.0 : sat);
    const double nu = r[4] - (c[0] * e2 + c[1] * e3 + c[2] * e4) - k_s * sat;
    const double u = alpha + (beta_hat > 0 ? beta_hat : beta) * nu;
    double k1[4], k2[4], k3[4], k4[4], xs[4];
    plant(x, u, &P, k1);
    for (int i = 0; i < 4; ++i) xs[i] = x[i] + 0.5 * dt * k1[i];
    plant(xs, u, &P, k2);
    for (int i = 0; i < 4; ++i) xs[i] = x[i] + 0.5 * dt * k2[i];
    plant(xs, u, &P, k3);
    for (int i = 0; i < 4; ++i) xs[i] = x[i] + dt * k3[i];
    plant(xs, u, &P, k4);
    for (int i = 0; i < 4; ++i) x[i] += (dt / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    double* wk = W + 4 * k;
    for (int i = 0; i < 4; ++i) wk[i] = x[i];
    double* ak = AUX + 6 * k;
    ak[0] = u; ak[1] = s; ak[2] = q0; ak[3] = dq0; ak[4] = y3; ak[5] = y4;
  }
  return 0;
}
