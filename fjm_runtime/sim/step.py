"""The closed loop's shared pieces: the CasADi step, metrics and the divergence check.

Used by :mod:`fjm_runtime.simulate` (python and fused CasADi loops),
:mod:`fjm_runtime.compiled` (the step in C) and :mod:`fjm_runtime.batch` (the
step folded over samples with running metrics), so each exists once and no two
of those modules import each other in a circle.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class SimulationDivergedError(RuntimeError):
    """The closed loop produced a non-finite (or absurdly large) state."""

    def __init__(self, t: float, message: str):
        super().__init__(message)
        self.t = t


@dataclass
class Metrics:
    """Per-run figures of merit (link-position error ``e1 = q_l - q_d``, worst joint).

    Attributes
    ----------
    final_error : float
        ``max_i |e1_i(t_end)|`` in rad.
    rms_error : float
        RMS of ``e1`` over the whole run (all joints), rad.
    rms_error_second_half : float
        RMS of ``e1`` over ``t >= t_end / 2``, rad.
    max_abs_u : float
        ``max |u|`` in N m.
    reaching_time : float
        First time after which ``|s_i| <= delta_i`` for all joints until the end
        (s); ``inf`` if the boundary layer is not reached and kept.
    total_variation_u : float
        ``sum_k |u_{k+1} - u_k|`` (summed over joints), N m: the chattering measure.
    """

    final_error: float
    rms_error: float
    rms_error_second_half: float
    max_abs_u: float
    reaching_time: float
    total_variation_u: float

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def metrics_from_sums(t, final_error, sum_e2, sum_e2_half, max_abs_u, last_outside, total_variation_u,
                      n: int) -> dict:
    """The :class:`Metrics` fields from running sums (one run, or arrays of runs: the batch).

    Parameters
    ----------
    t : ndarray, shape (N+1,)
        Sample times.
    final_error, sum_e2, sum_e2_half, max_abs_u, total_variation_u : float or ndarray, shape (B,)
        ``max_i |e1_i(t_end)|``, ``sum e1^2`` over all samples and joints, the same over
        ``t >= t_end / 2``, ``max |u|``, ``sum_k |u_{k+1} - u_k|``.
    last_outside : float or ndarray, shape (B,)
        Last sample index with some ``|s_i| > delta_i`` (-1: never).
    n : int
        Number of joints.

    Returns
    -------
    dict str -> float or ndarray
    """
    N = t.size - 1
    n_half = int(np.count_nonzero(t >= 0.5 * t[-1]))
    last = np.asarray(last_outside, dtype=float)
    reaching = np.where(last >= N, np.inf, np.where(last < 0, t[0], t[np.minimum(last + 1, N).astype(int)]))
    return {"final_error": final_error,
            "rms_error": np.sqrt(np.asarray(sum_e2) / ((N + 1) * n)),
            "rms_error_second_half": np.sqrt(np.asarray(sum_e2_half) / (n_half * n)),
            "max_abs_u": max_abs_u,
            "reaching_time": reaching,
            "total_variation_u": total_variation_u}


def compute_metrics(t, e1, u, s, delta) -> Metrics:
    """Compute :class:`Metrics` from sampled trajectories.

    Parameters
    ----------
    t : ndarray, shape (N+1,)
    e1, u, s : ndarray, shape (N+1, n)
    delta : ndarray, shape (n,)
    """
    half = t >= 0.5 * t[-1]
    outside = np.flatnonzero(np.any(np.abs(s) > delta, axis=1))
    m = metrics_from_sums(t, np.max(np.abs(e1[-1])), np.sum(e1 ** 2), np.sum(e1[half] ** 2),
                          np.max(np.abs(u)), outside[-1] if outside.size else -1,
                          np.sum(np.abs(np.diff(u, axis=0))), e1.shape[1])
    return Metrics(**{k: float(v) for k, v in m.items()})


def check_divergence(t_next, W, U, max_state: float) -> None:
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
    """
    W = np.asarray(W)
    bad = ~np.all(np.isfinite(W), axis=1) | (np.max(np.abs(W), axis=1) > max_state)
    if np.any(bad):
        j = int(np.argmax(bad))
        tb = float(t_next[j])
        raise SimulationDivergedError(
            tb, f"simulation diverged at t = {tb:.4f} s: state "
            f"{'is not finite' if not np.all(np.isfinite(W[j])) else f'exceeds |x| = {max_state:g}'}"
            f" (last applied torque {np.round(np.asarray(U[j]), 3).tolist()} N m)")


def casadi_functions(model):
    """The model's CasADi Functions ``f, g, T, alpha, beta`` of ``(x, p)``, or ``None``.

    Uses the loader's ``Model.functions`` mapping (name -> casadi.Function).
    """
    fns = getattr(model, "functions", None)
    if fns is None:
        fns = getattr(model, "casadi_functions", None)
    if fns is None:
        return None
    try:
        import casadi as ca
        out = {k: fns[k] for k in ("f", "g", "T", "alpha", "beta")}
    except (KeyError, TypeError, ImportError):
        return None
    return out if all(isinstance(v, ca.Function) for v in out.values()) else None


def symbolic_closed_loop_rk4(fns, controller, w, r0, rh, r1, p, nx: int, n: int, dt: float):
    """One closed-loop step in CasADi (SX or MX): sample the controller, RK4 of ``[x; z]`` under held u.

    Parameters
    ----------
    fns : dict
        CasADi Functions ``f``, ``g``, ``T``, ``alpha``, ``beta`` of ``(x, p)``.
    w : casadi SX/MX, shape (nx + nz, 1)
        Plant state and controller state.
    r0, rh, r1 : shape (5n, 1)
        Reference rows at t, t + dt/2, t + dt.
    p : shape (n_params, 1)
        TRUE plant parameters.

    Returns
    -------
    w_next : shape (nx + nz, 1)
    out : dict
        The controller sample of :meth:`symbolic_evaluate` (``u``, ``u_cmd``, ``s``, ``y_hat``).
    """
    import casadi as ca
    nz = int(w.shape[0]) - nx
    x, z = w[:nx], w[nx:]
    out = controller.symbolic_evaluate(x, z, r0, fns)
    u = out["u"]

    def rhs(wk, rk):
        xk, zk = wk[:nx], wk[nx:]
        dx = fns["f"](xk, p) + ca.mtimes(ca.reshape(fns["g"](xk, p), nx, n), u)
        if nz == 0:
            return dx
        return ca.vertcat(dx, controller.symbolic_state_derivative(xk, zk, rk, out))

    k1 = rhs(w, r0)
    k2 = rhs(w + 0.5 * dt * k1, rh)
    k3 = rhs(w + 0.5 * dt * k2, rh)
    k4 = rhs(w + dt * k3, r1)
    return w + (dt / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4), out


def build_fused_step(fns, controller, nx, n, nz, n_par, dt):
    """One closed-loop step (controller sample + RK4 of [x; z] under held u) as a CasADi Function."""
    import casadi as ca
    w = ca.MX.sym("w", nx + nz)
    r0, rh, r1 = (ca.MX.sym(nm, 5 * n) for nm in ("r0", "rh", "r1"))
    p = ca.MX.sym("p", n_par)
    w_next, out = symbolic_closed_loop_rk4(fns, controller, w, r0, rh, r1, p, nx, n, dt)
    u = out["u"]
    step = ca.Function("closed_loop_step", [w, r0, rh, r1, p],
                       [w_next, ca.vertcat(u, out["s"], out["y_hat"])])
    try:
        step = step.expand()
    except Exception:  # noqa: BLE001 - keep the MX graph if it cannot be expanded
        pass
    return step


def assemble(controller, t, W, aux, R, nx: int, n: int):
    """Sampled trajectories from the states ``W`` (N+1, nw) and the step outputs ``aux`` (N, 6n).

    The law is evaluated once more at ``t_end`` for the last row of ``u``, ``s``, ``y_hat``.

    Returns
    -------
    t, X, Z, U, S, Yh, R
        As :func:`fjm_runtime.simulate.simulate` stores them.
    """
    X, Z = W[:, :nx], W[:, nx:]
    last = controller.evaluate(t[-1], X[-1], Z[-1], R[-1])
    U = np.vstack([aux[:, :n], last.u[None]])
    S = np.vstack([aux[:, n:2 * n], last.s[None]])
    Yh = np.concatenate([aux[:, 2 * n:].reshape(-1, 4, n), last.y_hat[None]])
    return t, X, Z, U, S, Yh, R
