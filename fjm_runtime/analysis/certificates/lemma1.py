"""Lemma 1 of the paper: beta_hat from parameter bounds and the switching gain (one implementation).

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

``beta = J_l J_m / K`` (corrected, erratum 2 of the paper), so with ``K in [K_min, K_max]``
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
:func:`fjm_runtime.analysis.certificates.certify.synthesize_gains` (``fjm tune``) certifies
gains for the implemented law.

One evaluation, two entry points
--------------------------------
:func:`lemma1_on_box` is the one place Lemma 1 is evaluated: ``W`` (:func:`surface_W`), ``H`` and
the range of ``beta``
(:func:`~fjm_runtime.analysis.certificates.mismatch.mismatch_supremum`: ``alpha``, ``beta`` and
``T^{-1}`` of the generated model, vertices along the coordinates where the mismatch is affine, a
grid along the others), then eq (16) (:func:`lemma1_terms`). :func:`paper_bound` calls it for any one-joint
model with a fine grid and local maximization; :func:`lemma1_gain` for link1
(:mod:`fjm_runtime.analysis.certificates.link1`) on the fixed grid of :func:`alpha_mismatch_bound`, no
refinement (the numbers of the figures and of ``fjm simulate``). Both return a :class:`Lemma1Gain`:
``k_s`` is always the paper's eq (16), ``k_s_tight`` the value with ``rho``.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import product
from typing import Optional

import numpy as np

from ...control.defaults import DEFAULT_SWITCHING_GAIN, PAPER_K_RANGE
from .box import check_box, per_joint, surface_coefficients
from .link1 import POSITIVE, link1_bounds, link1_model, link1_params
from .mismatch import mismatch_supremum


# ---------------------------------------------------------------------------------------------
# the shared core
def surface_W(c, R, E) -> float:
    """``W = R_4 + c1 E_2 + c2 E_3 + c3 E_4 >= |w|`` for ``c`` (3,), ``R`` (5,), ``E`` (4,)."""
    return float(R[4] + c[0] * E[1] + c[1] * E[2] + c[2] * E[3])


def lemma1_terms(W: float, H: float, beta_min: float, beta_max: float, beta_hat: float, eta: float):
    """Lemma 1 gains from its ingredients.

    Returns
    -------
    k_s : float
        ``W + H / beta_hat + eta`` (the paper's eq 16).
    k_s_tight : float
        ``rho W + H / beta_hat + eta``.
    rho : float
        ``max |1 - beta / beta_hat|`` over ``[beta_min, beta_max]``.
    """
    rho = max(abs(1 - beta_min / beta_hat), abs(1 - beta_max / beta_hat))
    return W + H / beta_hat + eta, rho * W + H / beta_hat + eta, rho


# ---------------------------------------------------------------------------------------------
# link1: beta bounds and the mismatch on a fixed grid
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

    Notes
    -----
    ``beta`` is the generated model's, at the vertices of the ``(J_l, J_m, K)`` box:
    for link1 it does not depend on the state and is monotone in each of them.
    """
    m = link1_model()
    nom = link1_params(nominal or {})
    b = link1_bounds(nom, bounds)
    betas = []
    for combo in product(*[b[k] for k in POSITIVE]):
        p = dict(nom)
        p.update(dict(zip(POSITIVE, combo)))
        betas.append(float(m.beta(np.zeros(4), p)[0, 0]))
    beta_min, beta_max = min(betas), max(betas)
    beta_hat = 0.5 * (beta_max + beta_min)
    rho = lemma1_terms(0.0, 0.0, beta_min, beta_max, beta_hat, 0.0)[2]
    return beta_min, beta_max, beta_hat, rho


def beta_hat_link1(nominal=None, bounds=None) -> float:
    """The paper's ``beta_hat = (beta_max + beta_min) / 2`` (see :func:`beta_bounds_link1`)."""
    return beta_bounds_link1(nominal, bounds)[2]


def _link1_grid(n_grid: int, n_param: int, endpoints_only: bool):
    """Grid points per box coordinate of the link1 reading: ``y1`` n_grid, ``y2..y4`` 9/5/5, parameters n_param."""
    y_points = (n_grid, 9, 5, 5)
    return lambda dim: y_points[dim.index] if dim.kind == "y" else (2 if endpoints_only else n_param)


def _link1_box(nominal, bounds, n_grid: int, n_param: int, endpoints_only: Optional[bool]):
    """``(model, p_nom (npar,), box, points)`` of the link1 reading (see :func:`alpha_mismatch_bound`)."""
    m = link1_model()
    names = list(m.param_names)
    nom = link1_params(nominal or {})
    box = {k: v for k, v in link1_bounds(nom, bounds).items() if v[0] != v[1]}
    # K-only uncertainty with B_m = 0: the mismatch is affine in 1/K at each y (alpha_mismatch_bound's Notes),
    # so its modulus peaks at an end of the interval and the interior K points cannot raise the supremum.
    if endpoints_only is None:
        endpoints_only = list(box) == ["K"] and nom.get("B_m", 0.0) == 0.0
    return m, np.array([nom[k] for k in names]), box, _link1_grid(n_grid, n_param, endpoints_only)


def alpha_mismatch_bound(y_box, nominal=None, bounds=None, n_grid: int = 41, n_param: int = 5,
                         endpoints_only: Optional[bool] = None) -> float:
    """``H = sup |alpha(x; p_nom) - alpha(x; p)|`` over a y-box and the parameter box (link1).

    ``x = T^{-1}(y; p)``; the grid supremum of
    :func:`~fjm_runtime.analysis.certificates.mismatch.mismatch_supremum`.

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
    endpoints_only : bool, optional
        Evaluate only the ends of the parameter interval. Default: when ``K`` is the only uncertain
        parameter and ``B_m = 0`` (exact then, see Notes; the interior points cannot raise ``H``).

    Notes
    -----
    A grid supremum. For ``K``-only uncertainty and ``B_m = 0`` it is exact up
    to the ``y1`` grid: ``alpha_hat - alpha`` is then affine in ``1/K`` and in
    ``(y2^2, y3)`` for fixed ``y1``, so the vertices carry the supremum.
    """
    Y = np.asarray(y_box, dtype=float)
    if Y.shape != (4,) or not np.all(np.isfinite(Y)) or np.any(Y < 0):
        raise ValueError(f"y_box = {Y.tolist()}: expected 4 finite half-widths >= 0")
    m, p_nom, box, points = _link1_box(nominal, bounds, n_grid, n_param, endpoints_only)
    return mismatch_supremum(m, p_nom, box, Y[:, None], points).H


@dataclass
class Lemma1Gain:
    """Lemma 1 on a region (:func:`lemma1_gain`, :func:`paper_bound`; the module docstring has the formulas).

    Attributes
    ----------
    k_s : float
        The paper's eq (16): ``W + H / beta_hat + eta`` (rad/s^4).
    k_s_tight : float
        Eq (16) with ``rho``: ``rho W + H / beta_hat + eta`` (rad/s^4).
    W, H, beta_hat, beta_min, beta_max, rho, eta : float
    y_box : ndarray, shape (4,)
        Operating region used for ``H``.
    H_at : dict
        Where ``|alpha_hat - alpha|`` is largest (``y`` and the parameters).
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
    H_at: dict

    def reaching_time_bound(self, s0: float, delta: float = 0.0) -> float:
        """Upper bound on the time for ``|s|`` to fall from ``|s0|`` to ``delta`` (s).

        From ``s s' <= -(beta_hat / beta) eta |s| <= -(beta_hat / beta_max) eta |s|``.
        """
        return max(abs(s0) - delta, 0.0) * self.beta_max / (self.beta_hat * self.eta)


def lemma1_on_box(model, p_nom, box, c, R, E, eta: float, points, *, beta_hat=None, refine: bool = False,
                  seed: int = 0) -> Lemma1Gain:
    """The one evaluation of Lemma 1: ``W``, ``H`` and the ``beta`` range on a region, then eq (16).

    Parameters
    ----------
    model : Model
        One joint.
    p_nom : ndarray, shape (npar,)
    box : dict name -> (lo, hi)
        Validated parameter intervals with ``lo < hi``.
    c : array_like, shape (3,)
    R : ndarray, shape (5,)
        Reference derivative bounds.
    E : ndarray, shape (4,)
        Error region.
    eta : float
        Reaching margin (rad/s^4).
    points, refine, seed
        As :func:`~fjm_runtime.analysis.certificates.mismatch.mismatch_supremum`.
    beta_hat : float, optional
        Default ``(beta_max + beta_min) / 2``.

    Returns
    -------
    Lemma1Gain
    """
    W = surface_W(c, R, E)
    y_box = R[:4] + E
    mm = mismatch_supremum(model, p_nom, box, y_box[:, None], points, refine=refine, seed=seed)
    bh = 0.5 * (mm.beta_min + mm.beta_max) if beta_hat is None else float(beta_hat)
    k_s, k_s_tight, rho = lemma1_terms(W, mm.H, mm.beta_min, mm.beta_max, bh, eta)
    return Lemma1Gain(k_s=k_s, k_s_tight=k_s_tight, W=W, H=mm.H, beta_hat=bh, beta_min=mm.beta_min,
                      beta_max=mm.beta_max, rho=rho, eta=float(eta), y_box=y_box, H_at=mm.H_at)


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
    n_grid : int
        Grid points along ``y1`` (the grid of :func:`alpha_mismatch_bound`, no local maximization).

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
    m, p_nom, box, points = _link1_box(nominal, bounds, n_grid, 5, None)
    return lemma1_on_box(m, p_nom, box, c, R, E, eta, points)


# ---------------------------------------------------------------------------------------------
# any one-joint model: the bound on a box with vertices along affine coordinates, refined
def paper_bound(model, nominal_params=None, *, param_box, reference_bounds, error_bounds, lam=None, c=None,
                eta: float = 10.0, beta_hat=None, n_grid: int = 41, seed: int = 0) -> Lemma1Gain:
    """The paper's Lemma 1 gain evaluated on a box in TRUE coordinates (scalar models, e.g. link1).

    ``H = sup |alpha(x; p_nom) - alpha(x; p)|`` over ``x = T^{-1}(y; p)``, ``|y_k| <=
    R_{k-1} + E_k`` and the parameter box (grid of ``n_grid`` points over the nonlinear
    coordinates, vertices over the affine ones, then local maximization);
    ``beta_min/max`` over the same points; ``beta_hat = (beta_max + beta_min) / 2``
    unless given; ``rho = max |1 - beta / beta_hat|``; ``W = R_4 + c1 E2 + c2 E3 + c3 E4``.
    The result's ``k_s_tight`` is eq (16) with ``rho``, ``k_s`` the paper's eq (16).

    This gain guarantees reaching for the sliding variable in TRUE coordinates,
    ``c . (T(x; p) - y_d)``, which is not the one the controller computes: see
    :func:`synthesize_gains` for the implemented law.
    """
    if int(model.n) != 1:
        raise ValueError(f"paper_bound: model {model.name!r} has n = {model.n}; Lemma 1 is stated for one joint "
                         "(use synthesize_gains for chains)")
    p_nom = np.asarray(model.params_array(nominal_params or {}, arg="nominal_params"), dtype=float)
    box = check_box(model, p_nom, param_box)
    cc = surface_coefficients(lam, c, False)
    R = per_joint(reference_bounds, 5, 1, "reference_bounds")[:, 0]
    E = per_joint(error_bounds, 4, 1, "error_bounds")[:, 0]
    return lemma1_on_box(model, p_nom, box, cc, R, E, eta, lambda dim: n_grid, beta_hat=beta_hat, refine=True,
                         seed=seed)


# ---------------------------------------------------------------------------------------------
# defaults of the command line (policy lives here, the CLI only calls it)
FALLBACK_SWITCHING_GAIN = DEFAULT_SWITCHING_GAIN
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
    from ...model import load
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


def paper_beta_hat(model, nominal_params=None, k_bounds=PAPER_K_RANGE, *, box=None):
    """The paper's constant ``beta_hat = (beta_max + beta_min) / 2`` over ``K in k_bounds``, or None.

    Parameters
    ----------
    model : Model
    nominal_params : dict, optional
        Nominal parameters (defaults for missing names).
    k_bounds : (float, float)
        ``(K_min, K_max)``, N m/rad, ``0 < K_min <= K_max``.
    box : dict name -> (lo, hi), optional
        A parameter box instead of ``k_bounds``: its ``J_l``, ``J_m``, ``K`` intervals are used.

    Returns
    -------
    float or None
        None when :func:`paper_bound_applies` is false for ``model``.
    """
    if not paper_bound_applies(model):
        return None
    if box is not None:
        return beta_bounds_link1(nominal_params, {k: v for k, v in box.items() if k in POSITIVE})[2]
    return beta_bounds_link1(nominal_params, {"K": _check_k_bounds(k_bounds)})[2]


def default_switching_gain(model, nominal_params, lam: float, reference_bounds, *, k_bounds=PAPER_K_RANGE,
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
    from ...control.laws import coefficients_from_pole
    R = np.asarray(reference_bounds, dtype=float).reshape(5, -1)[:, 0]
    return lemma1_gain(coefficients_from_pole(lam), R, nominal=nominal_params,
                       bounds={"K": tuple(float(v) for v in k_bounds)}, error_bounds=error_bounds, eta=eta)
