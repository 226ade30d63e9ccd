"""The closed loop's shared pieces: the model's CasADi Functions and the divergence check.

Used by the sample step (:mod:`fjm_runtime.sim.sample_step`), its runners
(:mod:`fjm_runtime.sim.loops`, :mod:`fjm_runtime.sim.compiled`) and
:mod:`fjm_runtime.sim.simulate`, so each exists once and no two of those modules
import each other in a circle. The figures of merit are in :mod:`fjm_runtime.sim.metrics`.
"""
from __future__ import annotations

import numpy as np


class SimulationDivergedError(RuntimeError):
    """The closed loop produced a non-finite (or absurdly large) state.

    Attributes
    ----------
    t : float
        Time of the first bad state, s.
    peak_torque : ndarray, shape (n,), or None
        Largest ``|u|`` per joint applied from the start up to that state, N m (NaN where not finite).
    """

    def __init__(self, t: float, message: str, peak_torque=None):
        super().__init__(message)
        self.t = t
        self.peak_torque = peak_torque


def check_divergence(t_next, W, U, max_state: float, U_before=None) -> None:
    """Raise :class:`SimulationDivergedError` at the first row of ``W`` that is not finite or beyond ``max_state``.

    Parameters
    ----------
    t_next : ndarray, shape (N,)
        Time of each row of ``W``.
    W : ndarray, shape (N, nw)
        States after each step.
    U : ndarray, shape (N, >= n)
        Torque applied during the step (first n columns are reported).
    max_state : float
    U_before : ndarray, shape (k, n), optional
        The torques applied before these rows (the error's ``peak_torque`` covers them too).
    """
    W = np.asarray(W)
    bad = ~np.all(np.isfinite(W), axis=1) | (np.max(np.abs(W), axis=1) > max_state)
    if np.any(bad):
        j = int(np.argmax(bad))
        tb = float(t_next[j])
        U = np.asarray(U, dtype=float)
        applied = U[:j + 1] if U_before is None else np.vstack([np.asarray(U_before, dtype=float), U[:j + 1]])
        mag = np.where(np.isfinite(applied), np.abs(applied), -np.inf)
        peak = mag.max(axis=0)
        peak = np.where(np.isfinite(peak), peak, np.nan)
        raise SimulationDivergedError(
            tb, f"simulation diverged at t = {tb:.4f} s: state "
            f"{'is not finite' if not np.all(np.isfinite(W[j])) else f'exceeds |x| = {max_state:g}'}"
            f" (last applied torque {np.round(np.asarray(U[j]), 3).tolist()} N m)", peak_torque=peak)


def casadi_functions(model, names=("f", "g", "T", "alpha", "beta")):
    """The model's CasADi Functions ``names`` (default ``f, g, T, alpha, beta``) of ``(x, p)``, or ``None``.

    Uses the loader's ``Model.functions`` mapping (name -> casadi.Function). A predictor needs only
    ``("f", "g")`` (a complete model has no ``T``, ``alpha``, ``beta``).
    """
    fns = getattr(model, "functions", None)
    if fns is None:
        fns = getattr(model, "casadi_functions", None)
    if fns is None:
        return None
    try:
        import casadi as ca
        out = {k: fns[k] for k in names}
    except (KeyError, TypeError, ImportError):
        return None
    return out if all(isinstance(v, ca.Function) for v in out.values()) else None
