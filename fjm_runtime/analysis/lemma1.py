"""Lemma 1 of the paper for link1: beta_hat from parameter bounds and the switching gain.

Derivation (true linearizing coordinates ``y = T(x; p)``, ``y4' = (u - alpha) / beta``)
------------------------------------------------------------------------------------
With ``u = alpha_hat + beta_hat nu`` and ``nu = w - k_s sgn(s)``,
``w = y4d' - (c1 e2 + c2 e3 + c3 e4)``::

    s' = (beta_hat/beta - 1) w + (alpha_hat - alpha)/beta - (beta_hat/beta) k_s sgn(s)
    s s' = (beta_hat/beta) [ (1 - beta/beta_hat) w s + (alpha_hat - alpha)/beta_hat s - k_s |s| ]

so ``s s' <= -(beta_hat/beta) eta |s|`` whenever::

    k_s >= rho |w| + h / beta_hat + eta,   rho = max |1 - beta/beta_hat| < 1,   h >= |alpha_hat - alpha|.

The paper's eq (16) drops ``rho`` (uses 1, which is sufficient because eq (14)
gives ``rho < 1``); its proof also writes ``(alpha_hat - alpha)/beta`` inside
the last bracket where ``(alpha_hat - alpha)/beta_hat`` is correct, and claims
``<= -eta |s|`` where ``-(beta_hat/beta) eta |s|`` is what follows (we report
the reaching-time bound with that factor).

Which reading is implemented
----------------------------
Eq (16) has a state-dependent right-hand side (``w`` depends on the errors and
``h(y)`` on the state). We implement the CONSTANT gain that satisfies (16) on a
stated compact operating region: ``|y_i - y_id| <= E_i`` (``error_bounds``) and
the reference bounds ``|y_d^(k)| <= R_k``, so that::

    W = R_4 + c1 E_2 + c2 E_3 + c3 E_4                      >= |w|
    H = sup over |y1| <= R_0 + E_1, |y2| <= R_1 + E_2, |y3| <= R_2 + E_3,
        |y4| <= R_3 + E_4 and over the parameter box of |alpha(x; p_nom) - alpha(x; p)|,
        with x = T^{-1}(y; p)                               >= h(y)
    k_s (paper, eq 16)   = W + H / beta_hat + eta
    k_s_tight            = rho W + H / beta_hat + eta

``beta = J_l J_m / K`` (corrected, docs/errata.md erratum 2), so with ``K in [K_min, K_max]``
(and optionally ``J_l, J_m`` intervals) ``beta_min = J_l,min J_m,min / K_max``,
``beta_max = J_l,max J_m,max / K_min`` and ``beta_hat = (beta_max + beta_min) / 2``
(the paper's choice, which makes eq (14) hold with ``rho = (beta_max - beta_min)
/ (beta_max + beta_min)``).

Lemma 1 is stated in the TRUE coordinates. The implemented controller forms
``e`` from ``T(x; p_nom)``; with a wrong stiffness that adds a drift to ``s'``
that the input cannot cancel (through ``c2 = 3 lambda^2`` and ``c3``; also the
regulation offset analysed in :func:`predict_regulation_offset`). The gain of
this module does NOT include it and is therefore not a reaching guarantee for
the law that runs (on link1 it fails from lambda ~ 20):
:func:`fjm_runtime.tune.synthesize_gains` (``fjm tune``) certifies gains for the
implemented law, and :func:`fjm_runtime.tune.paper_bound` evaluates this
module's bound for any scalar model.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import product

import numpy as np

LINK1_PARAMS = ("J_l", "J_m", "K", "M", "g0", "L", "B_m")
LINK1_DEFAULTS = dict(J_l=1.0, J_m=2.0, K=150.0, M=1.0, g0=9.8, L=1.0, B_m=0.0)


def _link1_params(p) -> dict:
    if isinstance(p, dict):
        unknown = sorted(set(p) - set(LINK1_PARAMS))
        if unknown:
            raise ValueError(f"params: unknown names {unknown}; expected a subset of {LINK1_PARAMS}")
        d = dict(LINK1_DEFAULTS)
        d.update({k: float(v) for k, v in p.items()})
    else:
        a = np.asarray(p, dtype=float).ravel()
        if a.shape != (len(LINK1_PARAMS),):
            raise ValueError(f"params with shape {a.shape}: expected ({len(LINK1_PARAMS)},) in order {LINK1_PARAMS}")
        d = dict(zip(LINK1_PARAMS, a.tolist()))
    for k in ("J_l", "J_m", "K"):
        if not (np.isfinite(d[k]) and d[k] > 0):
            raise ValueError(f"{k} = {d[k]!r}: expected a finite value > 0")
    return d


def link1_T_inverse(y, p):
    """Closed-form ``x = T^{-1}(y; p)`` for link1 (broadcasts over leading axes).

    Parameters
    ----------
    y : array_like, shape (..., 4)
    p : dict or array_like

    Returns
    -------
    ndarray, shape (..., 4)
    """
    d = _link1_params(p)
    y = np.asarray(y, dtype=float)
    g = d["M"] * d["g0"] * d["L"] / d["J_l"]
    y1, y2, y3, y4 = np.moveaxis(y, -1, 0)
    c = d["J_l"] / d["K"]
    x3 = y1 + c * (y3 + g * np.sin(y1))
    x4 = y2 + c * (y4 + g * np.cos(y1) * y2)
    return np.stack([y1, y2, x3, x4], axis=-1)


def link1_alpha(x, p):
    """Closed-form ``alpha(x; p) = -beta a`` for link1, shape ``x.shape[:-1]``.

    ``a = L_f y4``, ``beta = J_l J_m / K``; includes motor damping ``B_m``.
    """
    d = _link1_params(p)
    x = np.asarray(x, dtype=float)
    x1, x2, x3, x4 = np.moveaxis(x, -1, 0)
    Jl, Jm, K = d["J_l"], d["J_m"], d["K"]
    g = d["M"] * d["g0"] * d["L"] / Jl
    f2 = -g * np.sin(x1) - K / Jl * (x1 - x3)
    f4 = (K * (x1 - x3) - d["B_m"] * x4) / Jm
    a = g * np.sin(x1) * x2 ** 2 - g * np.cos(x1) * f2 - K / Jl * (f2 - f4)
    return -(Jl * Jm / K) * a


def _bounds_dict(nominal: dict, bounds) -> dict:
    out = {}
    for k, v in (bounds or {}).items():
        if k not in LINK1_PARAMS:
            raise ValueError(f"bounds: unknown parameter {k!r}; expected one of {LINK1_PARAMS}")
        lo, hi = (float(b) for b in v)
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            raise ValueError(f"bounds[{k!r}] = {v!r}: expected finite (lo, hi) with lo <= hi")
        if k in ("J_l", "J_m", "K") and lo <= 0:
            raise ValueError(f"bounds[{k!r}] = {v!r}: expected lo > 0")
        out[k] = (lo, hi)
    for k in LINK1_PARAMS:
        out.setdefault(k, (nominal[k], nominal[k]))
    return out


def beta_bounds_link1(nominal=None, bounds=None):
    """``beta_min, beta_max, beta_hat, rho`` for link1 from parameter bounds.

    Parameters
    ----------
    nominal : dict, optional
        Nominal parameters (defaults for missing names).
    bounds : dict name -> (lo, hi), optional
        Intervals of the uncertain parameters, e.g. ``{"K": (100, 200)}``.

    Returns
    -------
    beta_min, beta_max, beta_hat, rho : float
        ``beta = J_l J_m / K`` ranges over ``[beta_min, beta_max]``;
        ``beta_hat = (beta_max + beta_min) / 2`` and
        ``rho = max |1 - beta / beta_hat| = (beta_max - beta_min) / (beta_max + beta_min)``.
    """
    nom = _link1_params(nominal or {})
    b = _bounds_dict(nom, bounds)
    beta_min = b["J_l"][0] * b["J_m"][0] / b["K"][1]
    beta_max = b["J_l"][1] * b["J_m"][1] / b["K"][0]
    beta_hat = 0.5 * (beta_max + beta_min)
    rho = (beta_max - beta_min) / (beta_max + beta_min)
    return beta_min, beta_max, beta_hat, rho


def beta_hat_link1(nominal=None, bounds=None) -> float:
    """The paper's ``beta_hat = (beta_max + beta_min) / 2`` (see :func:`beta_bounds_link1`)."""
    return beta_bounds_link1(nominal, bounds)[2]


def alpha_mismatch_bound(y_box, nominal=None, bounds=None, n_grid: int = 41, n_param: int = 5) -> float:
    """``H = sup |alpha(x; p_nom) - alpha(x; p)|`` over a y-box and the parameter box (link1).

    ``x = T^{-1}(y; p)`` is the state the TRUE plant is in when its
    linearizing coordinates are ``y``; ``alpha_hat`` is evaluated at that state
    with the nominal parameters, as the controller does.

    Parameters
    ----------
    y_box : array_like, shape (4,)
        Half-widths ``Y_i`` of the box ``|y_i| <= Y_i``.
    nominal : dict
    bounds : dict name -> (lo, hi)
    n_grid : int
        Grid points along ``y1`` (``y2..y4`` use 9/5/5 points including the vertices).
    n_param : int
        Grid points along each uncertain parameter (endpoints included).

    Notes
    -----
    A grid supremum. For ``K``-only uncertainty and ``B_m = 0`` it is exact up
    to the ``y1`` grid: ``alpha_hat - alpha`` is then affine in ``1/K`` and in
    ``(y2^2, y3)`` for fixed ``y1``, so the vertices carry the supremum.
    """
    Y = np.asarray(y_box, dtype=float)
    if Y.shape != (4,) or not np.all(np.isfinite(Y)) or np.any(Y < 0):
        raise ValueError(f"y_box = {Y.tolist()}: expected 4 finite half-widths >= 0")
    nom = _link1_params(nominal or {})
    b = _bounds_dict(nom, bounds)
    axes = [np.linspace(-Y[0], Y[0], n_grid), np.linspace(-Y[1], Y[1], 9),
            np.linspace(-Y[2], Y[2], 5), np.linspace(-Y[3], Y[3], 5)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 4)
    uncertain = [k for k in LINK1_PARAMS if b[k][0] != b[k][1]]
    values = [np.linspace(b[k][0], b[k][1], n_param) for k in uncertain]
    H = 0.0
    for combo in product(*values) if uncertain else [()]:
        p = dict(nom)
        p.update(dict(zip(uncertain, combo)))
        x = link1_T_inverse(grid, p)
        H = max(H, float(np.max(np.abs(link1_alpha(x, nom) - link1_alpha(x, p)))))
    return H


@dataclass
class Lemma1Gain:
    """Result of :func:`lemma1_gain` (see the module docstring for the formulas).

    Attributes
    ----------
    k_s : float
        Paper eq (16) reading: ``W + H / beta_hat + eta`` (rad/s^4).
    k_s_tight : float
        ``rho W + H / beta_hat + eta``.
    W, H, beta_hat, beta_min, beta_max, rho, eta : float
    y_box : ndarray, shape (4,)
        Operating region used for ``H``.
    """

    k_s: float
    k_s_tight: float
    W: float
    H: float
    beta_hat: float
    beta_min: float
    beta_max: float
    rho: float
    eta: float
    y_box: np.ndarray

    def reaching_time_bound(self, s0: float, delta: float = 0.0) -> float:
        """Upper bound on the time for ``|s|`` to fall from ``|s0|`` to ``delta`` (s).

        From ``s s' <= -(beta_hat / beta) eta |s| <= -(beta_hat / beta_max) eta |s|``.
        """
        return max(abs(s0) - delta, 0.0) * self.beta_max / (self.beta_hat * self.eta)


def lemma1_gain(c, reference_bounds, *, nominal=None, bounds=None, error_bounds=(0.0, 0.0, 0.0, 0.0),
                eta: float = 10.0, n_grid: int = 41) -> Lemma1Gain:
    """Smallest constant switching gain that Lemma 1 (eq 16) guarantees on a region (link1).

    Parameters
    ----------
    c : array_like, shape (3,)
        ``[c1, c2, c3]`` (all > 0).
    reference_bounds : array_like, shape (5,)
        ``R_k >= sup |y_d^(k)|`` for ``k = 0..4`` (``Reference.derivative_bounds()[:, 0]``).
    nominal : dict, optional
        Nominal parameters used by the controller (``alpha_hat``).
    bounds : dict name -> (lo, hi), optional
        Parameter intervals, e.g. ``{"K": (100, 200)}``.
    error_bounds : array_like, shape (4,)
        ``E_i >= |y_i - y_id|`` on the region where sliding must be guaranteed
        (zeros: on the sliding surface itself; enlarge to cover the reaching phase).
    eta : float
        Reaching margin ``> 0`` (rad/s^4).

    Returns
    -------
    Lemma1Gain
    """
    c = np.asarray(c, dtype=float).ravel()
    if c.shape != (3,) or not np.all(np.isfinite(c)) or np.any(c <= 0):
        raise ValueError(f"c = {c.tolist()}: expected 3 finite values > 0 ([c1, c2, c3])")
    R = np.asarray(reference_bounds, dtype=float).ravel()
    if R.shape != (5,) or not np.all(np.isfinite(R)) or np.any(R < 0):
        raise ValueError(f"reference_bounds = {R.tolist()}: expected 5 finite values >= 0")
    E = np.asarray(error_bounds, dtype=float).ravel()
    if E.shape != (4,) or not np.all(np.isfinite(E)) or np.any(E < 0):
        raise ValueError(f"error_bounds = {E.tolist()}: expected 4 finite values >= 0")
    if not (np.isfinite(eta) and eta > 0):
        raise ValueError(f"eta = {eta!r}: expected a finite value > 0")
    nom = _link1_params(nominal or {})
    beta_min, beta_max, beta_hat, rho = beta_bounds_link1(nom, bounds)
    W = R[4] + c[0] * E[1] + c[1] * E[2] + c[2] * E[3]
    y_box = R[:4] + E
    H = alpha_mismatch_bound(y_box, nom, bounds, n_grid=n_grid)
    return Lemma1Gain(k_s=W + H / beta_hat + eta, k_s_tight=rho * W + H / beta_hat + eta, W=W, H=H,
                      beta_hat=beta_hat, beta_min=beta_min, beta_max=beta_max, rho=rho, eta=float(eta),
                      y_box=y_box)


@dataclass
class OffsetPrediction:
    """Predicted steady state of a set-point regulation (link1).

    Attributes
    ----------
    q_ss : float
        Link angle at which the closed loop comes to rest (rad).
    offset : float
        ``q_ss - q_d`` (rad), exact for the controller's law (includes the boundary-layer term).
    first_order : float
        ``-(c3 / c1) (K_nom / K - 1) M g0 L sin(q_d) / J_l``: the sliding-surface
        term alone (``= -(3 / lambda^2) (...)`` for a triple pole), i.e. the
        offset when ``s = 0``; the rest, ``offset - first_order``, is the
        ``O(delta / k_s)`` boundary-layer term plus the ``sin(q_ss)`` vs
        ``sin(q_d)`` difference.
    s_ss : float
        Sliding variable at rest.
    """

    q_ss: float
    offset: float
    first_order: float
    s_ss: float


def link1_equilibrium(q: float, p) -> np.ndarray:
    """Rest state of link1 holding the link at ``q``: ``[q, 0, q + M g0 L sin(q) / K, 0]``."""
    d = _link1_params(p)
    return np.array([q, 0.0, q + d["M"] * d["g0"] * d["L"] * np.sin(q) / d["K"], 0.0])


def predict_regulation_offset(model, controller, q_d: float, true_params, search: float = 1.5,
                              n_scan: int = 301) -> OffsetPrediction:
    """Steady-state regulation error of a non-integral controller on link1 with wrong parameters.

    At rest at link angle ``q`` the plant needs the holding torque
    ``u_eq = M g0 L sin(q)`` and sits at ``x(q) = [q, 0, q + M g0 L sin(q) / K, 0]``.
    The controller (nominal ``T_hat``) sees ``e3 = T3(x(q); p_nom) = (K_nom / K - 1)
    M g0 L sin(q) / J_l`` (when ``J_l``, ``M``, ``L`` are right) instead of 0, so
    the rest point solves ``u_controller(x(q)) = u_eq(q)``. We solve that scalar
    equation (scan over ``q_d +- search`` then bisection; the root nearest
    ``q_d`` is returned). Inside the boundary layer the solution is
    ``c1 e1 + c3 e3 = s_ss`` with ``s_ss = O(delta / k_s)``, i.e. ``e1 ~ -(c3/c1) e3``.

    Parameters
    ----------
    model : Model
        ``fjm_runtime.load("link1")``.
    controller : SlidingModeController
        A non-integral controller (``'sat'`` or ``'fl'``).
    q_d : float
        Constant set point (rad).
    true_params : dict or array_like
        Plant parameters.

    Returns
    -------
    OffsetPrediction
    """
    if getattr(controller, "integral", False):
        raise ValueError("controller: the integral controller has no offset (z' = e1 forces e1 -> 0)")
    if getattr(controller, "mode", "sat") == "sign":
        raise ValueError("controller.mode = 'sign': no rest point (chatters); use 'sat' or 'fl'")
    if not np.isfinite(q_d):
        raise ValueError(f"q_d = {q_d!r}: expected a finite angle (rad)")
    p_true = _link1_params(dict(zip(model.param_names, np.asarray(model.params_array(true_params)).tolist())))
    p_nom = _link1_params(dict(zip(model.param_names, np.asarray(controller.p_nom).tolist())))
    r = np.zeros((5, 1)); r[0, 0] = q_d
    mgl = p_true["M"] * p_true["g0"] * p_true["L"]
    z = np.zeros(0)

    def residual(q):
        x = link1_equilibrium(q, p_true)
        return float(controller.evaluate(0.0, x, z, r).u_cmd[0] - mgl * np.sin(q))

    qs = q_d + np.linspace(-search, search, n_scan)
    F = np.array([residual(q) for q in qs])
    idx = np.flatnonzero(np.sign(F[:-1]) * np.sign(F[1:]) <= 0)
    if idx.size == 0:
        raise ValueError(f"no rest point within q_d +- {search} rad for these parameters")
    i = idx[np.argmin(np.abs(qs[idx] - q_d))]
    lo, hi, flo = qs[i], qs[i + 1], F[i]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        fm = residual(mid)
        if np.sign(fm) == np.sign(flo):
            lo, flo = mid, fm
        else:
            hi = mid
    q_ss = 0.5 * (lo + hi)
    x_ss = link1_equilibrium(q_ss, p_true)
    s_ss = float(controller.evaluate(0.0, x_ss, z, r).s[0])
    c1, c3 = controller.c[0], controller.c[2]
    first = -(c3 / c1) * (p_nom["K"] / p_true["K"] - 1.0) * mgl * np.sin(q_d) / p_true["J_l"]
    return OffsetPrediction(q_ss=float(q_ss), offset=float(q_ss - q_d), first_order=float(first), s_ss=s_ss)


def closed_loop_eigenvalues(model, controller, true_params, x_eq=None, r=None, h: float = 1e-6) -> np.ndarray:
    """Eigenvalues of the continuous-time closed loop linearized at a rest point.

    The loop is ``x' = f(x; p_true) + g(x; p_true) u(x)`` with ``u`` the
    controller's law (nominal parameters, no sampling), differentiated by
    central differences. Only for controllers without internal state.

    Parameters
    ----------
    model : Model
    controller : SlidingModeController
        Non-integral controller.
    true_params : dict or array_like
    x_eq : array_like, shape (4n,), optional
        Rest point (default 0: planar chains hanging straight down, link1 at q = 0).
    r : array_like, shape (5, n), optional
        Reference held at ``x_eq`` (default: ``q_d = q_l`` of ``x_eq``, derivatives 0).
    h : float
        Difference step.

    Returns
    -------
    ndarray, shape (4n,), complex
        Sorted by decreasing real part (the first one decides stability).
    """
    if getattr(controller, "integral", False):
        raise ValueError("controller: integral controllers carry a state; linearize the augmented loop instead")
    n, nx = int(model.n), int(model.nx)
    x_eq = np.zeros(nx) if x_eq is None else np.asarray(x_eq, dtype=float)
    if x_eq.shape != (nx,):
        raise ValueError(f"x_eq with shape {x_eq.shape}: expected ({nx},)")
    if r is None:
        r = np.zeros((5, n))
        r[0] = x_eq[:n]
    p = model.params_array(true_params)
    z = np.zeros(0)

    def field(x):
        u = controller.evaluate(0.0, x, z, r).u
        return model.f(x, p) + model.g(x, p) @ u

    J = np.empty((nx, nx))
    for i in range(nx):
        dx = np.zeros(nx)
        dx[i] = h
        J[:, i] = (field(x_eq + dx) - field(x_eq - dx)) / (2 * h)
    ev = np.linalg.eigvals(J)
    return ev[np.argsort(-ev.real)]


# ---------------------------------------------------------------------------------------------
# defaults of the command line (policy lives here, the CLI only calls it)
FALLBACK_SWITCHING_GAIN = 1000.0
"""Switching gain (rad/s^4) used where the paper's bound does not apply (chains, spatial arms)."""


def paper_bound_applies(model) -> bool:
    """True when the closed-form Lemma 1 helpers of this module apply to ``model``.

    They are written for the paper's single link (eq 1): a model qualifies when it
    has one joint and exactly the parameters of the generated ``link1`` model
    (same names, same order).

    Parameters
    ----------
    model : Model

    Returns
    -------
    bool
    """
    from ..model import load
    return int(model.n) == 1 and tuple(model.param_names) == tuple(load("link1").param_names)


def default_error_bounds(reference: str, amplitude: float = 0.5, omega: float = 1.0) -> tuple:
    """Error region ``E`` (shape (4,)) on which the default Lemma 1 gain is stated.

    Parameters
    ----------
    reference : str
        Reference kind (``'sine'``, ``'step'``, ``'constant'``).
    amplitude, omega : float
        Sine amplitude (rad) and frequency (rad/s); ``E_2 = amplitude omega`` for a sine.

    Returns
    -------
    tuple of 4 float
        ``(0.05, amplitude omega, 0.5, 0.5)`` for a sine, ``(0.05, 0.1, 0.5, 1.0)`` otherwise.
    """
    if reference == "sine":
        return (0.05, amplitude * omega, 0.5, 0.5)
    return (0.05, 0.1, 0.5, 1.0)


def _check_k_bounds(k_bounds) -> tuple:
    lo, hi = (float(v) for v in k_bounds)
    if not (0 < lo <= hi):
        raise ValueError(f"k_bounds = {lo}/{hi}: expected 0 < k_min <= k_max (N m/rad)")
    return lo, hi


def paper_beta_hat(model, nominal_params=None, k_bounds=(100.0, 200.0)):
    """The paper's constant ``beta_hat = (beta_max + beta_min) / 2`` over ``K in k_bounds``, or None.

    Parameters
    ----------
    model : Model
    nominal_params : dict, optional
        Nominal parameters (defaults for missing names).
    k_bounds : (float, float)
        ``(K_min, K_max)``, N m/rad, ``0 < K_min <= K_max``.

    Returns
    -------
    float or None
        None when :func:`paper_bound_applies` is false for ``model``.
    """
    if not paper_bound_applies(model):
        return None
    return beta_bounds_link1(nominal_params, {"K": _check_k_bounds(k_bounds)})[2]


def default_switching_gain(model, nominal_params, lam: float, reference_bounds, *, k_bounds=(100.0, 200.0),
                           error_bounds=(0.05, 0.5, 0.5, 0.5), eta: float = 10.0):
    """The Lemma 1 gain ``fjm simulate`` uses by default, or None where the paper's bound does not apply.

    Parameters
    ----------
    model : Model
    nominal_params : dict, optional
        Nominal parameters of the controller.
    lam : float
        Pole magnitude (1/s); ``c`` from :func:`fjm_runtime.control.laws.coefficients_from_pole`.
    reference_bounds : array_like, shape (5,) or (5, 1)
        ``R_k >= sup |y_d^(k)|``, k = 0..4 (``Reference.derivative_bounds()``).
    k_bounds : (float, float)
        Stiffness interval ``(K_min, K_max)``, N m/rad.
    error_bounds : array_like, shape (4,)
        Error region (:func:`default_error_bounds`).
    eta : float
        Reaching margin (rad/s^4).

    Returns
    -------
    Lemma1Gain or None
        None when :func:`paper_bound_applies` is false (use :data:`FALLBACK_SWITCHING_GAIN`).
    """
    if not paper_bound_applies(model):
        return None
    from ..control.laws import coefficients_from_pole
    R = np.asarray(reference_bounds, dtype=float).reshape(5, -1)[:, 0]
    return lemma1_gain(coefficients_from_pole(lam), R, nominal=nominal_params,
                       bounds={"K": tuple(float(v) for v in k_bounds)}, error_bounds=error_bounds, eta=eta)
