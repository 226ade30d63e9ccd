"""Reaching certificate of the TORQUE-SENSED sliding-mode law (``fjm tune MODEL --sensing torque``).

The law and why its stiffness error is matched
----------------------------------------------
A torque-sensed arm measures ``m = [q; dq; tau_J; dtau_J; dq_m]`` (5n) with
``tau_J = K (q_m - q)`` under the TRUE stiffness ``K``. The emitted ``control_<kind>_tau``
(docs/torque-sensing.md) computes, with NOMINAL parameters only::

    y_hat = T_tau(m; p_nom) = [q; dq; D^-1 (tau_J - h); D^-1 (dtau_J - D' y3 - h')]
    u     = alpha_tau(m; p_nom) + beta_tau(m; p_nom) nu,   beta_tau = J_m K_nom^-1 D
    alpha_tau = tau_J + B_m dq_m + J_m y3 + J_m K_nom^-1 W,  W = D'' y3 + 2 D' y4 + h''

``y_hat`` has no ``K`` in it, so with the true ``D``, ``h`` (no payload error) ``y_hat`` is the
true ``[q; dq; ddq; dddq]``. The motor equation gives
``tau_J'' = K J_m^-1 (u - tau_J - B_m dq_m - J_m y3)`` and, with the law,
``D y4' = Gamma (D nu + W) - W`` with ``Gamma = K J_m^-1 J_m,nom K_nom^-1`` (diagonal; ``K K_nom^-1``
when ``J_m`` is exact). The stiffness error is a MATCHED MULTIPLICATIVE input-gain error::

    y4' = D^-1 Gamma D nu + D^-1 (Gamma - I) W  (+ the J_m, B_m and payload terms when those are off)

For the sliding variable ``s`` of the integral law (``s = c0 z + c1 e1 + c2 e2 + c3 e3 + e4``,
``nu = w - k_s sat(s / delta)``, ``w = y4d' - (c0 e1 + c1 e2 + c2 e3 + c3 e4)``)::

    s' = F(y_hat, w, p) - G(y_hat, p) k_s psi,  G = D^-1 Gamma D,  F = (G - I) w + D^-1 (Gamma - I) W + ...

For one joint (or a diagonal ``D``) ``G = Gamma`` and the textbook sufficient condition is
``k_s >= (sup |F| + eta) / min Gamma``, i.e.
``k_s >= (sup |(Gamma - 1) w + (Gamma - 1) W / D| + eta) / Gamma_min``. For a chain ``G`` is a
similarity transform of ``Gamma``: its diagonal lies in ``[Gamma_min, Gamma_max]`` only
approximately and its off-diagonal entries couple the joints; the condition used is the
per-joint one of :mod:`fjm_runtime.analysis.certificates.certify` (``Phi_i = |F0_i| + sum_j |G_ij - d_ij| W_j +
sum_{j != i} |G_ij| k_j - G_ii k_i <= -eta_i``), which reduces to the textbook one when ``G``
is diagonal. The supremum over the box (nominal coordinates ``y_hat``, true ``K``, ``J_m`` and
payload) is computed by the same grid/sampling, vertex enumeration along affine coordinates
and local maximization (:class:`fjm_runtime.analysis.certificates.grid.BoxAnalysis`); only the evaluator
differs (:class:`TorqueEvaluator`: the true state ``x`` from ``y_hat`` and the true ``K``).

What it guarantees, and what not
--------------------------------
The certificate is the continuous-time reaching condition ``sgn(s_i) s_i' <= -eta_i`` outside
the boundary layer, for every state in the box (numerically, on the grid or samples, see
:data:`GUARANTEE_TAU`). It says nothing about: the zero-order hold at the control rate, a
computation delay, sensor noise or a filtered ``dtau_J``, the linear term ``k_lin`` (certified
with ``k_lin = 0``), whether the state stays in the box, and behaviour inside the boundary
layer. Those are what the sampled closed loops of the demo measure.
"""
from __future__ import annotations

from typing import Dict, Optional, Tuple

import numpy as np

from .certify import InfeasibleGainError, TuneResult, synthesize_gains
from .evaluator import Evaluator
from ...control.defaults import DEFAULT_LAYER_RATE
from ...drives import drive_indices, linear_stiffness_indices

__all__ = ["GUARANTEE_TAU", "TorqueEvaluator", "build_torque_inverse", "build_torque_nominal_fn",
           "torque_param_box", "synthesize_torque_gains", "gamma_tolerance", "obstacle", "input_gain_summary", "state_from_y_hat"]

GUARANTEE_TAU = ("continuous time, no delay, no sensor noise, dtau_J measured, k_lin = 0: "
                 "sgn(s_i) s_i' <= certificate_i <= -eta_i outside the boundary layer for every state whose "
                 "nominal torque coordinates y_hat = T_tau(m; p_nom), reference derivatives and true K, J_m and "
                 "payload lie in the box (numerical certificate: grid or samples, vertices along affine "
                 "coordinates, local maximization); the box is assumed invariant, not proven; the sampled "
                 "loop (zero-order hold, delay, noise) is not covered")
"""What a feasible torque-sensed certificate guarantees (reported by ``fjm tune --sensing torque``)."""


def _indices(model, role: str):
    """Indices of one drive role per joint; the stiffness of linear springs only (``model.drives``)."""
    if role == "stiffness":
        return list(linear_stiffness_indices(model, "the torque-sensed certificate"))
    return list(drive_indices(model, role))


def _measurement(x, K, n):
    import casadi as ca
    q, dq, qm, dqm = (x[i * n:(i + 1) * n] for i in range(4))
    return ca.vertcat(q, dq, K * (qm - q), K * (dqm - dq), dqm)


def build_torque_inverse(model, p_nom: np.ndarray):
    """CasADi Function ``(x, y, p) -> (Y_m(x; p) - y_m, dY_m/dx_m)`` with ``Y = T_tau(m(x; K); p_nom)``.

    ``p`` is the TRUE parameter vector (its ``K`` builds the measurement ``m``), ``p_nom``
    (npar,) the controller's; ``Y_m`` the motor half (rows 2n..4n) of ``Y``.
    """
    import casadi as ca
    n, nx, npar = int(model.n), int(model.nx), len(model.param_names)
    x, y, p = ca.SX.sym("x", nx), ca.SX.sym("y", nx), ca.SX.sym("p", npar)
    K = p[_indices(model, "stiffness")]
    Ym = model.torque_functions["T_tau"](_measurement(x, K, n), ca.DM(p_nom))[2 * n:]
    return ca.Function("tune_tau_newton", [x, y, p], [Ym - y[2 * n:], ca.jacobian(Ym, x[2 * n:])])


def build_torque_nominal_fn(model, p_nom: np.ndarray, c_last: np.ndarray, beta_hat=None):
    """CasADi Function ``(x, y, p) -> [F0; vec G; alpha_hat; vec B; vec C J g]`` of the torque-sensed law.

    Same outputs as :func:`fjm_runtime.analysis.certificates.evaluator.build_nominal_fn` (so that
    :class:`~fjm_runtime.analysis.certificates.grid.BoxAnalysis` works unchanged), with
    ``Y(x; p) = T_tau(m(x; K_true); p_nom)``, ``J = dY/dx``, ``alpha_hat = alpha_tau(m; p_nom)``,
    ``B = beta_tau(m; p_nom)``; ``x`` (4n,) the TRUE state, ``p`` the TRUE parameters; output
    shape ``(2n + 3n^2, 1)``. ``beta_hat`` must be None (the law uses ``beta_tau``).
    """
    import casadi as ca
    if beta_hat is not None:
        raise ValueError("beta_hat: the torque-sensed law uses beta_tau(m; p_nom); a constant beta_hat is "
                         "not supported (expected None)")
    n, nx, npar = int(model.n), int(model.nx), len(model.param_names)
    fns, tf = model.functions, model.torque_functions
    x, y, p = ca.SX.sym("x", nx), ca.SX.sym("y", 4 * n), ca.SX.sym("p", npar)
    pn = ca.DM(p_nom)
    m = _measurement(x, p[_indices(model, "stiffness")], n)
    J = ca.jacobian(tf["T_tau"](m, pn), x)
    C = ca.horzcat(*[float(c_last[k]) * ca.SX.eye(n) for k in range(3)], ca.SX.eye(n))
    f = fns["f"](x, p)
    g = ca.reshape(fns["g"](x, p), nx, n)
    a_hat = tf["alpha_tau"](m, pn)
    B = ca.reshape(tf["beta_tau"](m, pn), n, n)
    CJ = ca.mtimes(C, J)
    lin = float(c_last[0]) * y[n:2 * n] + float(c_last[1]) * y[2 * n:3 * n] + float(c_last[2]) * y[3 * n:]
    F0 = ca.mtimes(CJ, f + ca.mtimes(g, a_hat)) - lin
    CJg = ca.mtimes(CJ, g)
    G = ca.mtimes(CJg, B)
    out = ca.vertcat(F0, ca.reshape(G, n * n, 1), a_hat, ca.reshape(B, n * n, 1), ca.reshape(CJg, n * n, 1))
    return ca.Function("tune_tau_nominal", [x, y, p], [out])


class TorqueEvaluator(Evaluator):
    """:class:`~fjm_runtime.analysis.certificates.evaluator.Evaluator` of the torque-sensed law.

    ``x`` from ``y_hat`` and the TRUE parameters by Newton on ``Y_m(x; p) = y_m`` (``Y`` is
    affine in the motor half ``q_m``, ``dq_m`` for fixed ``q``, ``dq``: one step is exact,
    the others check it).

    Parameters
    ----------
    model : Model
    p_nom : ndarray, shape (npar,)
    c_last : ndarray, shape (3,)
        The last three surface coefficients.
    beta_hat : None
    """

    def __init__(self, model, p_nom, c_last, beta_hat=None):
        super().__init__(model, build_torque_nominal_fn(model, np.asarray(p_nom, dtype=float), c_last, beta_hat))
        self.inv = build_torque_inverse(model, np.asarray(p_nom, dtype=float))
        self.stats = None

    def __call__(self, Y: np.ndarray, P: np.ndarray) -> np.ndarray:
        """Values at ``Y`` (N, 4n), ``P`` (N, npar) (as the base class); records the extremes of ``G``
        and ``|F0|`` over every point evaluated (:func:`input_gain_summary`)."""
        V = super().__call__(Y, P)
        n = self.n
        if V.shape[1] == 2 * n + 3 * n * n and V.shape[0]:
            G = V[:, n:n + n * n].reshape(-1, n, n, order="F")
            diag = np.einsum("nii->ni", G)
            st = {"dmin": diag.min(axis=0), "dmax": diag.max(axis=0),
                  "off": (np.sum(np.abs(G), axis=2) - np.abs(diag)).max(axis=0),
                  "F0": np.abs(V[:, :n]).max(axis=0), "GI": np.abs(G - np.eye(n)).max(axis=0)}
            if self.stats is not None:
                old = self.stats
                st = {"dmin": np.minimum(old["dmin"], st["dmin"]), **{k: np.maximum(old[k], st[k])
                                                                      for k in ("dmax", "off", "F0", "GI")}}
            self.stats = st
        return V


def state_from_y_hat(model, y_hat, p_true, p_nom=None) -> np.ndarray:
    """The TRUE state ``x`` (4n,) whose measurement has nominal torque coordinates ``y_hat`` (4n,)."""
    pn = np.asarray(model.params_array(p_nom), dtype=float)
    ev = TorqueEvaluator(model, pn, np.ones(3))
    import casadi as ca
    nx = int(model.nx)
    xs, ys, ps = ca.SX.sym("x", nx), ca.SX.sym("y", nx), ca.SX.sym("p", pn.size)
    ev.fn = ca.Function("state", [xs, ys, ps], [xs])
    pt = np.asarray(model.params_array(p_true), dtype=float)
    return ev(np.asarray(y_hat, dtype=float)[None, :], pt[None, :])[0]


def torque_param_box(model, nominal_params=None, gamma_range=(0.7, 1.3), jm_range=(0.8, 1.2),
                     payload: float = 1.0) -> Dict[str, Tuple[float, float]]:
    """The box of TRUE parameters: every ``K_i = Gamma_i K_nom,i``, ``J_m,i`` scaled, a payload.

    Parameters
    ----------
    model : Model
    nominal_params : dict or array_like, optional
    gamma_range : (lo, hi)
        Stiffness ratio ``Gamma = K / K_nom`` of every joint.
    jm_range : (lo, hi) or None
        Motor inertia ratio of every joint (None: exact).
    payload : float
        Unknown payload mass, kg, >= 0: ``m_load`` in ``[nominal, nominal + payload]`` on models
        with a payload parameter (the Panda), otherwise the LAST link's mass ``m<n>`` (planar
        chains; its centre of mass stays at ``r<n>``).

    Returns
    -------
    dict name -> (lo, hi)
    """
    names = list(model.param_names)
    pv = np.asarray(model.params_array(nominal_params or {}, arg="nominal_params"), dtype=float)
    for label, rng in (("gamma_range", gamma_range), ("jm_range", jm_range)):
        if rng is not None and not (len(rng) == 2 and 0 < float(rng[0]) <= float(rng[1])
                                    and np.all(np.isfinite(rng))):
            raise ValueError(f"{label} = {rng!r}: expected (lo, hi) with 0 < lo <= hi")
    if not (np.isfinite(payload) and payload >= 0):
        raise ValueError(f"payload = {payload!r}: expected a finite mass >= 0 kg")
    box = {}
    for rng, role in ((gamma_range, "stiffness"), (jm_range, "rotor_inertia")):
        if rng is None:
            continue
        for j in _indices(model, role):
            box[names[j]] = (float(rng[0]) * pv[j], float(rng[1]) * pv[j])
    mass = "m_load" if "m_load" in names else ("M" if "M" in names else f"m{int(model.n)}")
    if payload > 0 and mass in names:
        j = names.index(mass)
        box[mass] = (pv[j], pv[j] + float(payload))
    return box


def input_gain_summary(stats: dict, W) -> dict:
    """Per joint, the numbers behind a certificate or its obstacle, over every box point evaluated.

    Parameters
    ----------
    stats : dict
        :attr:`TorqueEvaluator.stats`.
    W : array_like, shape (n,)
        Bound of ``|w|``.

    Returns
    -------
    dict of lists of n
        ``G_diag_min``, ``G_diag_max`` (the input gain ``G_ii`` of ``s_i'``; ``Gamma_i`` for a
        diagonal ``D``), ``G_offdiag_max`` (``sup sum_{j != i} |G_ij|``, the coupling through
        ``D^-1 Gamma D``), ``drift_F0`` (``sup |F0_i|``: the ``(Gamma - I) W``, ``J_m`` and payload
        terms) and ``drift_input_gain_bound`` (``sum_j sup |G_ij - d_ij| W_j``: the input-gain error
        acting on ``w``, an upper bound).
    """
    W = np.asarray(W, dtype=float)
    return {"G_diag_min": stats["dmin"].tolist(), "G_diag_max": stats["dmax"].tolist(),
            "G_offdiag_max": stats["off"].tolist(), "drift_F0": stats["F0"].tolist(),
            "drift_input_gain_bound": (stats["GI"] @ W).tolist()}


def gamma_tolerance(model, q_box, p_nom=None, samples: int = 4000, seed: int = 0, q_center=None) -> dict:
    """The largest stiffness-ratio spread for which the switching term still acts on every ``s_i``.

    With ``G = D^-1 Gamma D`` and ``Gamma_k = 1 + d_k``, ``|d_k| <= r`` (``J_m`` exact):
    ``G_ii = 1 + sum_k a_ik d_k`` with ``a_ik = (D^-1)_ik D_ki`` (``sum_k a_ik = 1``), so
    ``min G_ii = 1 - r sum_k |a_ik|`` and ``G_ii > 0`` on the whole box iff
    ``r < r_i = 1 / sup_q sum_k |a_ik|``. Exact in ``Gamma``; the supremum over ``q`` is sampled
    (uniform in ``|q_i - q_center_i| <= q_box_i``).

    Parameters
    ----------
    model : Model
    q_box : array_like, shape (n,)
        Half-widths of the link angles, rad.
    q_center : array_like, shape (n,), optional
        Centre of the link-angle box (default 0, the certificate's box).
    p_nom : dict or array_like, optional
    samples : int
    seed : int

    Returns
    -------
    dict
        ``r_max`` (n,) per joint (``Gamma in [1 - r, 1 + r]`` keeps ``G_ii > 0``),
        ``coupling`` (n,) ``sup_q sum_k |a_ik|`` and ``q_worst`` (n, n): the sampled ``q`` per joint.
    """
    n, nx = int(model.n), int(model.nx)
    qb = np.broadcast_to(np.asarray(q_box, dtype=float), (n,))
    pv = np.asarray(model.params_array(p_nom), dtype=float)
    rng = np.random.default_rng(seed)
    qc = np.zeros(n) if q_center is None else np.broadcast_to(np.asarray(q_center, dtype=float), (n,))
    Q = qc + rng.uniform(-qb, qb, (int(samples), n))
    X = np.zeros((Q.shape[0], nx))
    X[:, :n] = Q
    X[:, 2 * n:3 * n] = Q
    Dm = np.asarray(model.functions["inertia"].map(Q.shape[0])(X.T, np.repeat(pv[:, None], Q.shape[0], axis=1)))
    D = Dm.reshape(n, Q.shape[0], n).transpose(1, 0, 2)
    A = np.abs(np.linalg.inv(D) * np.swapaxes(D, 1, 2))          # a_ik = Dinv_ik D_ki
    S = A.sum(axis=2)
    worst = np.argmax(S, axis=0)
    return {"r_max": (1.0 / S.max(axis=0)).tolist(), "coupling": S.max(axis=0).tolist(),
            "q_worst": Q[worst].tolist()}


def obstacle(model, res: TuneResult, box) -> str:
    """The obstacle of an infeasible torque-sensed synthesis in numbers (which joint, which term, how far).

    For a non-positive input gain ``G_ii``: its value, the stiffness-ratio spread that would keep it
    positive (:func:`gamma_tolerance` on the same link-angle box) against the box's spread; otherwise
    the synthesis' own reason with the drift terms of the worst joint.
    """
    ig = res.settings.get("input_gain", {})
    n = int(model.n)
    names = list(model.param_names)
    ratio = []
    for j in _indices(model, "stiffness"):
        lo, hi = box.get(names[j], (None, None))
        if lo is not None:
            k0 = float(res.settings["nominal_params"][names[j]])
            ratio.append(max(1.0 - lo / k0, hi / k0 - 1.0))
    spread = max(ratio) if ratio else 0.0
    dmin = np.asarray(ig.get("G_diag_min", np.ones(n)))
    if np.any(dmin <= 0):
        i = int(np.argmin(dmin))
        tol = gamma_tolerance(model, res.y_box[0], res.settings["nominal_params"])
        return (f"joint {i + 1}: the input gain G_ii = (D^-1 Gamma D)_ii of s_i' reaches {dmin[i]:.3g} <= 0 on the box "
                f"(stiffness ratio K/K_nom within +-{100 * spread:.0f} % per joint, J_m and payload as boxed): the "
                f"per-joint switching term does not act on s_{i + 1} there, for any k_s. With J_m exact, G_ii > 0 "
                f"needs |Gamma_k - 1| < r_i = 1 / sup_q sum_k |(D^-1)_ik D_ki| = {tol['r_max'][i]:.3g} "
                f"(coupling {tol['coupling'][i]:.3g} at q = {np.round(tol['q_worst'][i], 3).tolist()}); "
                f"per joint r = {np.round(tol['r_max'], 3).tolist()}, i.e. the box is "
                f"{spread / max(tol['r_max'][i], 1e-12):.3g} x too wide for joint {i + 1}")
    i = int(np.nanargmax(np.asarray(ig.get("drift_F0", np.zeros(n)))))
    return (f"{res.reason}; worst drift on joint {i + 1}: sup |F0| = {ig['drift_F0'][i]:.4g}, "
            f"input-gain error on w <= {ig['drift_input_gain_bound'][i]:.4g}, G_ii in "
            f"[{ig['G_diag_min'][i]:.3g}, {ig['G_diag_max'][i]:.3g}], coupling sum |G_ij| <= {ig['G_offdiag_max'][i]:.3g}")


def synthesize_torque_gains(model, nominal_params=None, *, param_box=None, reference_bounds, error_bounds,
                            lam: float, integral: bool = True, eta=10.0, u_max=None, delta=None,
                            layer_rate: float = DEFAULT_LAYER_RATE, include_margin: bool = True,
                            budget: int = 60000, n_grid: Optional[int] = None, seed: int = 0,
                            raise_infeasible: bool = False) -> TuneResult:
    """Per-joint switching gains of the torque-sensed law (``ismc_tau``, or ``smc_tau`` with
    ``integral=False``) with a certificate.

    Parameters as :func:`fjm_runtime.analysis.certificates.certify.synthesize_gains` (``beta_tau``, no constant ``beta_hat``);
    ``param_box`` default :func:`torque_param_box`. ``result.settings['sensing']`` is ``'torque'``.

    Returns
    -------
    TuneResult
    """
    box = torque_param_box(model, nominal_params) if param_box is None else param_box
    made = []

    def evaluator(*args):
        made.append(TorqueEvaluator(*args))
        return made[-1]

    res = synthesize_gains(model, nominal_params, param_box=box, reference_bounds=reference_bounds,
                           error_bounds=error_bounds, lam=lam, integral=integral, eta=eta, u_max=u_max, delta=delta,
                           layer_rate=layer_rate, include_margin=include_margin, budget=budget, n_grid=n_grid,
                           seed=seed, raise_infeasible=False, evaluator=evaluator)
    res.settings.update({"sensing": "torque", "law": "ismc_tau" if integral else "smc_tau", "beta_hat": "beta_tau(m; p_nom)", "k_lin": 0.0,
                         "input_gain": input_gain_summary(made[0].stats, res.W)})
    if not res.feasible:
        res.settings["obstacle"] = obstacle(model, res, box)
    if raise_infeasible and not res.feasible:
        raise InfeasibleGainError(f"{model.name}: {res.reason}", res)
    return res
