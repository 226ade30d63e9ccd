"""Gains for the adaptive-stiffness law: frozen-estimate synthesis plus the ``K_hat'`` term.

See :func:`synthesize_adaptive_gains`; the synthesis for each frozen estimate is
:func:`fjm_runtime.analysis.certificates.certify.synthesize_gains`.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import product
from typing import Optional

import numpy as np

from .box import per_joint, stiffness_names, surface_coefficients
from .certify import synthesize_gains
from .evaluator import Evaluator
from ...control.defaults import DEFAULT_LAYER_RATE

__all__ = ["AdaptiveTuneResult", "synthesize_adaptive_gains"]


@dataclass
class AdaptiveTuneResult:
    """Gain for the adaptive-stiffness law (:mod:`fjm_runtime.control.adaptive`) and its reaching argument.

    Attributes
    ----------
    k_s : ndarray, shape (n,)
        Largest synthesized gain over the grid of frozen estimates ``K_hat``.
    feasible : bool
    reason : str
    per_estimate : list of (dict, TuneResult)
        ``K_hat`` values and the synthesis for that frozen estimate.
    Gamma : ndarray, shape (n, n)
        ``sup |d s_i / d K_hat_j|`` over the box and the estimates (sampled).
    tv_bound : ndarray, shape (n,)
        Bound on the total variation of ``K_hat_j``: ``max(K_nom - K_min, K_max - K_nom)``.
    eta : ndarray, shape (n,)
        Reaching margins.
    delta : ndarray, shape (n,)
        Boundary layers ``k_s / layer_rate``.
    """

    k_s: np.ndarray
    feasible: bool
    reason: str
    per_estimate: list
    Gamma: np.ndarray
    tv_bound: np.ndarray
    eta: np.ndarray
    delta: np.ndarray

    def reaching_time_bound(self, s0) -> np.ndarray:
        """``(|s_i(0)| - delta_i + sum_j Gamma_ij TV_j) / eta_i`` (s): total time outside the layer."""
        s0 = np.abs(np.broadcast_to(np.asarray(s0, dtype=float), self.k_s.shape))
        return (np.maximum(s0 - self.delta, 0.0) + self.Gamma @ self.tv_bound) / self.eta


def synthesize_adaptive_gains(model, nominal_params=None, *, K_bounds, param_box=None, reference_bounds,
                              error_bounds, lam=None, c=None, integral: bool = True, n_estimates: int = 3,
                              eta=10.0, u_max=None, layer_rate: float = DEFAULT_LAYER_RATE, budget: int = 60000,
                              n_grid: Optional[int] = None, n_gamma: int = 20000, seed: int = 0,
                              disturbance_bound=0.0) -> AdaptiveTuneResult:
    """Gains for the adaptive-stiffness law: frozen-estimate synthesis plus the ``K_hat'`` term.

    The adaptive law runs the same sliding-mode law with ``p_hat`` (``K`` replaced
    by ``K_hat``), so ``s' = [the law's s' at frozen K_hat] + (d s / d K_hat) K_hat'``.

    1. Frozen estimate: :func:`synthesize_gains` with the nominal stiffness set
       to every point of an ``n_estimates``-per-joint grid of ``K_bounds`` (the
       estimate is projected onto it) and the true stiffness over ``K_bounds``;
       the gain is the largest. ``beta(x; p_hat)`` as the adaptive law uses.
    2. The dropped term: ``|sgn(s_i) (d s_i / d K_hat) K_hat'| <= sum_j Gamma_ij |K_hat_j'|``.
       With exact ``J_m``, ``B_m``, no measurement noise and consistently started
       filters, the least-squares error obeys ``K~' = -P phi_f^2 K~`` (projection
       only stops it), so ``|K~|`` never increases and the total variation of
       ``K_hat_j`` is at most ``|K_hat_j(0) - K_j| <= max(K_nom - K_min, K_max - K_nom)``.
       Integrating ``d|s_i|/dt <= -eta_i + sum_j Gamma_ij |K_hat_j'|`` gives a
       finite total time outside the layer:
       ``(|s_i(0)| - delta_i + sum_j Gamma_ij TV_j) / eta_i``. With errors in
       ``J_m``, ``B_m`` or noise this monotonicity is lost (biased, wandering
       estimate): the argument then does not apply (see the sensitivity numbers in
       docs/robust-gains.md).

    Returns
    -------
    AdaptiveTuneResult
    """
    n = int(model.n)
    kn = stiffness_names(model)
    if len(kn) != n:
        raise ValueError(f"model {model.name!r}: the adaptive law needs one stiffness per joint ({kn} found)")
    lo, hi = (np.broadcast_to(np.asarray(v, dtype=float), (n,)) for v in K_bounds)
    if not (np.all(lo > 0) and np.all(hi > lo)):
        raise ValueError(f"K_bounds = {K_bounds!r}: expected 0 < K_min < K_max (N m/rad)")
    p_nom = np.asarray(model.params_array(nominal_params or {}, arg="nominal_params"), dtype=float)
    idx = [model.param_names.index(k) for k in kn]
    k0 = p_nom[idx]
    if np.any(k0 < lo) or np.any(k0 > hi):
        raise ValueError(f"nominal stiffness {k0.tolist()}: expected inside K_bounds ({lo.tolist()}, {hi.tolist()})")
    box = dict(param_box or {})
    for j, k in enumerate(kn):
        box[k] = (float(lo[j]), float(hi[j]))
    grids = [np.linspace(lo[j], hi[j], n_estimates) for j in range(n)]
    per, ks, reason = [], np.zeros(n), ""
    for combo in product(*grids):
        nom = dict(zip(model.param_names, p_nom.tolist()))
        nom.update(dict(zip(kn, combo)))
        r = synthesize_gains(model, nom, param_box=box, reference_bounds=reference_bounds,
                             error_bounds=error_bounds, lam=lam, c=c, integral=integral, eta=eta, u_max=u_max,
                             layer_rate=layer_rate, budget=budget, n_grid=n_grid, seed=seed,
                             disturbance_bound=disturbance_bound)
        per.append(({k: float(v) for k, v in zip(kn, combo)}, r))
        if not r.feasible and not reason:
            reason = f"K_hat = {dict(zip(kn, combo))}: {r.reason}"
        ks = np.maximum(ks, np.nan_to_num(r.k_s, nan=np.inf))
    Gamma = _gamma(model, p_nom, idx, grids, surface_coefficients(lam, c, integral)[-3:], reference_bounds,
                   error_bounds, n_gamma, seed)
    tv = np.maximum(k0 - lo, hi - k0)
    eta_v = np.broadcast_to(np.asarray(eta, dtype=float), (n,)).copy()
    return AdaptiveTuneResult(k_s=ks, feasible=not reason, reason=reason, per_estimate=per, Gamma=Gamma,
                              tv_bound=tv, eta=eta_v, delta=ks / layer_rate)


def _gamma(model, p_nom, idx, grids, c_last, reference_bounds, error_bounds, n_samples, seed) -> np.ndarray:
    """``sup |C dT(x; p_hat)/dK_j|`` over the y-box and the estimate grid (random samples + vertices)."""
    import casadi as ca
    n, nx = int(model.n), int(model.nx)
    R = per_joint(reference_bounds, 5, n, "reference_bounds")
    E = per_joint(error_bounds, 4, n, "error_bounds")
    Yb = (R[:4] + E).reshape(-1)
    x = ca.SX.sym("x", nx); y = ca.SX.sym("y", nx); p = ca.SX.sym("p", len(p_nom))
    C = ca.horzcat(*[float(c_last[k]) * ca.SX.eye(n) for k in range(3)], ca.SX.eye(n))
    dT = ca.jacobian(ca.mtimes(C, model.functions["T"](x, p)), p[idx])
    fn = ca.Function("dsdK", [x, y, p], [ca.reshape(dT, n * n, 1)])
    rng = np.random.default_rng(seed)
    G = np.zeros((n, n))
    for combo in product(*grids):
        ph = p_nom.copy(); ph[idx] = combo
        ev = Evaluator(model, fn, p_inverse=ph)
        Y = rng.uniform(-1, 1, size=(n_samples, nx)) * Yb
        if nx <= 12:
            Y = np.vstack([Y, np.array(list(product(*[(-1.0, 1.0)] * nx))) * Yb])
        P = np.repeat(ph[None, :], Y.shape[0], axis=0)
        V = np.abs(ev(Y, P)).reshape(-1, n, n, order="F")
        G = np.maximum(G, V.max(axis=0))
    return G


