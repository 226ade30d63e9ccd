"""Excitation trajectories for identification: a finite Fourier series per joint (``fjm excite``).

Per joint ``i`` the link reference is

    q_d(t) = q0_i + sum_{h=1..H} [a_ih sin(h w0 t) + b_ih (cos(h w0 t) - 1)]

with period ``2 pi / w0`` and ``q_d(0) = q0``. The coefficients obey ``sum_h h a_ih = sum_h h^3 a_ih = 0``
and ``sum_h h^2 b_ih = sum_h h^4 b_ih = 0``: the first four derivatives vanish at ``t = 0`` and so at every
whole period, and the log's duration is a whole number of periods (the base frequency is raised to
fit). The arm starts and ends at rest at the base posture ``q0`` (motors at ``q0 + K^-1 G(q0)``, holding
gravity), where a robot can hand over to and take back from the excitation.

The coefficients are chosen to make the identification well conditioned. For a candidate, the motion
the NOMINAL model needs to follow ``q_d`` is its flat-output inverse (:func:`nominal_motion`: the link
equation's ``tau_J = D(q) ddq + h(q, dq)`` and its first two time derivatives by forward automatic
differentiation of the model's generated ``f`` and ``inertia``, the spring law inverted for
``phi = q_m - q``, then ``u = J_m ddq_m + B_m dq_m + tau_J``); the cost is the worst joint's condition
number of the column-scaled regressors ``fjm identify`` solves (:func:`joint_conditions`): the motor
equation's ``[ddq_m, dq_m, tanh(dq_m / v_c)]`` and the spring's ``[phi, (phi^3,) 1]`` (the ``1`` is the
torque sensor's offset). Every candidate is scaled, per joint, to the largest amplitude within
``amplitude``, the position limits (less :data:`POSITION_MARGIN`), :data:`VELOCITY_SHARE` of the velocity
limits and :data:`TORQUE_SHARE` of the effort limits (stated in the model's manifest, from the URDF).
Random draws first, then a few iterations of a (1+1) local search on the worst joint's coefficients.
The CSV a robot plays and the loop that plays it: :mod:`fjm_runtime.ident.excite_loop`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple, Optional

import numpy as np

from ..control.references import Reference
from ..drives import drive_indices, model_springs, spring_laws
from ..validation import FjmValueError

__all__ = ["FourierReference", "Excitation", "Limits", "design_excitation", "joint_conditions", "limits_of",
           "nominal_motion", "regressor_condition", "rest_coefficients", "usage", "whole_periods",
           "POSITION_MARGIN", "TORQUE_SHARE", "VELOCITY_SHARE"]

#: Share of the velocity limits and of the effort limits an excitation may use.
VELOCITY_SHARE, TORQUE_SHARE = 0.5, 0.8
#: Distance kept from the position limits, rad.
POSITION_MARGIN = 0.05
#: Samples per period on which candidates are compared (the chosen one is rated on the log's own grid).
SEARCH_SAMPLES = 400


class FourierReference(Reference):
    """``q_d`` of the module docstring: ``q0`` (n,), ``a``, ``b`` (n, H), base frequency ``w0`` (rad/s)."""

    def __init__(self, q0, a, b, w0: float):
        self.q0 = np.asarray(q0, dtype=float).reshape(-1)
        self.a, self.b = np.atleast_2d(np.asarray(a, dtype=float)), np.atleast_2d(np.asarray(b, dtype=float))
        self.w0, self.n = float(w0), int(self.q0.size)
        self.h = np.arange(1, self.a.shape[1] + 1, dtype=float)

    @property
    def period(self) -> float:
        """``2 pi / w0``, s."""
        return 2.0 * np.pi / self.w0

    def sample(self, t) -> np.ndarray:
        """``(N, 5, n)``: ``q_d`` and its four derivatives at the times ``t``."""
        t = np.asarray(t, dtype=float).reshape(-1)
        wt = t[:, None] * (self.h * self.w0)[None, :]                  # (N, H)
        s, c = np.sin(wt), np.cos(wt)
        out = np.empty((t.size, 5, self.n))
        for k in range(5):
            wk = (self.h * self.w0) ** k
            ds, dc = [s, c, -s, -c][k % 4], [c, -s, -c, s][k % 4]      # k-th derivative: k quarter turns
            out[:, k, :] = (ds * wk) @ self.a.T + (dc * wk) @ self.b.T
        out[:, 0, :] += self.q0 - self.b.sum(axis=1)
        return out

    def __call__(self, t: float) -> np.ndarray:
        return self.sample([t])[0]

    def derivative_bounds(self) -> np.ndarray:
        amp = np.abs(self.a) + np.abs(self.b)
        return np.stack([np.abs(self.q0) + 2 * amp.sum(axis=1)]
                        + [(amp * (self.h * self.w0) ** k).sum(axis=1) for k in range(1, 5)])

    def as_dict(self) -> dict:
        return {"q0": self.q0.tolist(), "a": self.a.tolist(), "b": self.b.tolist(), "w0": self.w0}


def rest_coefficients(a, b):
    """``(a, b)`` projected (least change) onto the series whose derivatives 1..4 vanish at ``t = 0``.

    ``a``, ``b`` shape (n, H), ``H >= 3``: ``a`` orthogonal to ``h`` and ``h^3``, ``b`` to ``h^2`` and ``h^4``.
    """
    a, b = np.atleast_2d(np.asarray(a, dtype=float)), np.atleast_2d(np.asarray(b, dtype=float))
    h = np.arange(1, a.shape[1] + 1, dtype=float)
    out = []
    for x, powers in ((a, (1, 3)), (b, (2, 4))):
        C = np.stack([h ** k / np.linalg.norm(h ** k) for k in powers])     # (2, H), rows scaled
        out.append(x - (x @ C.T) @ np.linalg.solve(C @ C.T, C))
    return out[0], out[1]


def whole_periods(duration: float, base_freq: float, rate: float):
    """``(periods, base frequency Hz, samples per period)``: the lowest base frequency from ``base_freq`` up
    with a whole number of periods in ``duration`` (and of samples per period); one period if ``duration``
    is shorter than ``1 / base_freq``."""
    periods = max(1, int(np.ceil(duration * base_freq - 1e-9)))
    per = max(1, int(round(duration * rate / periods)))
    return periods, rate / per, per


class Limits(NamedTuple):
    """Bounds on the excitation: ``lo``, ``hi`` (n,) positions; ``v``, ``u`` (n,) allowed speed and torque
    (``inf``: the model states none); ``stated`` the model's own ``velocity``, ``effort`` (or None)."""

    lo: np.ndarray
    hi: np.ndarray
    v: np.ndarray
    u: np.ndarray
    position: Optional[np.ndarray]
    velocity: Optional[np.ndarray]
    effort: Optional[np.ndarray]


def limits_of(model, q0, amplitude: float) -> Limits:
    """The excitation's bounds (module docstring) about the base posture ``q0``."""
    n = int(model.n)
    pos, vel, eff = model.position_limits, model.velocity_limits, model.effort_limits
    lo, hi = q0 - amplitude, q0 + amplitude
    if pos is not None:
        lo, hi = np.maximum(lo, pos[:, 0] + POSITION_MARGIN), np.minimum(hi, pos[:, 1] - POSITION_MARGIN)
        if np.any(lo >= q0) or np.any(hi <= q0):
            j = int(np.argmax((lo >= q0) | (hi <= q0)))
            raise FjmValueError(f"excite: base posture q0_{j + 1} = {q0[j]:.4g} rad is within {POSITION_MARGIN} rad "
                                f"of the limits {pos[j].tolist()}; expected a posture inside the joint range")
    v = np.full(n, np.inf) if vel is None else VELOCITY_SHARE * vel
    u = np.full(n, np.inf) if eff is None else TORQUE_SHARE * eff
    return Limits(lo, hi, v, u, pos, vel, eff)


# -- the nominal model's motion along q_d (flat-output inverse) -------------------------------------------

_JETS: dict = {}


def _jet_function(model):
    """CasADi ``(q, dq, ddq, d3q, d4q, p) -> (tau, tau', tau'')`` of ``tau = D(q) ddq + h(q, dq)``."""
    import casadi as ca
    key = id(model)
    if key in _JETS and _JETS[key][0] is model:
        return _JETS[key][1]
    n, npar = int(model.n), len(model.param_names)
    d = [ca.SX.sym(f"d{k}", n) for k in range(5)]
    p = ca.SX.sym("p", npar)
    x = ca.vertcat(d[0], d[1], d[0], ca.SX.zeros(n))                   # q_m = q: no spring torque
    a0 = model.functions["f"](x, p)[n:2 * n]                            # -D^-1 h
    D = ca.reshape(model.functions["inertia"](x, p), n, n)
    tau = ca.mtimes(D, d[2] - a0)
    z, dz = ca.vertcat(d[0], d[1], d[2]), ca.vertcat(d[1], d[2], d[3])
    dtau = ca.jtimes(tau, z, dz)
    z2, dz2 = ca.vertcat(z, d[3]), ca.vertcat(dz, d[4])
    ddtau = ca.jtimes(dtau, z2, dz2)
    try:                                        # common subexpressions shared: ~40 % fewer instructions
        fn = ca.Function("fjm_excite_jet", d + [p], [tau, dtau, ddtau], {"cse": True})
    except RuntimeError:                        # a CasADi without the option
        fn = ca.Function("fjm_excite_jet", d + [p], [tau, dtau, ddtau])
    _JETS[key] = (model, fn)
    return fn


def link_jets(model, R: np.ndarray, p) -> tuple:
    """``(tau, tau', tau'')``, each (N, n), along reference rows ``R`` (N, 5, n) at parameters ``p``."""
    N = R.shape[0]
    fn = _jet_function(model).map(N)
    out = fn(*[R[:, k, :].T for k in range(5)], np.repeat(np.asarray(p, dtype=float)[:, None], N, axis=1))
    return tuple(np.asarray(o).T for o in out)


def drive_parameters(model, p) -> dict:
    """The motor values of ``p`` (``model.drives``): ``J_m``, ``B_m``, each (n,).

    Raises
    ------
    FjmValueError
        A spring law the identification's regressors do not cover (linear or one-joint cubic).
    """
    p = np.asarray(p, dtype=float)
    laws = spring_laws(model)
    if laws != ("cubic",) and set(laws) != {"linear"}:
        raise FjmValueError(f"excite: {model.name} has spring laws {sorted(set(laws))}; expected a reduced model "
                            "with a linear or cubic spring")
    return {"J_m": p[drive_indices(model, "rotor_inertia")], "B_m": p[drive_indices(model, "damping")]}


def _deflection(model, p, tau, dtau, ddtau):
    """``phi, phi', phi''``, each (N, n), with ``psi(phi) = tau`` by the model's spring law: ``phi = psi^-1(tau)``,
    ``phi' = tau' / psi'(phi)``, ``phi'' = (tau'' - psi''(phi) phi'^2) / psi'(phi)`` (``tau`` and its rates (N, n))."""
    fns = model_springs(model)
    N = tau.shape[0]
    P = np.repeat(np.asarray(p, dtype=float)[:, None], N, axis=1)
    phi = np.asarray(fns["spring_inverse"].map(N)(tau.T, P)).T
    _, d1, d2 = (np.asarray(v).T for v in fns["spring"].map(N)(phi.T, P))
    dphi = dtau / d1
    return phi, dphi, (ddtau - d2 * dphi ** 2) / d1


def nominal_motion(model, ref: FourierReference, t, p) -> dict:
    """The motion that makes the links follow ``ref`` at parameters ``p`` (flat-output inverse, module
    docstring): ``q, dq, ddq, qm, dqm, ddqm, phi, tau, u``, each shape (N, n), at the times ``t`` (N,)."""
    R = ref.sample(t)
    tau, dtau, ddtau = link_jets(model, R, p)
    drive = drive_parameters(model, p)
    phi, dphi, ddphi = _deflection(model, p, tau, dtau, ddtau)
    q, dq, ddq = R[:, 0], R[:, 1], R[:, 2]
    qm, dqm, ddqm = q + phi, dq + dphi, ddq + ddphi
    u = drive["J_m"] * ddqm + drive["B_m"] * dqm + tau
    return {"q": q, "dq": dq, "ddq": ddq, "qm": qm, "dqm": dqm, "ddqm": ddqm, "phi": phi, "tau": tau, "u": u}


# -- the cost ---------------------------------------------------------------------------------------------

def _condition(A: np.ndarray) -> float:
    A = A / np.maximum(np.linalg.norm(A, axis=0), 1e-300)
    sv = np.linalg.svd(A, compute_uv=False)
    return float(sv[0] / max(sv[-1], 1e-300 * sv[0]))


def joint_conditions(traj: dict, v_c: float = 0.01, cubic: bool = False) -> np.ndarray:
    """Per joint, the larger condition number of the column-scaled motor regressor
    ``[ddq_m, dq_m, tanh(dq_m / v_c)]`` and spring regressor ``[phi, (phi^3 if cubic,) 1]``, shape (n,)."""
    out = []
    for i in range(traj["q"].shape[1]):
        dqm, phi = traj["dqm"][:, i], traj["phi"][:, i]
        motor = np.column_stack([traj["ddqm"][:, i], dqm, np.tanh(dqm / v_c)])
        spring = np.column_stack([phi] + ([phi ** 3] if cubic else []) + [np.ones_like(phi)])
        out.append(max(_condition(motor), _condition(spring)))
    return np.array(out)


def regressor_condition(traj: dict, v_c: float = 0.01, cubic: bool = False) -> float:
    """The worst joint's :func:`joint_conditions` (1 is ideal)."""
    return float(np.max(joint_conditions(traj, v_c, cubic)))


def usage(traj: dict, q0, lim: Limits) -> dict:
    """Largest share of each stated limit used (None where the model states none): ``position`` (of the way
    from ``q0`` to the limit), ``velocity``, ``torque``; per joint arrays under ``<kind>_joints``."""
    out = {}
    if lim.position is not None:
        d = traj["q"] - q0
        room = np.where(d >= 0, lim.position[:, 1] - q0, q0 - lim.position[:, 0])
        out["position_joints"] = np.max(np.abs(d) / room, axis=0)
    if lim.velocity is not None:
        out["velocity_joints"] = np.max(np.abs(traj["dq"]), axis=0) / lim.velocity
    if lim.effort is not None:
        out["torque_joints"] = np.max(np.abs(traj["u"]), axis=0) / lim.effort
    for k in ("position", "velocity", "torque"):
        out[k] = float(np.max(out[f"{k}_joints"])) if f"{k}_joints" in out else None
    return out


# -- the search -------------------------------------------------------------------------------------------

@dataclass
class Excitation:
    """A chosen excitation.

    Attributes
    ----------
    reference : FourierReference
    condition : float
        Worst joint's condition number on the log's grid (:func:`regressor_condition`).
    first : float
        The same for the first random draw (what an unoptimized series reaches).
    joints : ndarray, shape (n,)
        Per-joint condition numbers.
    usage : dict
        :func:`usage` of the nominal motion.
    duration, base_freq : float
        Whole periods (s) and the base frequency (Hz) adjusted to them.
    periods, evaluations : int
    """

    reference: FourierReference
    condition: float
    first: float
    joints: np.ndarray
    usage: dict
    duration: float
    base_freq: float
    periods: int
    evaluations: int
    settings: dict = field(default_factory=dict)


class _Search:
    """Candidates scaled into the limits and rated on one period (module docstring)."""

    def __init__(self, model, q0, lim: Limits, w0: float, samples: int, v_c: float, cubic: bool):
        self.model, self.q0, self.lim, self.w0, self.v_c, self.cubic = model, q0, lim, w0, v_c, cubic
        self.p = model.params_array()
        self.t = np.arange(samples) * (2 * np.pi / w0) / samples
        self.evaluations = 0

    def scaled(self, a, b):
        """``(reference, motion, joint costs)`` of the series ``a, b`` scaled per joint into the limits."""
        a, b = rest_coefficients(a, b)
        unit = FourierReference(np.zeros_like(self.q0), a, b, self.w0).sample(self.t)
        g, dg = unit[:, 0], unit[:, 1]
        up, down = (np.maximum(np.max(v, axis=0), 1e-300) for v in (g, -g))    # g(0) = 0: both >= 0
        s = np.min(np.stack([(self.lim.hi - self.q0) / up, (self.q0 - self.lim.lo) / down,
                             self.lim.v / np.maximum(np.max(np.abs(dg), axis=0), 1e-300)]), axis=0)
        for _ in range(12):                       # torque: shrink every joint until the effort limits hold
            ref = FourierReference(self.q0, a * s[:, None], b * s[:, None], self.w0)
            traj = nominal_motion(self.model, ref, self.t, self.p)
            self.evaluations += 1
            over = float(np.max(np.abs(traj["u"]) / self.lim.u))
            if over <= 1.0:
                return ref, traj, joint_conditions(traj, self.v_c, self.cubic)
            s = s * 0.85
        return None

    @staticmethod
    def better(new, old) -> bool:
        return old is None or (new.max(), np.sum(np.log(new))) < (old.max(), np.sum(np.log(old)))


def design_excitation(model, duration: float, *, q0=None, amplitude: float = 0.5, harmonics: int = 5,
                      base_freq: float = 0.2, candidates: int = 20, iterations: int = 40, seed: int = 0,
                      v_c: float = 0.01, rate: float = 1000.0, cubic: Optional[bool] = None) -> Excitation:
    """The best-conditioned rest-to-rest Fourier series within the limits (module docstring).

    Parameters
    ----------
    model : Model
        A reduced model (linear ``K``/``K<i>`` or cubic ``k1, k3`` springs).
    duration : float
        Length of the log, s: a whole number of base periods (:func:`whole_periods`).
    q0 : array_like, shape (n,), optional
        Base posture (default: the middle of the joint ranges, zeros where none is stated).
    amplitude : float
        Largest excursion from ``q0``, rad.
    harmonics : int
        Harmonics per joint, >= 3 (two coefficients of each kind go to starting at rest).
    base_freq : float
        Lowest base frequency, Hz (raised to fit whole periods in ``duration``).
    candidates, iterations : int
        Random draws, then local-search iterations.
    v_c : float
        The Coulomb regularization of ``fjm identify`` (rad/s).
    rate : float
        Sample rate of the log, Hz.
    cubic : bool, optional
        Rate the cubic spring column ``phi^3`` (default: the model's spring is cubic).

    Raises
    ------
    FjmValueError
        Bad settings, a posture at a limit, or gravity alone beyond the effort limits.
    """
    n = int(model.n)
    for name, value, ok, expect in (("duration", duration, duration > 0, "> 0 s"),
                                    ("base_freq", base_freq, base_freq > 0, "> 0 Hz"),
                                    ("harmonics", harmonics, harmonics >= 3, ">= 3"),
                                    ("candidates", candidates, candidates >= 1, ">= 1"),
                                    ("iterations", iterations, iterations >= 0, ">= 0"),
                                    ("amplitude", amplitude, amplitude > 0, "> 0 rad"),
                                    ("rate", rate, rate > 0, "> 0 Hz"), ("v_c", v_c, v_c > 0, "> 0 rad/s")):
        if not (np.isfinite(value) and ok):                            # one line per setting, named
            raise FjmValueError(f"excite: {name} = {value!r}; expected a finite {name} {expect}")
    pos = model.position_limits
    if q0 is None:
        q0 = np.zeros(n) if pos is None else np.where(np.isfinite(pos).all(axis=1),   # a continuous joint: 0
                                                  np.where(np.isfinite(pos), pos, 0.0).mean(axis=1), 0.0)
    q0 = np.asarray(q0, dtype=float).reshape(n)
    periods, f0, per = whole_periods(duration, base_freq, rate)
    cubic = (spring_laws(model) == ("cubic",)) if cubic is None else bool(cubic)
    search = _Search(model, q0, limits_of(model, q0, amplitude), 2 * np.pi * f0, min(per, SEARCH_SAMPLES), v_c, cubic)
    rng = np.random.default_rng(seed)
    decay = np.arange(1, harmonics + 1, dtype=float)
    best, first = None, None
    for _ in range(candidates):
        ab = rng.standard_normal((2, n, harmonics)) / decay
        got = search.scaled(*ab)
        if got is not None and first is None:
            first = got[0]
        if got is not None and _Search.better(got[2], None if best is None else best[1]):
            best = (ab, got[2], got[0])
    if best is None:
        raise FjmValueError(f"excite: no series of {candidates} keeps within {TORQUE_SHARE:.0%} of the effort limits "
                            f"{model.effort_limits.tolist()} N m (gravity at the base posture {np.round(q0, 3).tolist()} "
                            "alone?); expected another --posture")
    sigma = 0.3
    for _ in range(iterations):
        ab = best[0].copy()
        j = int(np.argmax(best[1]))
        ab[:, j] += sigma * np.sqrt(np.mean(ab[:, j] ** 2)) * rng.standard_normal((2, harmonics)) / decay
        got = search.scaled(*ab)
        ok = got is not None and _Search.better(got[2], best[1])
        sigma = min(1.0, sigma * 1.5) if ok else max(0.02, sigma * 0.85)
        if ok:
            best = (ab, got[2], got[0])
    return _rate_on_log_grid(model, best[2], q0, search, first, periods, f0, per, rate)


def _rate_on_log_grid(model, ref, q0, search: _Search, first, periods, f0, per, rate) -> Excitation:
    """The chosen series on one period of the log's own grid (the whole log repeats it): its conditions,
    the limits' usage, and, if the finer grid finds a peak the search grid missed, the series scaled back."""
    t = np.arange(per) / rate
    lim = search.lim
    for _ in range(20):
        traj = nominal_motion(model, ref, t, search.p)
        d = traj["q"] - q0
        over = max(float(np.max(np.where(d >= 0, d / (lim.hi - q0), -d / (q0 - lim.lo)))),
                   float(np.max(np.abs(traj["dq"]) / lim.v)), float(np.max(np.abs(traj["u"]) / lim.u)))
        if over <= 1.0:
            break
        ref = FourierReference(q0, ref.a * 0.999 / over, ref.b * 0.999 / over, ref.w0)
    joints = joint_conditions(traj, search.v_c, search.cubic)
    first = regressor_condition(nominal_motion(model, first, t, search.p), search.v_c, search.cubic)
    settings = {"v_c": search.v_c, "cubic": search.cubic, "velocity_share": VELOCITY_SHARE,
                "torque_share": TORQUE_SHARE, "position_margin": POSITION_MARGIN, "rate": rate}
    return Excitation(ref, float(np.max(joints)), first, joints, usage(traj, q0, lim), periods * per / rate, f0,
                      periods, search.evaluations, settings)
