"""The closed loop's shared pieces: the CasADi step, the fused step, assembly and the divergence check.

Used by :mod:`fjm_runtime.sim.simulate` (python and fused CasADi loops),
:mod:`fjm_runtime.sim.compiled` (the step in C) and :mod:`fjm_runtime.batch` (the
step folded over samples with running metrics), so each exists once and no two
of those modules import each other in a circle. The figures of merit are in
:mod:`fjm_runtime.sim.metrics`.
"""
from __future__ import annotations

import numpy as np


class SimulationDivergedError(RuntimeError):
    """The closed loop produced a non-finite (or absurdly large) state."""

    def __init__(self, t: float, message: str):
        super().__init__(message)
        self.t = t


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
        As :func:`fjm_runtime.sim.simulate.simulate` stores them.
    """
    X, Z = W[:, :nx], W[:, nx:]
    last = controller.evaluate(t[-1], X[-1], Z[-1], R[-1])
    U = np.vstack([aux[:, :n], last.u[None]])
    S = np.vstack([aux[:, n:2 * n], last.s[None]])
    Yh = np.concatenate([aux[:, 2 * n:].reshape(-1, 4, n), last.y_hat[None]])
    return t, X, Z, U, S, Yh, R
