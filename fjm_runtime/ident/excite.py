"""Excitation trajectories for identification: a finite Fourier series per joint (``fjm excite``).

Per joint ``i`` the link reference is ``q_d(t) = q0_i + sum_h [a_ih sin(h w0 t) + b_ih (cos(h w0 t) - 1)]``
(period ``2 pi / w0``; ``q_d(0) = q0``), with all four derivatives in closed form, so the
sliding-mode laws can track it. The coefficients are drawn at random and kept when they make the
identification best conditioned: for each candidate, the motor and spring regressors of
:mod:`fjm_runtime.ident.identify` are built from the trajectory the NOMINAL model needs (the
flat-output inverse: ``tau_J = D ddq + h``, ``q_m = q + K^-1 tau_J``, ``u = J_m ddq_m + B_m dq_m + tau_J``)
and the worst joint's condition number is the cost, under the joint position, velocity and torque
limits. The winner is then run in closed loop on the nominal model (:func:`check_in_closed_loop`).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from ..control.references import Reference
from ..validation import FjmValueError
from .linkeq import link_torque

__all__ = ["FourierReference", "Excitation", "design_excitation", "load_excitation", "nominal_motion",
           "regressor_condition", "write_excitation", "check_in_closed_loop"]


class FourierReference(Reference):
    """``q_d`` of the module docstring; ``a``, ``b`` shape (n, H), ``q0`` (n,), ``w0`` rad/s."""

    def __init__(self, q0, a, b, w0: float):
        self.q0 = np.asarray(q0, dtype=float).reshape(-1)
        self.a, self.b = np.atleast_2d(np.asarray(a, dtype=float)), np.atleast_2d(np.asarray(b, dtype=float))
        self.w0, self.n = float(w0), int(self.q0.size)
        self.h = np.arange(1, self.a.shape[1] + 1, dtype=float)

    def sample(self, t) -> np.ndarray:
        """``(N, 5, n)``: ``q_d`` and its four derivatives at the times ``t``."""
        t = np.asarray(t, dtype=float).reshape(-1)
        wt = t[:, None] * (self.h * self.w0)[None, :]                  # (N, H)
        s, c = np.sin(wt), np.cos(wt)
        out = np.empty((t.size, 5, self.n))
        for k in range(5):
            wk = (self.h * self.w0) ** k
            # d^k/dt^k of sin and cos: rotate by k quarter turns
            ds = [s, c, -s, -c][k % 4]
            dc = [c, -s, -c, s][k % 4]
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


@dataclass
class Excitation:
    """A chosen excitation: the reference, its cost and how much of each limit it uses."""

    reference: FourierReference
    condition: float
    usage: dict
    candidates: int


def nominal_motion(model, ref: FourierReference, t: np.ndarray, p) -> dict:
    """The motion that makes the links follow ``ref`` at parameters ``p`` (module docstring): ``q, dq, qm,
    dqm, ddqm, tau, u, phi``, each shape (N, n) at the times ``t`` (uniform)."""
    R = ref.sample(t)
    q, dq, ddq = R[:, 0], R[:, 1], R[:, 2]
    tau = link_torque(model, q, dq, ddq, p)
    names, n = list(model.param_names), model.n
    Jm = np.array([p[names.index("J_m" if n == 1 and "J_m" in names else f"Jm{i + 1}")] for i in range(n)])
    dt = t[1] - t[0]
    phi = spring_deflection(model, p, tau)
    dphi = np.gradient(phi, dt, axis=0)
    ddphi = np.gradient(dphi, dt, axis=0)
    qm, dqm, ddqm = q + phi, dq + dphi, ddq + ddphi
    return {"q": q, "dq": dq, "qm": qm, "dqm": dqm, "ddqm": ddqm, "tau": tau, "u": Jm * ddqm + tau, "phi": phi}


def spring_deflection(model, p, tau) -> np.ndarray:
    """``phi`` with ``psi(phi) = tau``: ``tau / K`` for a linear spring; Newton on ``k1 phi + k3 phi^3``."""
    names, n = list(model.param_names), model.n
    if n == 1 and {"k1", "k3"} <= set(names) and "K" not in names:
        k1, k3 = p[names.index("k1")], p[names.index("k3")]
        phi = tau / k1
        for _ in range(30):                                   # psi' >= k1 > 0: monotone, converges
            phi = phi - (k1 * phi + k3 * phi ** 3 - tau) / (k1 + 3 * k3 * phi ** 2)
        return phi
    K = np.array([p[names.index("K" if n == 1 and "K" in names else f"K{i + 1}")] for i in range(n)])
    return tau / K


def regressor_condition(traj: dict, v_c: float = 0.01) -> float:
    """Worst joint's condition number of the scaled motor regressor ``[ddq_m, dq_m, tanh(dq_m / v_c)]``
    and spring regressor ``[phi, 1]``."""
    worst = 1.0
    for i in range(traj["q"].shape[1]):
        for A in (np.column_stack([traj["ddqm"][:, i], traj["dqm"][:, i], np.tanh(traj["dqm"][:, i] / v_c)]),
                  np.column_stack([traj["phi"][:, i], np.ones_like(traj["phi"][:, i])])):
            A = A / np.maximum(np.linalg.norm(A, axis=0), 1e-300)
            sv = np.linalg.svd(A, compute_uv=False)
            worst = max(worst, float(sv[0] / max(sv[-1], 1e-300)))
    return worst


def _limits(model, q0, amplitude):
    n = model.n
    pos = getattr(model, "position_limits", None)
    vel = getattr(model, "velocity_limits", None)
    eff = getattr(model, "effort_limits", None)
    lo = q0 - amplitude if pos is None else np.maximum(q0 - amplitude, np.asarray(pos)[:, 0] + 0.05)
    hi = q0 + amplitude if pos is None else np.minimum(q0 + amplitude, np.asarray(pos)[:, 1] - 0.05)
    return lo, hi, (np.full(n, np.inf) if vel is None else 0.5 * np.asarray(vel)), \
        (np.full(n, np.inf) if eff is None else 0.8 * np.asarray(eff))


def _draw(rng, n, harmonics, q0, lo, hi):
    a = rng.standard_normal((n, harmonics)) / np.arange(1, harmonics + 1) ** 1.5
    b = rng.standard_normal((n, harmonics)) / np.arange(1, harmonics + 1) ** 1.5
    span = np.minimum(q0 - lo, hi - q0)                                # room on the tighter side
    scale = span / (2.0 * (np.abs(a) + np.abs(b)).sum(axis=1))         # |q_d - q0| <= span
    return a * scale[:, None], b * scale[:, None]


def design_excitation(model, duration: float, *, q0=None, amplitude: float = 0.5, harmonics: int = 5,
                      base_freq: float = 0.2, candidates: int = 40, seed: int = 0, v_c: float = 0.01,
                      rate: float = 1000.0) -> Excitation:
    """Draw ``candidates`` Fourier series and keep the best-conditioned one within the limits.

    Parameters
    ----------
    model : Model
    duration : float
        Length of the excitation, s (a whole number of base periods is best).
    q0 : array_like, shape (n,), optional
        Centre posture (default: zeros, or the middle of the joint ranges).
    amplitude : float
        Largest excursion from ``q0``, rad.
    harmonics, base_freq : int, float
        Number of harmonics, base frequency (Hz).

    Raises
    ------
    FjmValueError
        When no candidate stays within the velocity and torque limits.
    """
    n = model.n
    if not (np.isfinite(duration) and duration > 0 and harmonics >= 1 and base_freq > 0 and candidates >= 1
            and amplitude > 0):
        raise FjmValueError(f"excite: duration {duration!r}, harmonics {harmonics!r}, base frequency "
                            f"{base_freq!r}, candidates {candidates!r}, amplitude {amplitude!r}; expected all > 0")
    pos = getattr(model, "position_limits", None)
    if q0 is None:
        q0 = np.zeros(n) if pos is None else np.mean(np.asarray(pos), axis=1)
    q0 = np.asarray(q0, dtype=float)
    lo, hi, vmax, umax = _limits(model, q0, amplitude)
    p = model.params_array()
    t = np.arange(0.0, duration, 1.0 / rate)
    rng = np.random.default_rng(seed)
    best = None
    for _ in range(candidates):
        a, b = _draw(rng, n, harmonics, q0, lo, hi)
        ref = FourierReference(q0, a, b, 2 * np.pi * base_freq)
        traj = nominal_motion(model, ref, t, p)
        use_v = np.max(np.abs(traj["dq"]), axis=0) / vmax
        use_u = np.max(np.abs(traj["u"]), axis=0) / umax
        if np.any(use_v > 1) or np.any(use_u > 1):
            continue
        cond = regressor_condition(traj, v_c)
        if best is None or cond < best.condition:
            best = Excitation(ref, cond, {"velocity": float(np.max(use_v)), "torque": float(np.max(use_u))},
                              candidates)
    if best is None:
        raise FjmValueError(f"excite: none of {candidates} trajectories of amplitude {amplitude:g} rad at "
                            f"{base_freq:g} Hz x {harmonics} harmonics stays within half the velocity and 80 % of "
                            "the torque limits; expected a smaller --amplitude or --base-freq")
    return best


def write_excitation(path, exc: Excitation, model, duration: float, rate: float = 1000.0) -> Path:
    """CSV ``t, q_d_<i>, dq_d_<i>, ddq_d_<i>, u_ff_<i>`` (nominal feedforward) plus ``<path>.json``
    with the series' coefficients (what :func:`load_excitation` reads)."""
    p = Path(path)
    t = np.arange(0.0, duration, 1.0 / rate)
    traj = nominal_motion(model, exc.reference, t, model.params_array())
    R = exc.reference.sample(t)
    n = model.n
    cols = ["t"] + [f"{k}_{i + 1}" for k in ("q_d", "dq_d", "ddq_d", "u_ff") for i in range(n)]
    data = np.column_stack([t, R[:, 0], R[:, 1], R[:, 2], traj["u"]])
    np.savetxt(p, data, delimiter=",", header=",".join(cols), comments="", fmt="%.17g")
    meta = {"model": model.name, "duration": duration, "rate": rate, "condition": exc.condition,
            "usage": exc.usage, "fourier": exc.reference.as_dict()}
    p.with_suffix(".json").write_text(json.dumps(meta, indent=1) + "\n")
    return p


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


def check_in_closed_loop(model, ref: FourierReference, duration: float, rate: float = 1000.0,
                         gains: Optional[dict] = None):
    """Run ``ref`` on the NOMINAL model under the integral SMC (state sensing); returns the result."""
    from ..control.factory import make_controller
    from ..sim.simulate import simulate
    kw = {"lam": 10.0, "k_s": 20.0, "delta": 20.0, **(gains or {})}
    eff = getattr(model, "effort_limits", None)
    if eff is not None:
        kw["u_max"] = np.asarray(eff, dtype=float)
    ctrl = make_controller("ismc", model, model.default_params, **kw)
    return simulate(model, ctrl, ref, duration=duration, dt=1.0 / rate)
