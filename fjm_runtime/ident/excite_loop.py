"""An excitation's files (the CSV a robot plays, its JSON) and the loop it is played with.

The loop is a PD on the motor angle plus the nominal feedforward,
``u = u_ff + k_p (q_m_d - q_m) + k_d (dq_m_d - dq_m)`` with ``q_m_d``, ``dq_m_d``, ``u_ff`` the nominal
model's motion along the excitation (:func:`fjm_runtime.ident.excite.nominal_motion`, the columns of the
excitation CSV) and ``k_p = J_m w^2``, ``k_d = 2 zeta w J_m`` on the nominal rotor inertia: a motor-side
loop, stable whatever the spring (Tomei's PD), that a torque-controlled arm can run from the CSV alone.
:func:`check_in_closed_loop` runs it on the NOMINAL model in :func:`fjm_runtime.sim.simulate` (the
sampled loop, 1 kHz, the ``franka_like`` sensor: quantized encoders, differentiated velocities, the
1000 N m/s torque-rate limit) and reports the tracking and the limits' usage.

The CSV (:func:`write_excitation`, :data:`COLUMNS`): ``t`` and, per joint, ``q_d``, ``dq_d``, ``ddq_d``
(rad, rad/s, rad/s^2), ``q_m_d``, ``dq_m_d`` (the motor on the link side), ``tau_J_d``, ``u_ff`` (N m) over
the whole excitation with both ends (``N + 1`` rows); the JSON beside it holds the Fourier coefficients
(:func:`load_excitation`), the settings, the condition numbers and the limits' usage.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import numpy as np

from ..control.laws import ControlSample
from ..control.references import Reference
from ..model import command_name
from ..validation import FjmValueError
from .excite import Excitation, FourierReference, drive_parameters, limits_of, nominal_motion, usage

__all__ = ["COLUMNS", "PD_OMEGA", "PD_ZETA", "pd_gains", "motor_pd", "LoopRows", "MotorPDFeedforward",
           "check_in_closed_loop", "load_excitation", "read_excitation", "write_excitation"]

#: Natural frequency (rad/s) and damping of the motor-side PD on the nominal rotor inertia.
PD_OMEGA, PD_ZETA = 30.0, 0.7


def pd_gains(model, p=None, omega: float = PD_OMEGA, zeta: float = PD_ZETA):
    """``(k_p, k_d)``, each (n,): ``J_m w^2`` and ``2 zeta w J_m`` at parameters ``p`` (default: nominal)."""
    Jm = drive_parameters(model, model.params_array(p))["J_m"]
    return Jm * omega ** 2, 2.0 * zeta * omega * Jm


def motor_pd(u_ff, q_m_d, dq_m_d, q_m, dq_m, k_p, k_d):
    """The loop's torque (module docstring); any matching shapes."""
    return u_ff + k_p * (q_m_d - q_m) + k_d * (dq_m_d - dq_m)


class LoopRows(Reference):
    """The loop's reference rows ``[q_d; q_m_d; dq_m_d; u_ff; 0]`` (5, n) at time ``t`` (the sample step passes
    these rows to :class:`MotorPDFeedforward`; row 0 is the link reference, so errors are ``q - q_d``)."""

    def __init__(self, model, ref, p=None):
        self.model, self.ref, self.n = model, ref, int(model.n)
        self.p = model.params_array(p)

    def sample(self, t) -> np.ndarray:
        tr = nominal_motion(self.model, self.ref, np.asarray(t, dtype=float).reshape(-1), self.p)
        return np.stack([tr["q"], tr["qm"], tr["dqm"], tr["u"], np.zeros_like(tr["q"])], axis=1)

    def __call__(self, t: float) -> np.ndarray:
        return self.sample([t])[0]


class MotorPDFeedforward:
    """:func:`motor_pd` as a controller of :func:`fjm_runtime.sim.simulate` (state sensing, stateless), with
    the rows of :class:`LoopRows` as its reference; ``u_max`` (n,) clips the torque (None: none)."""

    sensing, n_states, law_kind = "state", 0, None

    def __init__(self, model, k_p, k_d, u_max=None):
        self.n = int(model.n)
        self.k_p, self.k_d = np.asarray(k_p, dtype=float), np.asarray(k_d, dtype=float)
        self.u_max = None if u_max is None else np.asarray(u_max, dtype=float)
        self.delta = np.full(self.n, np.inf)
        self.p_nom = model.params_array()

    def initial_state(self, t0, x0, r0) -> np.ndarray:
        return np.zeros(0)

    def evaluate(self, t, x, z, r) -> ControlSample:
        n, r = self.n, np.asarray(r, dtype=float).reshape(5, self.n)
        x = np.asarray(x, dtype=float)
        cmd = motor_pd(r[3], r[1], r[2], x[2 * n:3 * n], x[3 * n:], self.k_p, self.k_d)
        u = cmd if self.u_max is None else np.clip(cmd, -self.u_max, self.u_max)
        y = np.concatenate([x[:2 * n], np.zeros(2 * n)]).reshape(4, n)
        return ControlSample(u, cmd, r[1] - x[2 * n:3 * n], y, y - r[:4], u != cmd)

    def state_derivative(self, t, x, z, r, sample) -> np.ndarray:
        return np.zeros(0)

    def symbolic_evaluate(self, x, z, r, fns=None) -> dict:
        import casadi as ca
        n = self.n
        cmd = motor_pd(r[3 * n:4 * n], r[n:2 * n], r[2 * n:3 * n], x[2 * n:3 * n], x[3 * n:4 * n],
                       ca.DM(self.k_p), ca.DM(self.k_d))
        u = cmd if self.u_max is None else ca.fmin(ca.fmax(cmd, -ca.DM(self.u_max)), ca.DM(self.u_max))
        return {"u": u, "u_cmd": cmd, "s": r[n:2 * n] - x[2 * n:3 * n], "y_hat": ca.vertcat(x[:2 * n], ca.DM.zeros(2 * n))}

    def symbolic_state_derivative(self, x, z, r, sample):
        import casadi as ca
        return ca.DM(0, 1)


def check_in_closed_loop(model, exc: Excitation, sensor: str = "franka_like", seed: int = 0,
                         rate: Optional[float] = None) -> dict:
    """Play ``exc`` on the NOMINAL model under :class:`MotorPDFeedforward` (module docstring).

    Returns
    -------
    dict
        ``max_error`` (rad, worst joint's largest ``|q - q_d|``), ``usage`` (:func:`~fjm_runtime.ident.excite.usage`
        of the simulated motion and torque), ``peak_torque`` (n,), ``sensor``; ``diverged`` (str) instead when the
        run diverged.
    """
    from ..sim.sensor import sensor_from_spec
    from ..sim.simulate import simulate
    from ..sim.step import SimulationDivergedError
    rate = float(exc.settings.get("rate", 1000.0) if rate is None else rate)
    ref = exc.reference
    k_p, k_d = pd_gains(model)
    ctrl = MotorPDFeedforward(model, k_p, k_d, model.effort_limits)
    start = nominal_motion(model, ref, np.zeros(1), model.params_array())      # at rest holding gravity
    x0 = np.concatenate([start[k][0] for k in ("q", "dq", "qm", "dqm")])
    try:
        res = simulate(model, ctrl, LoopRows(model, ref), duration=exc.duration, dt=1.0 / rate, x0=x0,
                       sensor=sensor_from_spec(sensor, seed=seed))
    except SimulationDivergedError as err:
        return {"diverged": str(err), "sensor": sensor}
    n = int(model.n)
    motion = {"q": res.x[:, :n], "dq": res.x[:, n:2 * n], "u": res.u}
    lim = limits_of(model, ref.q0, np.inf)
    return {"max_error": float(np.max(np.abs(res.e1))), "usage": usage(motion, ref.q0, lim),
            "peak_torque": np.max(np.abs(res.u), axis=0), "sensor": sensor}


# -- files ------------------------------------------------------------------------------------------------

#: Column groups of the excitation CSV, one column ``<group>_<i>`` per joint.
COLUMNS = ("q_d", "dq_d", "ddq_d", "q_m_d", "dq_m_d", "tau_J_d", "u_ff")


def _plain(v):
    """``v`` with numpy arrays and scalars as JSON values (recursively)."""
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (np.ndarray, np.generic)):
        return v.tolist()
    return v


def write_excitation(path, exc: Excitation, model, rate: Optional[float] = None, check: Optional[dict] = None) -> Path:
    """CSV ``t`` and :data:`COLUMNS` (the nominal model's motion, ``u_ff`` its feedforward) over
    ``exc.duration`` with both ends (``N + 1`` rows), and ``<path>.json``: the coefficients, the settings,
    the condition numbers, the limits' usage and the closed-loop ``check``."""
    p = Path(path)
    rate = float(exc.settings["rate"] if rate is None else rate)
    N = int(round(exc.duration * rate))
    t = np.arange(N + 1) / rate
    tr = nominal_motion(model, exc.reference, t, model.params_array())
    data = [tr["q"], tr["dq"], tr["ddq"], tr["qm"], tr["dqm"], tr["tau"], tr["u"]]
    n = int(model.n)
    head = ["t"] + [f"{c}_{i + 1}" for c in COLUMNS for i in range(n)]
    np.savetxt(p, np.column_stack([t] + data), delimiter=",", header=",".join(head), comments="", fmt="%.17g")
    meta = {"model": model.name, "duration": exc.duration, "rate": rate, "periods": exc.periods,
            "base_freq": exc.base_freq, "condition": exc.condition, "first_draw_condition": exc.first,
            "joint_conditions": exc.joints.tolist(), "usage": _plain(exc.usage), "settings": exc.settings,
            "check": _plain(check or {}), "fourier": exc.reference.as_dict()}
    p.with_suffix(".json").write_text(json.dumps(meta, indent=1) + "\n")
    return p


def read_excitation(path, model) -> dict:
    """An excitation CSV as arrays: ``t`` (N,) and each of :data:`COLUMNS` (N, n) (what a robot's loop plays).

    Raises
    ------
    FjmValueError
        A missing column or a non-finite value (one line naming the file and the column).
    """
    p, n = Path(path), int(model.n)
    try:
        with open(p) as fh:
            head = fh.readline().strip().split(",")
        data = np.loadtxt(p, delimiter=",", skiprows=1, ndmin=2)
    except (OSError, ValueError) as exc:
        raise FjmValueError(f"excitation {p}: cannot read it ({exc}); expected the CSV of `fjm excite`") from None
    out = {"t": data[:, head.index("t")] if "t" in head else None}
    for c in COLUMNS:
        cols = [f"{c}_{i + 1}" for i in range(n)]
        missing = [k for k in cols if k not in head]
        if missing or out["t"] is None:
            raise FjmValueError(f"excitation {p}: no column {(missing or ['t'])[0]}; expected t and "
                                f"{', '.join(c + '_<i>' for c in COLUMNS)} for i = 1..{n} (`fjm excite {command_name(model)}`)")
        out[c] = data[:, [head.index(k) for k in cols]]
    if not np.all(np.isfinite(data)):
        raise FjmValueError(f"excitation {p}: row {int(np.argmax(~np.isfinite(data).all(axis=1))) + 1}: not a "
                            "finite number; expected the CSV of `fjm excite`")
    return out


def load_excitation(path) -> FourierReference:
    """The :class:`FourierReference` of a ``fjm excite`` output (its ``.json`` beside the CSV)."""
    p = Path(path)
    meta_path = p if p.suffix == ".json" else p.with_suffix(".json")
    try:
        f = json.loads(meta_path.read_text())["fourier"]
        return FourierReference(f["q0"], f["a"], f["b"], f["w0"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise FjmValueError(f"excitation {meta_path}: cannot read the Fourier coefficients ({exc}); expected the "
                            "JSON that `fjm excite` writes beside its CSV") from None
