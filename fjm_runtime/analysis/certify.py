"""Reaching-gain synthesis for the sliding-mode law that is actually run (``fjm tune``).

The law (:mod:`fjm_runtime.controllers`)
----------------------------------------
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

:func:`paper_bound` evaluates the paper's Lemma 1 (eq 16 with ``rho``) in TRUE
coordinates with the same machinery, for comparison (scalar models only).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from itertools import product
from typing import Dict, List, Optional, Tuple

import numpy as np

from ..control.laws import coefficients_from_pole

__all__ = ["TuneResult", "InfeasibleGainError", "synthesize_gains", "certificate", "paper_bound",
           "AdaptiveTuneResult", "synthesize_adaptive_gains",
           "PaperBound", "param_box_from_ranges", "surface_coefficients"]


class InfeasibleGainError(ValueError):
    """No gain satisfies the reaching condition on the box (``.result`` holds the analysis)."""

    def __init__(self, message: str, result: "TuneResult" = None):
        super().__init__(message)
        self.result = result


# ---------------------------------------------------------------------------------------------
# inputs
def surface_coefficients(lam: Optional[float] = None, c=None, integral: bool = False) -> np.ndarray:
    """Surface coefficients, lowest first (``[c1, c2, c3]`` or ``[c0, c1, c2, c3]``), from ``lam`` or ``c``."""
    order = 4 if integral else 3
    if (lam is None) == (c is None):
        raise ValueError("lam/c: give exactly one of lam (pole magnitude, 1/s) or c (coefficients)")
    if lam is not None:
        return coefficients_from_pole(lam, order)
    cc = np.asarray(c, dtype=float).ravel()
    if cc.shape != (order,) or not np.all(np.isfinite(cc)) or np.any(cc <= 0):
        raise ValueError(f"c = {np.asarray(c).tolist()}: expected {order} finite values > 0")
    return cc


def param_box_from_ranges(model, k_range=None, jm_range=None, bm_range=None, mass_range=None,
                          extra: Optional[Dict[str, Tuple[float, float]]] = None) -> Dict[str, Tuple[float, float]]:
    """Parameter box ``{name: (lo, hi)}`` from per-kind ranges applied to every joint.

    Parameters
    ----------
    model : Model
    k_range, jm_range, bm_range : (lo, hi), optional
        Absolute bounds for every joint stiffness (``K``/``K<i>``), motor inertia
        (``J_m``/``Jm<i>``) and motor damping (``B_m``/``Bm<i>``).
    mass_range : (lo, hi), optional
        Absolute bounds for every link mass (``M``/``m<i>``; link1's ``M`` is the tip mass).
    extra : dict, optional
        Further ``name: (lo, hi)`` entries (override the above).
    """
    names = list(model.param_names)
    n = int(model.n)

    def pick(single, pattern):
        if single in names:
            return [single]
        return [pattern.format(i + 1) for i in range(n) if pattern.format(i + 1) in names]

    box: Dict[str, Tuple[float, float]] = {}
    for rng, single, pattern in ((k_range, "K", "K{}"), (jm_range, "J_m", "Jm{}"),
                                 (bm_range, "B_m", "Bm{}"), (mass_range, "M", "m{}")):
        if rng is None:
            continue
        lst = pick(single, pattern)
        if not lst:
            raise ValueError(f"model {model.name!r} has no parameter {single!r} or {pattern.format(1)!r}; "
                             f"parameters: {names}")
        for nm in lst:
            box[nm] = (float(rng[0]), float(rng[1]))
    box.update(extra or {})
    return box


def _check_box(model, p_nom: np.ndarray, box) -> Dict[str, Tuple[float, float]]:
    out = {}
    for name, rng in (box or {}).items():
        if name not in model.param_names:
            raise ValueError(f"param_box: unknown parameter {name!r}; expected one of {list(model.param_names)}")
        try:
            lo, hi = (float(v) for v in rng)
        except (TypeError, ValueError):
            raise ValueError(f"param_box[{name!r}] = {rng!r}: expected (lo, hi)") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            raise ValueError(f"param_box[{name!r}] = {rng!r}: expected finite lo <= hi")
        if lo < hi:
            out[name] = (lo, hi)
    return out


def _per_joint(value, rows: int, n: int, field: str) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.ndim == 1 and a.shape == (rows,):
        a = np.repeat(a[:, None], n, axis=1)
    if a.shape != (rows, n) or not np.all(np.isfinite(a)) or np.any(a < 0):
        raise ValueError(f"{field} with shape {np.shape(value)}: expected {rows} finite values >= 0 "
                         f"(shape ({rows},) or ({rows}, {n}))")
    return a


# ---------------------------------------------------------------------------------------------
# CasADi: F0, G, alpha_hat, B as functions of (y_hat, p_true)
def _build_inverse(model, p_const=None):
    """CasADi Function ``(x, y, p) -> (T_m(x; p) - y_m, dT_m/dx_m)`` for Newton on the motor half of ``T``.

    ``T`` keeps ``q_l`` and ``dq_l`` as they are (``y1 = q_l``, ``y2 = dq_l``), so
    ``x = T^{-1}(y)`` only needs ``q_m``, ``dq_m``. ``p_const``: a fixed parameter
    vector (the nominal one) instead of the argument ``p``.
    """
    import casadi as ca
    n, nx, npar = int(model.n), int(model.nx), len(model.param_names)
    x = ca.SX.sym("x", nx)
    y = ca.SX.sym("y", nx)
    p = ca.SX.sym("p", npar)
    pp = ca.DM(p_const) if p_const is not None else p
    Tm = model.functions["T"](x, pp)[2 * n:]
    return ca.Function("tune_newton", [x, y, p], [Tm - y[2 * n:], ca.jacobian(Tm, x[2 * n:])])


def _build_nominal_fn(model, p_nom: np.ndarray, c_last: np.ndarray, beta_hat):
    """CasADi Function ``(x, y, p) -> [F0; vec G; alpha_hat; vec B; vec C J g]`` (see the module docstring)."""
    import casadi as ca
    n, nx, npar = int(model.n), int(model.nx), len(model.param_names)
    fns = model.functions
    x = ca.SX.sym("x", nx)
    y = ca.SX.sym("y", 4 * n)
    p = ca.SX.sym("p", npar)
    pn = ca.DM(p_nom)
    J = ca.jacobian(fns["T"](x, pn), x)
    C = ca.horzcat(*[float(c_last[k]) * ca.SX.eye(n) for k in range(3)], ca.SX.eye(n))
    f = fns["f"](x, p)
    g = ca.reshape(fns["g"](x, p), nx, n)
    a_hat = fns["alpha"](x, pn)
    B = ca.SX(ca.DM(beta_hat)) if beta_hat is not None else ca.reshape(fns["beta"](x, pn), n, n)
    CJ = ca.mtimes(C, J)
    lin = float(c_last[0]) * y[n:2 * n] + float(c_last[1]) * y[2 * n:3 * n] + float(c_last[2]) * y[3 * n:]
    F0 = ca.mtimes(CJ, f + ca.mtimes(g, a_hat)) - lin
    G = ca.mtimes(ca.mtimes(CJ, g), B)
    CJg = ca.mtimes(CJ, g)
    out = ca.vertcat(F0, ca.reshape(G, n * n, 1), a_hat, ca.reshape(B, n * n, 1), ca.reshape(CJg, n * n, 1))
    return ca.Function("tune_nominal", [x, y, p], [out])


def _build_true_fn(model, p_nom: np.ndarray):
    """``(x, y, p) -> [alpha(x; p_nom) - alpha(x; p); beta(x; p)]`` (true coordinates, ``x = T^{-1}(y; p)``)."""
    import casadi as ca
    n, nx, npar = int(model.n), int(model.nx), len(model.param_names)
    fns = model.functions
    x = ca.SX.sym("x", nx)
    y = ca.SX.sym("y", nx)
    p = ca.SX.sym("p", npar)
    d_alpha = fns["alpha"](x, ca.DM(p_nom)) - fns["alpha"](x, p)
    beta = ca.reshape(fns["beta"](x, p), n * n, 1)
    return ca.Function("tune_true", [x, y, p], [ca.vertcat(d_alpha, beta)])


class _Evaluator:
    """Batched ``(Y, P) -> values``: ``x = T^{-1}(y; p_inv)`` by batched Newton, then ``fn(x, y, p)``.

    Chunks of columns through cached ``Function.map``; the Newton residual of
    every point is checked (``ValueError`` when it does not converge).
    """

    def __init__(self, model, fn, p_inverse=None, chunk: int = 20000, iterations: int = 4):
        self.n, self.nx = int(model.n), int(model.nx)
        self.inv = _build_inverse(model, p_inverse)
        self.fn, self.chunk, self.maps, self.iterations = fn, chunk, {}, iterations

    def _map(self, fn, m):
        key = (fn.name(), m)
        fm = self.maps.get(key)
        if fm is None:
            fm = self.maps[key] = fn.map(m)
        return fm

    def __call__(self, Y: np.ndarray, P: np.ndarray) -> np.ndarray:
        N, n = Y.shape[0], self.n
        out = []
        for a in range(0, N, self.chunk):
            b = min(N, a + self.chunk)
            m = b - a
            Yc, Pc = Y[a:b], P[a:b]
            X = np.concatenate([Yc[:, :2 * n], Yc[:, :2 * n]], axis=1)
            inv = self._map(self.inv, m)
            for _ in range(self.iterations):
                r, J = inv(X.T, Yc.T, Pc.T)
                r = np.asarray(r).T
                J = np.asarray(J).reshape(2 * n, m, 2 * n).transpose(1, 0, 2)
                X[:, 2 * n:] -= np.linalg.solve(J, r[:, :, None])[:, :, 0]
            r = np.asarray(inv(X.T, Yc.T, Pc.T)[0]).T
            scale = 1.0 + np.max(np.abs(Yc), axis=1)
            bad = ~(np.max(np.abs(r), axis=1) <= 1e-8 * scale)
            if np.any(bad):
                j = int(np.flatnonzero(bad)[0])
                raise ValueError(f"T^(-1): Newton did not converge at y = {np.round(Yc[j], 4).tolist()} "
                                 f"(residual {np.max(np.abs(r[j])):.3g}); the box may be too large for this model")
            out.append(np.asarray(self._map(self.fn, m)(X.T, Yc.T, Pc.T)).T)
        return np.concatenate(out, axis=0)


# ---------------------------------------------------------------------------------------------
# the box: coordinates, affinity classification, grid
@dataclass
class _Dim:
    name: str
    kind: str          # 'y' or 'p'
    index: int         # index into y (4n) or into the parameter vector
    lo: float
    hi: float
    affine: bool = False
    points: int = 2
    constant: bool = False

    def values(self) -> np.ndarray:
        if self.lo == self.hi or self.constant:
            return np.array([0.5 * (self.lo + self.hi)])
        return np.array([self.lo, self.hi]) if self.affine else np.linspace(self.lo, self.hi, self.points)


def _dims(model, Ybox: np.ndarray, p_nom, box) -> List[_Dim]:
    n = int(model.n)
    names = ("q", "dq", "ddq", "dddq")
    dims = []
    for k in range(4):
        for i in range(n):
            Y = float(Ybox[k, i])
            dims.append(_Dim(f"y{k + 1}[{i + 1}] ({names[k]}{i + 1})", "y", k * n + i, -Y, Y))
    pn = list(model.param_names)
    for name, (lo, hi) in box.items():
        dims.append(_Dim(name, "p", pn.index(name), lo, hi))
    return dims


def _assemble(dims: List[_Dim], pts: np.ndarray, n: int, p_nom: np.ndarray):
    """Columns of ``pts`` (one per dim) -> (Y (N, 4n), P (N, npar))."""
    N = pts.shape[0]
    Y = np.zeros((N, 4 * n))
    P = np.repeat(p_nom[None, :], N, axis=0)
    for d, dim in enumerate(dims):
        (Y if dim.kind == "y" else P)[:, dim.index] = pts[:, d]
    return Y, P


def _classify(dims, evaluate, n, p_nom, rng, n_test: int = 48, tol: float = 1e-7, relevant=None) -> None:
    """Mark the coordinates along which the outputs are affine (numerical midpoint/third-point test).

    ``relevant``: indices of the outputs that enter ``Phi``; a coordinate that none of
    them depends on is marked ``constant`` (one grid point; the torque bound then
    handles it separately).
    """
    lo = np.array([d.lo for d in dims]); hi = np.array([d.hi for d in dims])
    base = lo + (hi - lo) * rng.random((n_test, len(dims)))
    for d, dim in enumerate(dims):
        if dim.lo == dim.hi:
            dim.affine = True
            continue
        fr = np.array([0.0, 1.0, 0.5, 1.0 / 3.0])
        pts = np.repeat(base, fr.size, axis=0)
        pts[:, d] = np.tile(dim.lo + fr * (dim.hi - dim.lo), n_test)
        Y, P = _assemble(dims, pts, n, p_nom)
        V = evaluate(Y, P).reshape(n_test, fr.size, -1)
        a, b, m, t = V[:, 0], V[:, 1], V[:, 2], V[:, 3]
        scale = 1.0 + np.max(np.abs(V))
        err = max(np.max(np.abs(m - 0.5 * (a + b))), np.max(np.abs(t - (2 * a + b) / 3.0)))
        dim.affine = bool(err <= tol * scale)
        if relevant is not None:
            ra, rb, rm = a[:, relevant], b[:, relevant], m[:, relevant]
            rs = 1.0 + np.max(np.abs(V[:, :, relevant]))
            dim.constant = bool(dim.affine and np.max(np.abs(rb - ra)) <= tol * rs and
                                np.max(np.abs(rm - ra)) <= tol * rs)


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
        The curvature margin ``sum_d M_d h_d^2 / 8`` (see :meth:`_Analysis.margin`).
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

    def reaching_time_bound(self, s0) -> np.ndarray:
        """``(|s_i(0)| - delta_i)^+ / eta_i`` per joint (s), valid while the state stays in the box."""
        s0 = np.abs(np.broadcast_to(np.asarray(s0, dtype=float), self.k_s.shape))
        return np.maximum(s0 - self.delta, 0.0) / self.eta

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


def _nominal_setup(model, nominal_params, param_box, reference_bounds, error_bounds, lam, c, integral,
                   beta_hat):
    n = int(model.n)
    p_nom = np.asarray(model.params_array(nominal_params or {}, arg="nominal_params"), dtype=float)
    box = _check_box(model, p_nom, param_box)
    cc = surface_coefficients(lam, c, integral)
    R = _per_joint(reference_bounds, 5, n, "reference_bounds")
    E = _per_joint(error_bounds, 4, n, "error_bounds")
    Ybox = R[:4] + E
    ce = np.concatenate([[0.0], cc]) if not integral else cc       # coefficient of e1 .. e4 in `linear`
    W = R[4] + ce[0] * E[0] + ce[1] * E[1] + ce[2] * E[2] + ce[3] * E[3] if integral else \
        R[4] + cc[0] * E[1] + cc[1] * E[2] + cc[2] * E[3]
    bh = None
    if beta_hat is not None:
        bh = np.asarray(beta_hat, dtype=float)
        bh = bh * np.eye(n) if bh.ndim == 0 else bh
        if bh.shape != (n, n):
            raise ValueError(f"beta_hat with shape {bh.shape}: expected a scalar or ({n}, {n})")
    return p_nom, box, cc, R, E, Ybox, np.asarray(W, dtype=float), bh


def _box_maximize(fg, v0: np.ndarray, maxiter: int = 60, tol: float = 1e-12) -> np.ndarray:
    """Projected gradient ascent on ``[0, 1]^d`` with an adaptive step (NumPy only, no SciPy).

    ``fg(v) -> (value, gradient)``. Accepts a step when the value increases
    (then grows the step 1.5x), halves it otherwise; stops when the step falls
    below ``tol`` or after ``maxiter`` accepted-or-rejected trials. Returns the best ``v``.
    """
    v = np.clip(np.asarray(v0, dtype=float), 0.0, 1.0)
    f, g = fg(v)
    step = 0.1
    for _ in range(maxiter):
        norm = float(np.linalg.norm(g))
        if norm == 0.0 or step < tol:
            break
        cand = np.clip(v + step * g / norm, 0.0, 1.0)
        if np.array_equal(cand, v):
            break
        fc, gc = fg(cand)
        if fc > f:
            v, f, g = cand, fc, gc
            step *= 1.5
        else:
            step *= 0.5
    return v


class _Analysis:
    """Grid of the box and the values ``F0``, ``G``, ``alpha_hat``, ``B`` on it (one model, one setting)."""

    def __init__(self, model, p_nom, box, cc, Ybox, W, beta_hat, budget: int, seed: int, n_grid=None,
                 D=None):
        self.model, self.n = model, int(model.n)
        self.D = np.zeros(self.n) if D is None else np.asarray(D, dtype=float)
        self.p_nom, self.W, self.Ybox = p_nom, W, Ybox
        self.fn = _build_nominal_fn(model, p_nom, cc[-3:], beta_hat)
        self.ev = _Evaluator(model, self.fn, p_inverse=p_nom)
        self.rng = np.random.default_rng(seed)
        self.dims = _dims(model, Ybox, p_nom, box)
        n = self.n
        relevant = np.r_[0:n + n * n, 2 * n + 2 * n * n:2 * n + 3 * n * n]      # F0, G, C J g
        _classify(self.dims, self.ev, self.n, p_nom, self.rng, relevant=relevant)
        nl = [d for d in self.dims if not d.affine and d.lo < d.hi]
        n_vert = int(np.prod([len(d.values()) for d in self.dims if d.affine or d.lo == d.hi]))
        self.random = False
        if n_grid is None:
            per = int(np.floor((budget / max(n_vert, 1)) ** (1.0 / max(len(nl), 1)) + 1e-9))
            n_grid = max(3, per)
            self.random = n_vert * float(n_grid) ** len(nl) > 4 * budget
        for d in nl:
            d.points = int(n_grid)
        if self.random:
            # too many coordinates for a grid: uniform samples, affine coordinates at random vertices
            N = int(budget)
            mesh = np.empty((N, len(self.dims)))
            for j, d in enumerate(self.dims):
                v = d.values()
                if d.affine or d.lo == d.hi:
                    mesh[:, j] = v[self.rng.integers(0, len(v), N)]
                else:
                    mesh[:, j] = self.rng.uniform(d.lo, d.hi, N)
            self.shape = None
        else:
            axes = [d.values() for d in self.dims]
            self.shape = tuple(len(a) for a in axes)
            mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(self.dims))
        self.pts = mesh
        Y, P = _assemble(self.dims, mesh, self.n, p_nom)
        V = self.ev(Y, P)
        self._unpack(V)

    def split(self, V):
        """``(|F0| + |C J g| D, G)`` from raw values: the drift bound including the matched disturbance."""
        n = self.n
        F0 = np.abs(V[:, :n])
        if np.any(self.D > 0):
            CJg = V[:, 2 * n + 2 * n * n:2 * n + 3 * n * n].reshape(-1, n, n, order="F")
            F0 = F0 + np.abs(CJg) @ self.D
        return F0, V[:, n:n + n * n].reshape(-1, n, n, order="F")

    def _unpack(self, V):
        n = self.n
        self.F0, self.G = self.split(V)
        self.ah = V[:, n + n * n:2 * n + n * n]
        self.B = V[:, 2 * n + n * n:2 * n + 2 * n * n].reshape(-1, n, n, order="F")

    def u_bound(self, k, top: int = 200) -> np.ndarray:
        """``sup |u_i| = |alpha_hat_i| + sum_j |B_ij| (W_j + k_j)`` on the grid; coordinates collapsed
        as irrelevant for ``Phi`` (but affine) are put back at their vertices around the worst points."""
        n = self.n
        U = np.abs(self.ah) + np.abs(self.B) @ (self.W + k)
        collapsed = [d for d, dim in enumerate(self.dims) if dim.constant and dim.lo < dim.hi]
        best = np.max(U, axis=0)
        if not collapsed:
            return best
        idx = np.unique(np.concatenate([np.argsort(-U[:, i])[:top] for i in range(n)]))
        combos = np.array(list(product(*[(self.dims[d].lo, self.dims[d].hi) for d in collapsed])))
        pts = np.repeat(self.pts[idx], len(combos), axis=0)
        pts[:, collapsed] = np.tile(combos, (len(idx), 1))
        Y, P = _assemble(self.dims, pts, n, self.p_nom)
        V = self.ev(Y, P)
        ah = V[:, n + n * n:2 * n + n * n]
        B = V[:, 2 * n + n * n:2 * n + 2 * n * n].reshape(-1, n, n, order="F")
        return np.maximum(best, np.max(np.abs(ah) + np.abs(B) @ (self.W + k), axis=0))

    # Phi on a set of values
    @staticmethod
    def phi(F0, G, W, k) -> np.ndarray:
        n = F0.shape[1]
        I = np.eye(n)
        drift = np.abs(F0) + np.abs(G - I) @ W
        absG = np.abs(G)
        diag = np.einsum("nii->ni", G)
        cross = absG @ k - np.einsum("nii->ni", absG) * k
        return drift + cross - diag * k

    def phi_at(self, pts, k):
        Y, P = _assemble(self.dims, pts, self.n, self.p_nom)
        V = self.ev(Y, P)
        F0, G = self.split(V)
        return self.phi(F0, G, self.W, k), V

    def margin(self, Phi: np.ndarray, kind: str = "curvature") -> np.ndarray:
        """Grid margin per joint: how much ``Phi`` may exceed its grid maximum between grid points.

        ``kind='curvature'``: ``sum_d M_d h_d^2 / 8`` with ``M_d`` the largest NEGATIVE
        curvature along coordinate ``d`` seen in the grid's second differences
        (``Phi <= multilinear interpolant + sum_d M_d h_d^2 / 8`` when ``Phi'' >= -M_d``;
        convex kinks such as ``|F0|`` do not count). ``kind='lipschitz'``:
        ``sum_d L_d h_d / 2`` with ``L_d`` the largest neighbour slope (much coarser).
        Both use slopes/curvatures sampled on the grid: numerical, not proven.
        """
        n = self.n
        if self.shape is None:            # random sampling: no grid, no margin
            return np.zeros(n)
        A = Phi.reshape(self.shape + (n,))
        m = np.zeros(n)
        rest = tuple(range(A.ndim - 1))
        for d, dim in enumerate(self.dims):
            if dim.affine or dim.lo == dim.hi or len(dim.values()) < 2:
                continue
            h = (dim.hi - dim.lo) / (dim.points - 1)
            if kind == "lipschitz":
                m += 0.5 * h * np.max(np.abs(np.diff(A, axis=d)), axis=rest) / h
            else:
                curv = np.max(-np.diff(A, n=2, axis=d), axis=rest) / h ** 2
                m += np.maximum(curv, 0.0) * h ** 2 / 8.0
        return m

    def refine(self, Phi, k, n_starts: int = 4, maxiter: int = 80):
        """Local maximization of ``Phi_i`` from the worst grid points; returns extra points and values."""
        n = self.n
        free = [d for d, dim in enumerate(self.dims) if not dim.affine and dim.lo < dim.hi]
        if not free:
            return np.zeros((0, len(self.dims))), np.zeros((0, n))
        lo = np.array([self.dims[d].lo for d in free]); hi = np.array([self.dims[d].hi for d in free])
        span = hi - lo
        extra = []
        for i in range(n):
            order = np.argsort(-Phi[:, i])[:n_starts]
            for j in order:
                base = self.pts[j].copy()

                def obj(v, base=base, i=i):
                    h = 1e-6
                    V = np.repeat(base[None, :], 2 * len(free) + 1, axis=0)
                    V[0, free] = lo + v * span
                    for a in range(len(free)):
                        V[1 + 2 * a] = V[0]; V[2 + 2 * a] = V[0]
                        V[1 + 2 * a, free[a]] = lo[a] + np.clip(v[a] + h, 0, 1) * span[a]
                        V[2 + 2 * a, free[a]] = lo[a] + np.clip(v[a] - h, 0, 1) * span[a]
                    ph, _ = self.phi_at(V, k)
                    val = ph[:, i]
                    grad = np.empty(len(free))
                    for a in range(len(free)):
                        dv = np.clip(v[a] + h, 0, 1) - np.clip(v[a] - h, 0, 1)
                        grad[a] = (val[1 + 2 * a] - val[2 + 2 * a]) / dv if dv > 0 else 0.0
                    return val[0], grad

                v0 = (base[free] - lo) / span
                vbest = _box_maximize(obj, v0, maxiter=maxiter)
                pt = base.copy()
                pt[free] = lo + vbest * span
                extra.append(pt)
        extra = np.array(extra)
        ph, _ = self.phi_at(extra, k)
        return extra, ph


def _solve_gain(F0, G, W, eta, max_iter: int = 500):
    """Smallest ``k`` with ``max Phi_i <= -eta_i`` (fixed-point iteration); (k, reason or '')."""
    n = F0.shape[1]
    diag = np.einsum("nii->ni", G)
    if np.any(diag <= 0):
        j = int(np.argmin(np.min(diag, axis=1)))
        i = int(np.argmin(diag[j]))
        return np.full(n, np.nan), (f"joint {i + 1}: the input gain G_ii of s_i' is {diag[j, i]:.3g} <= 0 at a "
                                    "point of the box: the switching term does not act on s_i there")
    drift = np.abs(F0) + np.abs(G - np.eye(n)) @ W
    absG = np.abs(G)
    off = absG - np.einsum("nij,ij->nij", absG, np.eye(n))
    k = np.max((drift + eta) / diag, axis=0)
    for _ in range(max_iter):
        k_new = np.max((drift + eta + off @ k) / diag, axis=0)
        if np.all(np.abs(k_new - k) <= 1e-12 * (1 + np.abs(k_new))):
            return k_new, ""
        if not np.all(np.isfinite(k_new)) or np.max(k_new) > 1e15:
            break
        k = k_new
    return np.full(n, np.nan), ("the input gains couple the joints too strongly (G is not diagonally "
                                "dominant on the box): no per-joint constant gain dominates the coupling")


def _witness(an: "_Analysis", pt: np.ndarray, i: int, k) -> dict:
    n = an.n
    Y, P = _assemble(an.dims, pt[None, :], n, an.p_nom)
    V = an.ev(Y, P)
    F0 = V[0, :n]
    G = V[0, n:n + n * n].reshape(n, n, order="F")
    sgn = 1.0 if F0[i] >= 0 else -1.0
    w = sgn * np.sign(G[i] - np.eye(n)[i]) * an.W
    CJg = V[0, 2 * n + 2 * n * n:2 * n + 3 * n * n].reshape(n, n, order="F")
    d = sgn * np.sign(CJg[i]) * an.D
    params = {d_.name: float(pt[j]) for j, d_ in enumerate(an.dims) if d_.kind == "p"}
    return {"joint": i + 1, "y_hat": Y[0].reshape(4, n).tolist(), "params": params,
            "w": w.tolist(), "sign_s": sgn, "F0": float(F0[i]), "G_row": G[i].tolist(),
            "disturbance": d.tolist()}


def synthesize_gains(model, nominal_params=None, *, param_box=None, reference_bounds, error_bounds,
                     lam: Optional[float] = None, c=None, integral: bool = False, beta_hat=None,
                     eta=10.0, u_max=None, delta=None, layer_rate: float = 200.0,
                     include_margin: bool = True, budget: int = 60000, n_grid: Optional[int] = None,
                     seed: int = 0, raise_infeasible: bool = False, disturbance_bound=0.0) -> TuneResult:
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
        e.g. Coulomb friction, :mod:`fjm_runtime.disturbance`), N m; adds
        ``sum_j |(C J g)_ij| D_j`` to the drift bound.

    Returns
    -------
    TuneResult
    """
    n = int(model.n)
    p_nom, box, cc, R, E, Ybox, W, bh = _nominal_setup(model, nominal_params, param_box, reference_bounds,
                                                       error_bounds, lam, c, integral, beta_hat)
    eta = np.broadcast_to(np.asarray(eta, dtype=float), (n,)).copy()
    if not np.all(np.isfinite(eta)) or np.any(eta <= 0):
        raise ValueError(f"eta = {eta.tolist()}: expected finite values > 0 (rad/s^4)")
    umax = None if u_max is None else np.broadcast_to(np.asarray(u_max, dtype=float), (n,)).copy()
    if umax is not None and (not np.all(np.isfinite(umax)) or np.any(umax <= 0)):
        raise ValueError(f"u_max = {umax.tolist()}: expected finite values > 0 (N m)")
    D = np.broadcast_to(np.asarray(disturbance_bound, dtype=float), (n,)).copy()
    if not np.all(np.isfinite(D)) or np.any(D < 0):
        raise ValueError(f"disturbance_bound = {D.tolist()}: expected finite values >= 0 (N m)")
    an = _Analysis(model, p_nom, box, cc, Ybox, W, bh, budget, seed, n_grid, D)
    F0, G = an.F0, an.G
    k, reason = _solve_gain(F0, G, W, eta)
    margin = np.zeros(n)
    extra_pts = np.zeros((0, len(an.dims)))
    if not reason:
        for _ in range(3):     # refine the supremum, add the worst points, re-solve
            Phi = an.phi(F0, G, W, k)
            margin = an.margin(Phi)
            pts, _ = an.refine(Phi, k)
            extra_pts = np.vstack([extra_pts, pts])
            _, V = an.phi_at(extra_pts, k)
            F0x, Gx = an.split(V)
            eta_eff = eta + (margin if include_margin else 0.0)
            k_new, reason = _solve_gain(np.vstack([F0, F0x]), np.vstack([G, Gx]), W, eta_eff)
            if reason:
                break
            done = np.allclose(k_new, k, rtol=1e-9, atol=0)
            k = k_new
            if done:
                break
    allF0 = np.vstack([F0, an.split(an.phi_at(extra_pts, np.zeros(n))[1])[0]]) if len(extra_pts) else F0
    sup_F = np.max(np.abs(allF0), axis=0) + np.max(np.abs(G - np.eye(n)), axis=0) @ W
    all_pts = np.vstack([an.pts, extra_pts]) if len(extra_pts) else an.pts
    if reason:
        cert = np.full(n, np.nan); grid_bound = np.full(n, np.nan); witness = []; margin_lip = None
        u_bound = np.full(n, np.nan)
    else:
        Phi_all, V_all = an.phi_at(all_pts, k) if len(extra_pts) else (an.phi(F0, G, W, k), None)
        Phi_grid = an.phi(F0, G, W, k)
        margin = an.margin(Phi_grid)
        cert = np.max(Phi_all, axis=0)
        grid_bound = np.max(Phi_grid, axis=0) + margin
        margin_lip = an.margin(Phi_grid, kind="lipschitz")
        witness = [_witness(an, all_pts[int(np.argmax(Phi_all[:, i]))], i, k) for i in range(n)]
        u_bound = an.u_bound(k)
    dl = (k / layer_rate) if delta is None else np.broadcast_to(np.asarray(delta, dtype=float), (n,)).copy()
    if not reason and umax is not None and np.any(u_bound > umax):
        i = int(np.argmax(u_bound / umax))
        reason = (f"joint {i + 1}: the gain the reaching condition needs (k_s = {k[i]:.4g}) lets the law command "
                  f"|u| up to {u_bound[i]:.4g} N m on the box, above u_max = {umax[i]:.4g} N m: no admissible "
                  "gain within the actuator limit (shrink the box or lambda, or use the adaptive law)")
    grid = {"coordinates": [{"name": d.name, "lo": d.lo, "hi": d.hi,
                             "treatment": "no effect (one point)" if d.constant else
                             "vertices (affine)" if d.affine else f"grid {d.points} + local max"}
                            for d in an.dims],
            "grid_points": int(an.pts.shape[0]), "refined_points": int(extra_pts.shape[0]),
            "sampling": ("random (too many coordinates for a grid): uniform samples, affine coordinates at random "
                         "vertices, local maximization; no grid margin, a weaker numerical certificate")
            if an.random else "tensor grid"}
    settings = {"nominal_params": dict(zip(model.param_names, p_nom.tolist())), "param_box": box,
                "reference_bounds": R.tolist(), "error_bounds": E.tolist(), "integral": bool(integral),
                "beta_hat": "beta(x; p_nom)" if bh is None else bh.tolist(), "include_margin": include_margin,
                "layer_rate": layer_rate, "disturbance_bound": D.tolist()}
    result = TuneResult(model=model.name, feasible=not reason, reason=reason, k_s=k, delta=dl, eta=eta,
                        certificate=cert, certificate_grid_bound=grid_bound, margin=margin, witness=witness,
                        sup_F=sup_F, u_bound=u_bound, u_max=umax, W=W, y_box=Ybox, c=cc, grid=grid,
                        settings=settings, margin_lipschitz=margin_lip)
    if reason and raise_infeasible:
        raise InfeasibleGainError(f"{model.name}: {reason}", result)
    return result


def certificate(model, k_s, nominal_params=None, *, param_box=None, reference_bounds, error_bounds,
                lam: Optional[float] = None, c=None, integral: bool = False, beta_hat=None,
                budget: int = 60000, n_grid: Optional[int] = None, seed: int = 0, disturbance_bound=0.0) -> dict:
    """Worst ``sgn(s_i) s_i'`` bound on the box for a GIVEN gain (e.g. a hand-picked or Lemma 1 gain).

    Same box and method as :func:`synthesize_gains`. Returns a dict with
    ``certificate`` (n,) (grid + local refinement), ``grid_bound`` (n,) (grid
    supremum + curvature margin), ``margin`` (n,) and ``witness`` (list of dict).
    """
    n = int(model.n)
    p_nom, box, cc, R, E, Ybox, W, bh = _nominal_setup(model, nominal_params, param_box, reference_bounds,
                                                       error_bounds, lam, c, integral, beta_hat)
    k = np.broadcast_to(np.asarray(k_s, dtype=float), (n,)).copy()
    if not np.all(np.isfinite(k)) or np.any(k < 0):
        raise ValueError(f"k_s = {k.tolist()}: expected finite values >= 0")
    D = np.broadcast_to(np.asarray(disturbance_bound, dtype=float), (n,)).copy()
    an = _Analysis(model, p_nom, box, cc, Ybox, W, bh, budget, seed, n_grid, D)
    Phi = an.phi(an.F0, an.G, W, k)
    margin = an.margin(Phi)
    pts, ph = an.refine(Phi, k)
    all_pts = np.vstack([an.pts, pts]); all_phi = np.vstack([Phi, ph])
    return {"certificate": np.max(all_phi, axis=0), "grid_bound": np.max(Phi, axis=0) + margin,
            "margin": margin,
            "witness": [_witness(an, all_pts[int(np.argmax(all_phi[:, i]))], i, k) for i in range(n)]}


# ---------------------------------------------------------------------------------------------
@dataclass
class PaperBound:
    """Lemma 1 (eq 16 with ``rho``) in TRUE coordinates: ``k_s = rho W + H / beta_hat + eta``.

    Attributes
    ----------
    k_s : float
        ``rho W + H / beta_hat + eta``.
    k_s_eq16 : float
        ``W + H / beta_hat + eta`` (the paper's eq 16, ``rho`` replaced by 1).
    rho, W, H, beta_hat, beta_min, beta_max, eta : float
    H_at : dict
        Where ``|alpha_hat - alpha|`` is largest (``y`` and the parameters).
    """

    k_s: float
    k_s_eq16: float
    rho: float
    W: float
    H: float
    beta_hat: float
    beta_min: float
    beta_max: float
    eta: float
    H_at: dict


def paper_bound(model, nominal_params=None, *, param_box, reference_bounds, error_bounds, lam=None, c=None,
                eta: float = 10.0, beta_hat=None, n_grid: int = 41, seed: int = 0) -> PaperBound:
    """The paper's Lemma 1 gain evaluated on a box in TRUE coordinates (scalar models, e.g. link1).

    ``H = sup |alpha(x; p_nom) - alpha(x; p)|`` over ``x = T^{-1}(y; p)``, ``|y_k| <=
    R_{k-1} + E_k`` and the parameter box (grid over the nonlinear coordinates,
    vertices over the affine ones, then local maximization);
    ``beta_min/max`` over the same points; ``beta_hat = (beta_max + beta_min) / 2``
    unless given; ``rho = max |1 - beta / beta_hat|``; ``W = R_4 + c1 E2 + c2 E3 + c3 E4``.

    This gain guarantees reaching for the sliding variable in TRUE coordinates,
    ``c . (T(x; p) - y_d)``, which is not the one the controller computes: see
    :func:`synthesize_gains` for the implemented law.
    """
    if int(model.n) != 1:
        raise ValueError(f"paper_bound: model {model.name!r} has n = {model.n}; Lemma 1 is stated for one joint "
                         "(use synthesize_gains for chains)")
    p_nom = np.asarray(model.params_array(nominal_params or {}, arg="nominal_params"), dtype=float)
    box = _check_box(model, p_nom, param_box)
    cc = surface_coefficients(lam, c, False)
    R = _per_joint(reference_bounds, 5, 1, "reference_bounds")[:, 0]
    E = _per_joint(error_bounds, 4, 1, "error_bounds")[:, 0]
    W = float(R[4] + cc[0] * E[1] + cc[1] * E[2] + cc[2] * E[3])
    Ybox = (R[:4] + E)[:, None]
    fn = _build_true_fn(model, p_nom)
    ev = _Evaluator(model, fn)
    dims = _dims(model, Ybox, p_nom, box)
    rng = np.random.default_rng(seed)
    _classify(dims, lambda Y, P: ev(Y, P)[:, :1], 1, p_nom, rng)
    for d in dims:
        if not d.affine:
            d.points = n_grid
    axes = [d.values() for d in dims]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(dims))
    Y, P = _assemble(dims, pts, 1, p_nom)
    V = ev(Y, P)
    dA = np.abs(V[:, 0])
    free = [j for j, d in enumerate(dims) if not d.affine and d.lo < d.hi]
    best, best_pt = float(np.max(dA)), pts[int(np.argmax(dA))]
    if free:
        lo = np.array([dims[j].lo for j in free]); hi = np.array([dims[j].hi for j in free])
        for j0 in np.argsort(-dA)[:8]:
            base = pts[j0].copy()

            def obj(v, base=base, h=1e-7):
                vs = np.repeat(v[None, :], 2 * len(free) + 1, axis=0)
                for a in range(len(free)):
                    vs[1 + 2 * a, a] = min(v[a] + h, 1.0)
                    vs[2 + 2 * a, a] = max(v[a] - h, 0.0)
                pt = np.repeat(base[None, :], vs.shape[0], axis=0)
                pt[:, free] = lo + vs * (hi - lo)
                Yv, Pv = _assemble(dims, pt, 1, p_nom)
                val = np.abs(ev(Yv, Pv)[:, 0])
                grad = np.array([(val[1 + 2 * a] - val[2 + 2 * a]) / max(vs[1 + 2 * a, a] - vs[2 + 2 * a, a], 1e-300)
                                 for a in range(len(free))])
                return float(val[0]), grad

            vb = _box_maximize(obj, (base[free] - lo) / (hi - lo), maxiter=300, tol=1e-14)
            val, _ = obj(vb)
            if val > best:
                best = val
                best_pt = base.copy(); best_pt[free] = lo + vb * (hi - lo)
    beta = V[:, 1]
    b_min, b_max = float(np.min(beta)), float(np.max(beta))
    bh = 0.5 * (b_min + b_max) if beta_hat is None else float(beta_hat)
    rho = max(abs(1 - b_min / bh), abs(1 - b_max / bh))
    Yb, Pb = _assemble(dims, best_pt[None, :], 1, p_nom)
    at = {"y": Yb[0].tolist(), "params": {d.name: float(best_pt[j]) for j, d in enumerate(dims) if d.kind == "p"}}
    return PaperBound(k_s=rho * W + best / bh + eta, k_s_eq16=W + best / bh + eta, rho=rho, W=W, H=best,
                      beta_hat=bh, beta_min=b_min, beta_max=b_max, eta=float(eta), H_at=at)


# ---------------------------------------------------------------------------------------------
# adaptive stiffness law: frozen-estimate gains + the dropped K_hat' term
@dataclass
class AdaptiveTuneResult:
    """Gain for the adaptive-stiffness law (:mod:`fjm_runtime.adaptive`) and its reaching argument.

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


def _stiffness_names(model) -> List[str]:
    names = list(model.param_names)
    if "K" in names:
        return ["K"]
    return [f"K{i + 1}" for i in range(int(model.n)) if f"K{i + 1}" in names]


def synthesize_adaptive_gains(model, nominal_params=None, *, K_bounds, param_box=None, reference_bounds,
                              error_bounds, lam=None, c=None, integral: bool = True, n_estimates: int = 3,
                              eta=10.0, u_max=None, layer_rate: float = 200.0, budget: int = 60000,
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
    kn = _stiffness_names(model)
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
    R = _per_joint(reference_bounds, 5, n, "reference_bounds")
    E = _per_joint(error_bounds, 4, n, "error_bounds")
    Yb = (R[:4] + E).reshape(-1)
    x = ca.SX.sym("x", nx); y = ca.SX.sym("y", nx); p = ca.SX.sym("p", len(p_nom))
    C = ca.horzcat(*[float(c_last[k]) * ca.SX.eye(n) for k in range(3)], ca.SX.eye(n))
    dT = ca.jacobian(ca.mtimes(C, model.functions["T"](x, p)), p[idx])
    fn = ca.Function("dsdK", [x, y, p], [ca.reshape(dT, n * n, 1)])
    rng = np.random.default_rng(seed)
    G = np.zeros((n, n))
    for combo in product(*grids):
        ph = p_nom.copy(); ph[idx] = combo
        ev = _Evaluator(model, fn, p_inverse=ph)
        Y = rng.uniform(-1, 1, size=(n_samples, nx)) * Yb
        if nx <= 12:
            Y = np.vstack([Y, np.array(list(product(*[(-1.0, 1.0)] * nx))) * Yb])
        P = np.repeat(ph[None, :], Y.shape[0], axis=0)
        V = np.abs(ev(Y, P)).reshape(-1, n, n, order="F")
        G = np.maximum(G, V.max(axis=0))
    return G


# ---------------------------------------------------------------------------------------------
# CLI: ``fjm tune MODEL``
def _floats(text: str, count: int, flag: str) -> List[float]:
    try:
        vals = [float(v) for v in str(text).replace(",", " ").split()]
    except ValueError:
        raise ValueError(f"{flag} {text!r}: expected {count} numbers separated by commas") from None
    if len(vals) != count:
        raise ValueError(f"{flag} {text!r}: expected {count} numbers separated by commas, got {len(vals)}")
    return vals


def add_parser(sub) -> None:
    """Register ``tune`` on the ``fjm`` subparsers."""
    tp = sub.add_parser(
        "tune", help="synthesize per-joint switching gains with a reaching certificate (JSON)",
        description="Per-joint switching gains k_s for the sliding-mode law as it is run (nominal "
                    "coordinates), such that sgn(s_i) s_i' <= -eta on a box of tracking errors, reference "
                    "derivatives and true parameters; prints gains, boundary layer, the certificate (worst "
                    "sgn(s) s' found and where) and the reaching-time bound as JSON. A numerical certificate on "
                    "a grid (vertices along affine coordinates), not a proof; the box is assumed invariant. "
                    "Exit status 1 when no admissible gain exists (the JSON says why).")
    tp.add_argument("model", help="model name, e.g. link1, planar2")
    tp.add_argument("--controller", choices=("smc", "sign", "ismc"), default="smc",
                    help="law to certify: smc/sign = paper surface, ismc = integral surface (default smc)")
    tp.add_argument("--lam", type=float, default=8.0, help="pole magnitude lambda, 1/s (default 8)")
    tp.add_argument("--nominal", action="append", default=[], metavar="NAME=VALUE",
                    help="NOMINAL controller parameter (repeatable); default: model defaults")
    tp.add_argument("--k-range", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                    help="true stiffness of every joint, N m/rad (default: each joint's nominal stiffness "
                         "x [2/3, 4/3], i.e. 100 200 at 150)")
    tp.add_argument("--jm-range", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                    help="true motor inertia of every joint (default: nominal, exact)")
    tp.add_argument("--bm-range", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                    help="true motor damping of every joint (default: nominal, exact)")
    tp.add_argument("--mass-range", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                    help="true link (link1: tip) mass of every link, kg (default: nominal, exact)")
    tp.add_argument("--param-box", action="append", default=[], metavar="NAME=LO:HI",
                    help="interval of any true parameter (repeatable), e.g. --param-box K2=120:180")
    tp.add_argument("--reference", choices=("sine", "step"), default="sine",
                    help="reference whose derivative bounds R_0..R_4 define the box (default sine)")
    tp.add_argument("--amplitude", type=float, default=0.5, help="sine amplitude, rad (default 0.5)")
    tp.add_argument("--omega", type=float, default=1.0, help="sine frequency, rad/s (default 1)")
    tp.add_argument("--q-d", type=float, default=1.0, help="step target, rad (default 1)")
    tp.add_argument("--rise-time", type=float, default=2.0, help="step duration, s (default 2)")
    tp.add_argument("--reference-bounds", default=None, metavar="R0,R1,R2,R3,R4",
                    help="explicit bounds of |y_d^(k)|, k = 0..4 (overrides --reference)")
    tp.add_argument("--error-box", default=None, metavar="E1,E2,E3,E4",
                    help="bounds of |y_hat_k - y_dk| (default 0.05,0.5,0.5,0.5 for sine, 0.05,0.1,0.5,1 for step)")
    tp.add_argument("--beta-hat", choices=("paper", "model"), default="paper",
                    help="link1: the paper's constant (beta_max + beta_min)/2 over --k-range, or beta(x; nominal); "
                         "chains always use beta(x; nominal) (default paper)")
    tp.add_argument("--eta", type=float, default=10.0, help="reaching margin, rad/s^4 (default 10)")
    tp.add_argument("--u-max", type=float, default=None, help="actuator limit, N m (default none)")
    tp.add_argument("--layer-rate", type=float, default=200.0,
                    help="boundary layer delta = k_s / rate (default 200)")
    tp.add_argument("--budget", type=int, default=60000, help="approximate grid size (default 60000)")
    tp.add_argument("--disturbance-bound", type=float, default=0.0, metavar="D",
                    help="bound of a matched motor torque disturbance (Coulomb friction level + any bounded "
                         "torque), N m (default 0)")
    tp.add_argument("--no-margin", action="store_true",
                    help="do not make the grid's curvature margin part of the condition")


def run(args) -> int:
    """``fjm tune``: print the :class:`TuneResult` as JSON; exit status 1 when infeasible."""
    import json
    import sys
    from .. import load
    from ..control.references import Sinusoid, SmoothStep
    from ..analysis.lemma1 import LINK1_PARAMS, beta_bounds_link1
    m = load(args.model)
    n = int(m.n)
    nominal = {}
    for item in args.nominal:
        name, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--nominal {item!r}: expected NAME=VALUE, e.g. --nominal K=150")
        try:
            nominal[name.strip()] = float(value)
        except ValueError:
            raise ValueError(f"--nominal {item!r}: VALUE {value!r} is not a number") from None
    extra = {}
    for item in args.param_box:
        name, sep, rng = item.partition("=")
        lo, sep2, hi = rng.partition(":")
        if not sep or not sep2:
            raise ValueError(f"--param-box {item!r}: expected NAME=LO:HI, e.g. --param-box K2=120:180")
        try:
            extra[name.strip()] = (float(lo), float(hi))
        except ValueError:
            raise ValueError(f"--param-box {item!r}: LO and HI must be numbers") from None
    k_extra = {}
    if args.k_range is not None:
        lo, hi = args.k_range
        if not (0 < lo <= hi):
            raise ValueError(f"--k-range {lo} {hi}: expected 0 < LO <= HI (N m/rad)")
        k_range = (lo, hi)
    else:
        k_range = None
        p_nom = m.params_array(nominal, arg="--nominal")
        for name in _stiffness_names(m):
            k0 = float(p_nom[m.param_names.index(name)])
            k_extra[name] = (k0 * 2.0 / 3.0, k0 * 4.0 / 3.0)
    k_extra.update(extra)
    box = param_box_from_ranges(m, k_range=k_range, jm_range=args.jm_range, bm_range=args.bm_range,
                                mass_range=args.mass_range, extra=k_extra)
    if args.reference_bounds is not None:
        R = _floats(args.reference_bounds, 5, "--reference-bounds")
        ref_label = "explicit"
    elif args.reference == "sine":
        R = Sinusoid(args.amplitude, args.omega, n=n).derivative_bounds()
        ref_label = f"sine amplitude {args.amplitude:g} rad, omega {args.omega:g} rad/s"
    else:
        R = SmoothStep(args.q_d, n=n, rise_time=args.rise_time).derivative_bounds()
        ref_label = f"smooth step to {args.q_d:g} rad in {args.rise_time:g} s"
    if args.error_box is not None:
        E = _floats(args.error_box, 4, "--error-box")
    else:
        E = [0.05, 0.5, 0.5, 0.5] if args.reference == "sine" else [0.05, 0.1, 0.5, 1.0]
    beta_hat = None
    if args.beta_hat == "paper" and tuple(m.param_names) == LINK1_PARAMS:
        beta_hat = beta_bounds_link1(nominal, {k: v for k, v in box.items() if k in ("J_l", "J_m", "K")})[2]
    res = synthesize_gains(m, nominal, param_box=box, reference_bounds=R, error_bounds=E, lam=args.lam,
                           integral=(args.controller == "ismc"), beta_hat=beta_hat, eta=args.eta,
                           u_max=args.u_max, layer_rate=args.layer_rate, include_margin=not args.no_margin,
                           budget=args.budget, disturbance_bound=args.disturbance_bound)
    c = res.c
    Ea = np.asarray(res.settings["error_bounds"])
    s0 = (c[1:] @ Ea[:3] + Ea[3]) if c.size == 4 else (c @ Ea[:3] + Ea[3])   # sup |s| on the error box
    report = res.as_dict()
    report.update({"controller": args.controller, "lam": args.lam, "reference": ref_label,
                   "s0_max": np.asarray(s0).tolist(),
                   "reaching_time_bound": None if not res.feasible else res.reaching_time_bound(s0).tolist(),
                   "guarantee": "sgn(s_i) s_i' <= certificate_i <= -eta_i for every state whose nominal "
                                "coordinates, reference derivatives and true parameters lie in the box (numerical "
                                "certificate on the grid, vertices along affine coordinates); the box is assumed "
                                "invariant, not proven; reaching_time_bound = (|s(0)| - delta) / eta for "
                                "|s(0)| = s0_max while the state stays in the box"})
    print(json.dumps(report, indent=2))
    if not res.feasible:
        print(f"fjm tune: no admissible gain: {res.reason}", file=sys.stderr)
        return 1
    return 0
