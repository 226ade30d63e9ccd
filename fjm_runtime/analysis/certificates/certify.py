"""Reaching-gain synthesis for the sliding-mode law that is actually run (``fjm tune``).

The law (:mod:`fjm_runtime.control.laws`)
-----------------------------------------
The controller forms everything from NOMINAL parameters: ``y_hat = T(x; p_nom)``,
``e = y_hat - y_d``, ``s = c . e`` (``c = [c1, c2, c3, 1]``, or the integral surface),
``w = y4d' - linear(e)``, ``u = alpha(x; p_nom) + B (w - k_s psi(s))`` with
``B = beta(x; p_nom)`` or a constant ``beta_hat``. The TRUE plant is
``x' = f(x; p) + g(x; p) u``. Differentiating ``s`` along it (any surface of this
package; ``c3, c2, c1`` below are the last three surface coefficients)::

    s' = F(y_hat, w, p) - G(y_hat, p) k_s psi
    F  = C J(x) (f(x; p) + g(x; p) (alpha(x; p_nom) + B w)) - (c1 y2_hat + c2 y3_hat + c3 y4_hat) - w
    G  = C J(x) g(x; p) B,       C = [c1 I, c2 I, c3 I, I],  J = dT(x; p_nom)/dx,  x = T^{-1}(y_hat; p_nom)

(at ``p = p_nom`` and ``B = beta(x; p_nom)``: ``F = 0``, ``G = I``). The stiffness
error enters ``F`` through ``c2 = 3 lambda^2`` and ``c3`` (the drift of ``y2_hat``,
``y3_hat`` the input cannot cancel), which is why a gain from the paper's Lemma 1
(true coordinates) stops holding for large ``lambda``.

Region and condition
--------------------
The region is the box ``|y_d^(k)| <= R_k`` (reference bounds, k = 0..4) and
``|e_i| <= E_i`` (error box, nominal coordinates). Every such state has
``|y_hat_k| <= R_{k-1} + E_k`` and ``|w| <= W = R_4 + sum c_k E_{k+1}``; ``F`` is
affine in ``w``, so for joint ``i`` and any sign of ``s_i``, with ``|psi_j| <= 1``
for the other joints and ``psi_i = sgn(s_i)`` outside the boundary layer::

    sgn(s_i) s_i' <= Phi_i = |F0_i| + sum_j |G_ij - d_ij| W_j + sum_{j != i} |G_ij| k_j - G_ii k_i

with ``F0 = F(w = 0)``. The gain is the smallest ``k`` with ``sup Phi_i <= -eta_i``
over the box (a fixed point ``k_i = sup (... + eta_i) / G_ii``; it needs
``G_ii > 0`` and diagonal dominance). The CERTIFICATE is ``sup Phi_i`` for the
gain: the worst ``sgn(s_i) s_i'`` over the box (a bound, worst over the sign of
``s`` and over ``w``) and where it occurs.

How the supremum is computed (what is guaranteed)
-------------------------------------------------
Each coordinate of the box (``y_hat`` per joint and block, and each uncertain
parameter) is tested numerically for affinity of ``F0`` and ``G`` (midpoint and
third-point tests at random points). Along affine coordinates ``Phi`` is convex,
so its supremum is at the end points: those coordinates are enumerated at their
two vertices (the exact vertex argument; e.g. the stiffnesses, which enter ``f``
linearly, and ``y4_hat``). The other coordinates (link angles, velocities, ...)
are covered by a tensor grid, then local maximization (projected gradient ascent) from the worst
grid points refines the supremum. The grid supremum plus a curvature margin
``sum_d M_d h_d^2 / 8`` (``M_d`` the largest negative curvature seen in the
grid's second differences along coordinate ``d``, ``h_d`` the spacing: ``Phi``
exceeds its multilinear interpolant by at most that when ``Phi'' >= -M_d``) is
reported; with ``include_margin=True`` (default) the gain covers it.
Coordinates on which ``F0`` and ``G`` do not depend at all get one grid point
(the torque bound puts them back at their vertices). This is a NUMERICAL
certificate on that grid, not a proof: the affinity tests and the curvatures
are sampled. Invariance of the error box is ASSUMED, not
proven: the reaching condition holds while the state is in the box; whether the
state leaves the box (large initial errors, the reaching transient, peaking in
the other joints) is not analysed.

``predicted reaching time``: ``sgn(s_i) s_i' <= -eta_i`` on the box gives
``|s_i|`` down to ``delta_i`` within ``(|s_i(0)| - delta_i) / eta_i``.

:func:`fjm_runtime.analysis.certificates.lemma1.paper_bound` evaluates the paper's Lemma 1 (eq 16
with ``rho``) in TRUE coordinates with the same machinery, for comparison (scalar models
only). The box and its sampling live in :mod:`fjm_runtime.analysis.certificates.box`, the CasADi
evaluation in :mod:`fjm_runtime.analysis.certificates.evaluator`, the grid of ``Phi`` in
:mod:`fjm_runtime.analysis.certificates.grid`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .grid import BoxAnalysis, nominal_setup, solve_gain, witness_point
from .spring_interval import stiffness_interval
from ...control.defaults import DEFAULT_LAYER_RATE

__all__ = ["TuneResult", "InfeasibleGainError", "synthesize_gains", "certificate", "GUARANTEE"]

GUARANTEE = ("sgn(s_i) s_i' <= certificate_i <= -eta_i for every state whose nominal "
             "coordinates, reference derivatives and true parameters lie in the box (numerical "
             "certificate on the grid, vertices along affine coordinates); the box is assumed "
             "invariant, not proven; reaching_time_bound = (|s(0)| - delta) / eta for "
             "|s(0)| = s0_max while the state stays in the box")
"""What a feasible :class:`TuneResult` guarantees, in one sentence (reported by ``fjm tune``)."""


class InfeasibleGainError(ValueError):
    """No gain satisfies the reaching condition on the box (``.result`` holds the analysis)."""

    def __init__(self, message: str, result: "TuneResult" = None):
        super().__init__(message)
        self.result = result


# ---------------------------------------------------------------------------------------------
@dataclass
class TuneResult:
    """Synthesized per-joint gains and their certificate (see the module docstring).

    Attributes
    ----------
    model : str
    feasible : bool
        False when no admissible gain exists (``reason`` says why); the other
        fields then describe the analysis (``k_s`` is the gain the reaching
        condition alone would need, or NaN).
    reason : str
    k_s : ndarray, shape (n,)
        Switching gains (rad/s^4).
    delta : ndarray, shape (n,)
        Boundary layers.
    eta : ndarray, shape (n,)
        Reaching margins: ``sgn(s_i) s_i' <= -eta_i`` on the box.
    certificate : ndarray, shape (n,)
        ``sup Phi_i`` found for ``k_s`` (grid + local refinement): the worst
        ``sgn(s_i) s_i'`` bound on the box; ``<= -eta_i`` when feasible.
    certificate_grid_bound : ndarray, shape (n,)
        Grid supremum plus the curvature margin.
    margin : ndarray, shape (n,)
        The curvature margin ``sum_d M_d h_d^2 / 8`` (see :meth:`fjm_runtime.analysis.certificates.grid.BoxAnalysis.margin`).
    witness : list of dict
        Per joint, where the certificate is attained: ``y_hat`` (4, n), the
        parameters that differ from nominal, the worst ``w`` and sign of ``s``.
    sup_F : ndarray, shape (n,)
        ``sup |F_i|`` over the box (``w`` included): the drift the gain must dominate.
    u_bound : ndarray, shape (n,)
        ``sup |u_i|`` the law can command on the box with this gain, N m.
    u_max : ndarray or None
    W : ndarray, shape (n,)
    y_box : ndarray, shape (4, n)
        Half-widths of ``|y_hat_k|``.
    c : ndarray
        Surface coefficients, lowest first.
    grid : dict
        Coordinates, which were enumerated at vertices (affine) and grid sizes.
    settings : dict
    margin_lipschitz : ndarray, shape (n,)
        For comparison: the Lipschitz margin ``sum_d L_d h_d / 2`` of the same grid
        (valid under weaker assumptions, much coarser on coarse grids; not used by the gain).
    stiffness : dict or None
        Nonlinear-spring models (:mod:`fjm_runtime.analysis.certificates.spring_interval`): the deflections the
        box's states reach, the declared range, and ``psi'`` in ``[k_min, k_max]`` there over the
        parameter box: the stiffness interval of the paper's Lemma 1 that the certificate covers.
        None for a linear spring.
    """

    model: str
    feasible: bool
    reason: str
    k_s: np.ndarray
    delta: np.ndarray
    eta: np.ndarray
    certificate: np.ndarray
    certificate_grid_bound: np.ndarray
    margin: np.ndarray
    witness: list
    sup_F: np.ndarray
    u_bound: np.ndarray
    u_max: Optional[np.ndarray]
    W: np.ndarray
    y_box: np.ndarray
    c: np.ndarray
    grid: dict
    settings: dict = field(default_factory=dict)
    margin_lipschitz: Optional[np.ndarray] = None
    stiffness: Optional[dict] = None

    def reaching_time_bound(self, s0) -> np.ndarray:
        """``(|s_i(0)| - delta_i)^+ / eta_i`` per joint (s), valid while the state stays in the box."""
        s0 = np.abs(np.broadcast_to(np.asarray(s0, dtype=float), self.k_s.shape))
        return np.maximum(s0 - self.delta, 0.0) / self.eta

    def max_sliding_variable(self) -> np.ndarray:
        """``sup |s_i|`` on the error box, shape (n,): ``c1 E1 + c2 E2 + c3 E3 + E4`` (paper surface;
        the integral surface without its integral state)."""
        c = self.c
        Ea = np.asarray(self.settings["error_bounds"])
        return (c[1:] @ Ea[:3] + Ea[3]) if c.size == 4 else (c @ Ea[:3] + Ea[3])

    def as_dict(self) -> dict:
        """JSON-ready dictionary."""
        def conv(v):
            if isinstance(v, np.ndarray):
                return [conv(x) for x in v.tolist()] if v.ndim else conv(v.item())
            if isinstance(v, (list, tuple)):
                return [conv(x) for x in v]
            if isinstance(v, dict):
                return {k: conv(x) for k, x in v.items()}
            if isinstance(v, float) and not np.isfinite(v):
                return str(v)
            if isinstance(v, (np.floating, np.integer)):
                return conv(v.item())
            return v
        return {k: conv(v) for k, v in self.__dict__.items()}


def synthesize_gains(model, nominal_params=None, *, param_box=None, reference_bounds, error_bounds,
                     lam: Optional[float] = None, c=None, integral: bool = False, beta_hat=None,
                     eta=10.0, u_max=None, delta=None, layer_rate: float = DEFAULT_LAYER_RATE,
                     include_margin: bool = True, budget: int = 60000, n_grid: Optional[int] = None,
                     seed: int = 0, raise_infeasible: bool = False, disturbance_bound=0.0,
                     evaluator=None) -> TuneResult:
    """Per-joint switching gains for the law that is run (nominal coordinates), with a certificate.

    Parameters
    ----------
    model : Model
        ``fjm_runtime.load(name)``; uses its ``T``, ``alpha``, ``beta``, ``f``, ``g``.
    nominal_params : dict or array_like, optional
        Parameters the controller uses (default: model defaults).
    param_box : dict name -> (lo, hi), optional
        Intervals of the TRUE parameters (e.g. ``{"K": (100, 200)}``;
        :func:`param_box_from_ranges` builds one per joint).
    reference_bounds : array_like, shape (5,) or (5, n)
        ``R_k >= sup |y_d^(k)|``, k = 0..4 (``Reference.derivative_bounds()``).
    error_bounds : array_like, shape (4,) or (4, n)
        ``E_k >= |y_hat_k - y_dk|`` (nominal coordinates) on the region to certify.
    lam, c : pole magnitude (1/s) or surface coefficients (one of them).
    integral : bool
        Integral surface (``ismc``) instead of the paper's.
    beta_hat : scalar or array_like (n, n), optional
        Constant ``beta_hat`` as configured in the controller; default ``beta(x; p_nom)``.
    eta : float or array_like, shape (n,)
        Reaching margin (rad/s^4), > 0.
    u_max : float or array_like, shape (n,), optional
        Actuator limit (N m); infeasible when the law may command more on the box.
    delta : float or array_like, optional
        Boundary layer; default ``k_s / layer_rate``.
    include_margin : bool
        Make the grid bound (grid supremum + curvature margin) satisfy the condition too.
    budget : int
        Approximate number of grid points (sets the grid size of the nonlinear coordinates).
    n_grid : int, optional
        Points per nonlinear coordinate (overrides ``budget``).
    raise_infeasible : bool
        Raise :class:`InfeasibleGainError` instead of returning ``feasible=False``.
    disturbance_bound : float or array_like, shape (n,)
        ``D_j >= |d_j|`` of a matched motor torque disturbance (plant ``x' = f + g (u + d)``,
        e.g. Coulomb friction, :mod:`fjm_runtime.control.disturbance`), N m; adds
        ``sum_j |(C J g)_ij| D_j`` to the drift bound.
    evaluator : callable, optional
        ``evaluator(model, p_nom, c_last, beta_hat) -> Evaluator`` of the same outputs for
        another law (the torque-sensed one: :mod:`fjm_runtime.analysis.certificates.certify_tau`);
        default the state-feedback law above.

    Returns
    -------
    TuneResult
    """
    n = int(model.n)
    p_nom, box, cc, R, E, Ybox, W, bh = nominal_setup(model, nominal_params, param_box, reference_bounds,
                                                       error_bounds, lam, c, integral, beta_hat)
    eta, umax, D = _check_vectors(n, eta, u_max, disturbance_bound)
    an = BoxAnalysis(model, p_nom, box, cc, Ybox, W, bh, budget, seed, n_grid, D, evaluator=evaluator)
    k, reason, extra_pts, margin = _refined_gain(an, eta, include_margin)
    out = _certify_gain(an, k, reason, extra_pts, margin)
    dl = (k / layer_rate) if delta is None else np.broadcast_to(np.asarray(delta, dtype=float), (n,)).copy()
    u_bound = out["u_bound"]
    if not reason and umax is not None and np.any(u_bound > umax):
        i = int(np.argmax(u_bound / umax))
        reason = (f"joint {i + 1}: the gain the reaching condition needs (k_s = {k[i]:.4g}) lets the law command "
                  f"|u| up to {u_bound[i]:.4g} N m on the box, above u_max = {umax[i]:.4g} N m: no admissible "
                  "gain within the actuator limit (shrink the box or lambda, or use the adaptive law)")
    stiffness = _stiffness(model, an, box, p_nom)
    if stiffness is not None and stiffness["outside"] and not reason:
        reason = stiffness["outside"]
    settings = {"nominal_params": dict(zip(model.param_names, p_nom.tolist())), "param_box": box,
                "reference_bounds": R.tolist(), "error_bounds": E.tolist(), "integral": bool(integral),
                "beta_hat": "beta(x; p_nom)" if bh is None else bh.tolist(), "include_margin": include_margin,
                "layer_rate": layer_rate, "disturbance_bound": D.tolist()}
    result = TuneResult(model=model.name, feasible=not reason, reason=reason, k_s=k, delta=dl, eta=eta,
                        W=W, y_box=Ybox, c=cc, u_max=umax, grid=_grid_summary(an, extra_pts),
                        settings=settings, stiffness=stiffness, **out)
    if reason and raise_infeasible:
        raise InfeasibleGainError(f"{model.name}: {reason}", result)
    return result


def _check_vectors(n: int, eta, u_max, disturbance_bound):
    """``eta`` (n,) > 0, ``u_max`` (n,) > 0 or None, ``D`` (n,) >= 0, broadcast per joint."""
    eta = np.broadcast_to(np.asarray(eta, dtype=float), (n,)).copy()
    if not np.all(np.isfinite(eta)) or np.any(eta <= 0):
        raise ValueError(f"eta = {eta.tolist()}: expected finite values > 0 (rad/s^4)")
    umax = None if u_max is None else np.broadcast_to(np.asarray(u_max, dtype=float), (n,)).copy()
    if umax is not None and (not np.all(np.isfinite(umax)) or np.any(umax <= 0)):
        raise ValueError(f"u_max = {umax.tolist()}: expected finite values > 0 (N m)")
    D = np.broadcast_to(np.asarray(disturbance_bound, dtype=float), (n,)).copy()
    if not np.all(np.isfinite(D)) or np.any(D < 0):
        raise ValueError(f"disturbance_bound = {D.tolist()}: expected finite values >= 0 (N m)")
    return eta, umax, D


def _stiffness(model, an: BoxAnalysis, box, p_nom) -> Optional[dict]:
    """A nonlinear spring's interval over the deflections the certificate visited (None: linear spring)."""
    deflection = getattr(an.ev, "deflection", None)
    if deflection is None or not np.all(np.isfinite(deflection)):
        return None
    return stiffness_interval(model, box, p_nom, deflection)


def _refined_gain(an: BoxAnalysis, eta: np.ndarray, include_margin: bool):
    """Gain on the grid, then up to 3 rounds: refine the supremum, add the worst points, re-solve.

    Returns ``(k (n,), reason, extra points (M, len(dims)), last curvature margin (n,))``.
    """
    F0, G, W = an.F0, an.G, an.W
    k, reason = solve_gain(F0, G, W, eta)
    extra_pts = np.zeros((0, len(an.dims)))
    margin = np.zeros(an.n)
    if reason:
        return k, reason, extra_pts, margin
    for _ in range(3):
        Phi = an.phi(F0, G, W, k)
        margin = an.margin(Phi)
        pts, _ = an.refine(Phi, k)
        extra_pts = np.vstack([extra_pts, pts])
        _, V = an.phi_at(extra_pts, k)
        F0x, Gx = an.split(V)
        eta_eff = eta + (margin if include_margin else 0.0)
        k_new, reason = solve_gain(np.vstack([F0, F0x]), np.vstack([G, Gx]), W, eta_eff)
        if reason:
            break
        done = np.allclose(k_new, k, rtol=1e-9, atol=0)
        k = k_new
        if done:
            break
    return k, reason, extra_pts, margin


def _certify_gain(an: BoxAnalysis, k: np.ndarray, reason: str, extra_pts: np.ndarray, margin: np.ndarray) -> dict:
    """The certificate fields of :class:`TuneResult` for the gain ``k`` (n,) (NaN when ``reason``)."""
    n, F0, G, W = an.n, an.F0, an.G, an.W
    allF0 = np.vstack([F0, an.split(an.phi_at(extra_pts, np.zeros(n))[1])[0]]) if len(extra_pts) else F0
    sup_F = np.max(np.abs(allF0), axis=0) + np.max(np.abs(G - np.eye(n)), axis=0) @ W
    all_pts = np.vstack([an.pts, extra_pts]) if len(extra_pts) else an.pts
    if reason:
        nan = np.full(n, np.nan)
        return dict(certificate=nan, certificate_grid_bound=nan.copy(), margin=margin, witness=[],
                    sup_F=sup_F, u_bound=nan.copy(), margin_lipschitz=None)
    Phi_all = an.phi_at(all_pts, k)[0] if len(extra_pts) else an.phi(F0, G, W, k)
    Phi_grid = an.phi(F0, G, W, k)
    margin = an.margin(Phi_grid)
    return dict(certificate=np.max(Phi_all, axis=0), certificate_grid_bound=np.max(Phi_grid, axis=0) + margin,
                margin=margin, sup_F=sup_F, u_bound=an.u_bound(k),
                witness=[witness_point(an, all_pts[int(np.argmax(Phi_all[:, i]))], i, k) for i in range(n)],
                margin_lipschitz=an.margin(Phi_grid, kind="lipschitz"))


def _grid_summary(an: BoxAnalysis, extra_pts: np.ndarray) -> dict:
    """``TuneResult.grid``: how each coordinate was treated and the grid sizes."""
    return {"coordinates": [{"name": d.name, "lo": d.lo, "hi": d.hi,
                             "treatment": "no effect (one point)" if d.constant else
                             "vertices (affine)" if d.affine else f"grid {d.points} + local max"}
                            for d in an.dims],
            "grid_points": int(an.pts.shape[0]), "refined_points": int(extra_pts.shape[0]),
            "sampling": ("random (too many coordinates for a grid): uniform samples, affine coordinates at random "
                         "vertices, local maximization; no grid margin, a weaker numerical certificate")
            if an.random else "tensor grid"}



def certificate(model, k_s, nominal_params=None, *, param_box=None, reference_bounds, error_bounds,
                lam: Optional[float] = None, c=None, integral: bool = False, beta_hat=None,
                budget: int = 60000, n_grid: Optional[int] = None, seed: int = 0, disturbance_bound=0.0,
                evaluator=None) -> dict:
    """Worst ``sgn(s_i) s_i'`` bound on the box for a GIVEN gain (e.g. a hand-picked or Lemma 1 gain).

    Same box and method as :func:`synthesize_gains`. Returns a dict with
    ``certificate`` (n,) (grid + local refinement), ``grid_bound`` (n,) (grid
    supremum + curvature margin), ``margin`` (n,) and ``witness`` (list of dict). ``evaluator``:
    as in :func:`synthesize_gains`.
    """
    n = int(model.n)
    p_nom, box, cc, R, E, Ybox, W, bh = nominal_setup(model, nominal_params, param_box, reference_bounds,
                                                       error_bounds, lam, c, integral, beta_hat)
    k = np.broadcast_to(np.asarray(k_s, dtype=float), (n,)).copy()
    if not np.all(np.isfinite(k)) or np.any(k < 0):
        raise ValueError(f"k_s = {k.tolist()}: expected finite values >= 0")
    D = np.broadcast_to(np.asarray(disturbance_bound, dtype=float), (n,)).copy()
    an = BoxAnalysis(model, p_nom, box, cc, Ybox, W, bh, budget, seed, n_grid, D, evaluator=evaluator)
    Phi = an.phi(an.F0, an.G, W, k)
    margin = an.margin(Phi)
    pts, ph = an.refine(Phi, k)
    all_pts = np.vstack([an.pts, pts]); all_phi = np.vstack([Phi, ph])
    return {"certificate": np.max(all_phi, axis=0), "grid_bound": np.max(Phi, axis=0) + margin,
            "margin": margin,
            "witness": [witness_point(an, all_pts[int(np.argmax(all_phi[:, i]))], i, k) for i in range(n)]}
