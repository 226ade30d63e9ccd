"""Closed-loop simulation: RK4 plant with TRUE parameters, controller with NOMINAL ones.

The torque is computed once per step and held (zero-order hold, like a digital
controller sampling at ``1/dt``); the plant state and the controller's internal
state are integrated together by classical RK4.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from ..sim.metrics import Metrics, compute_metrics
from ..sim.rk4 import rk4_step
from ..sim.step import SimulationDivergedError, assemble, build_fused_step, casadi_functions, check_divergence

__all__ = ["BACKENDS", "Metrics", "SimulationDivergedError", "SimulationResult", "simulate", "stderr_progress"]


@dataclass
class SimulationResult:
    """Trajectories and metrics of one closed-loop run (``N + 1`` samples, ``n`` joints).

    Attributes
    ----------
    t : ndarray, shape (N+1,)
    x : ndarray, shape (N+1, 4n)
        Plant state ``[q_l; dq_l; q_m; dq_m]``.
    z : ndarray, shape (N+1, n_states)
        Controller state.
    u : ndarray, shape (N+1, n)
        Applied torque held over ``[t_k, t_k + dt)`` (the last row is the law at ``t_end``).
    y : ndarray, shape (N+1, 4, n)
        True linearizing coordinates ``T(x; p_true)`` (link angle, velocity,
        acceleration, jerk).
    y_hat : ndarray, shape (N+1, 4, n)
        The controller's estimate ``T(x; p_nom)``.
    ref : ndarray, shape (N+1, 5, n)
        Reference and its derivatives.
    s : ndarray, shape (N+1, n)
        Sliding variable as computed by the controller.
    e1 : ndarray, shape (N+1, n)
        Link-position error ``q_l - q_d`` (rad).
    delta : ndarray, shape (n,)
        Boundary-layer width used for the reaching time.
    metrics : Metrics
    """

    t: np.ndarray
    x: np.ndarray
    z: np.ndarray
    u: np.ndarray
    y: np.ndarray
    y_hat: np.ndarray
    ref: np.ndarray
    s: np.ndarray
    e1: np.ndarray
    delta: np.ndarray
    metrics: Metrics


def _true_params_array(model, true_params) -> np.ndarray:
    p = {} if true_params is None else true_params
    try:
        return np.asarray(model.params_array(p, arg="true_params"), dtype=float)
    except TypeError:  # a model whose params_array has no ``arg`` keyword
        try:
            return np.asarray(model.params_array(p), dtype=float)
        except ValueError as exc:
            raise ValueError(f"true_params: {exc}") from exc


def _check_state(x, nx, field):
    a = np.asarray(x, dtype=float)
    if a.shape != (nx,):
        raise ValueError(f"{field} with shape {a.shape}: expected ({nx},) = [q_l; dq_l; q_m; dq_m]")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{field} = {a.tolist()}: expected finite values")
    return a


def simulate(model, controller, reference, *, duration: float, dt: float = 1e-3,
             true_params=None, x0=None, progress: Optional[Callable[[float], None]] = None,
             max_state: float = 1e6, backend: str = "auto") -> SimulationResult:
    """Simulate the closed loop with the TRUE plant and the controller's NOMINAL model.

    Parameters
    ----------
    model : Model
        ``fjm_runtime.load(name)``.
    controller : SlidingModeController
        Holds its own nominal parameters (see :mod:`fjm_runtime.control.laws`).
    reference : Reference
        ``reference(t) -> (5, n)``.
    duration : float
        Simulated time in s, > 0.
    dt : float
        RK4 step and control sample time in s, > 0 (default 1 ms).
    true_params : dict or array_like, optional
        Plant parameters (default: model defaults).
    x0 : array_like, shape (4n,), optional
        Initial state; default: at rest with ``q_l = q_m = q_d(0)``.
    progress : callable, optional
        Called as ``progress(fraction)`` about 20 times during the run.
    max_state : float
        ``|x|`` beyond this counts as divergence.
    backend : {'auto', 'casadi', 'compiled', 'python'}
        ``'python'``: a plain loop calling ``model.f``, ``model.g`` and the
        controller's :meth:`evaluate` (works for any controller object).
        ``'casadi'``: the same zero-order-hold RK4 closed loop composed from the
        model's CasADi Functions into one ``mapaccum`` (10-50x faster; needs
        the controller's ``symbolic_evaluate``). ``'auto'`` picks ``'casadi'``
        when possible. ``'compiled'``: that same closed loop code-generated to C,
        compiled once and cached (:mod:`fjm_runtime.sim.compiled`). All give the
        same trajectories to rounding.

    Returns
    -------
    SimulationResult

    Raises
    ------
    ValueError
        Bad durations, steps, shapes or parameters (the message names the field).
    SimulationDivergedError
        The state became non-finite or exceeded ``max_state``; ``.t`` is the time.
    """
    p_true, x, z, n_steps = _initial_conditions(model, controller, reference, duration, dt, true_params, x0)
    name = _choose_backend(backend, model, controller)
    t, X, Z, U, S, Yh, R = BACKENDS[name](model, controller, reference, p_true, x, z, dt, n_steps,
                                          progress, max_state)
    return _finish(model, controller, p_true, t, X, Z, U, S, Yh, R)


def _initial_conditions(model, controller, reference, duration, dt, true_params, x0):
    """Check the run's arguments; ``(p_true, x0, z0, n_steps)`` (x0 default: at rest on the reference)."""
    n, nx = int(model.n), int(model.nx)
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"duration = {duration!r}: expected a finite value > 0 s")
    if not (np.isfinite(dt) and 0 < dt <= duration):
        raise ValueError(f"dt = {dt!r}: expected a finite step with 0 < dt <= duration")
    if getattr(reference, "n", n) != n:
        raise ValueError(f"reference.n = {reference.n}: expected {n} joints for this model")
    if getattr(controller, "n", n) != n:
        raise ValueError(f"controller.n = {controller.n}: expected {n} joints for this model")
    p_true = _true_params_array(model, true_params)
    if not np.all(np.isfinite(p_true)):
        raise ValueError(f"true_params = {p_true.tolist()}: expected finite values")
    r0 = np.asarray(reference(0.0), dtype=float)
    if r0.shape != (5, n):
        raise ValueError(f"reference(0) with shape {r0.shape}: expected (5, {n})")
    if x0 is None:
        x0 = np.zeros(nx)
        x0[0:n] = r0[0]
        x0[2 * n:3 * n] = r0[0]
    x = _check_state(x0, nx, "x0")
    z = np.asarray(controller.initial_state(0.0, x, r0), dtype=float)
    return p_true, x, z, int(round(duration / dt))


def _choose_backend(backend: str, model, controller) -> str:
    """The key of :data:`BACKENDS` that runs ``backend`` (``'auto'``: casadi when possible)."""
    if backend not in ("auto",) + tuple(BACKENDS):
        raise ValueError(f"backend = {backend!r}: expected 'auto', 'casadi', 'compiled' or 'python'")
    if backend in ("compiled", "python"):
        return backend
    fused_ok = casadi_functions(model) is not None and hasattr(controller, "symbolic_evaluate")
    if backend == "casadi" and not fused_ok:
        raise ValueError("backend = 'casadi': the model exposes no CasADi Functions or the controller "
                         "has no symbolic_evaluate; use backend='python'")
    return "casadi" if fused_ok else "python"


def _run_python(model, controller, reference, p_true, x, z, dt, n_steps, progress, max_state):
    """A plain loop calling ``model.f``, ``model.g`` and the controller; ``t, X, Z, U, S, Yh, R``."""
    n, nx, nz = int(model.n), int(model.nx), z.size
    t = dt * np.arange(n_steps + 1)
    X = np.empty((n_steps + 1, nx)); Z = np.empty((n_steps + 1, nz))
    U = np.empty((n_steps + 1, n)); S = np.empty((n_steps + 1, n))
    Yh = np.empty((n_steps + 1, 4, n)); R = np.empty((n_steps + 1, 5, n))
    report_every = max(1, n_steps // 20)

    for k in range(n_steps + 1):
        tk = t[k]
        rk = reference(tk)
        sample = controller.evaluate(tk, x, z, rk)
        X[k], Z[k], U[k], S[k], Yh[k], R[k] = x, z, sample.u, sample.s, sample.y_hat, rk
        if k == n_steps:
            break
        u = sample.u

        def rhs(tau, w, u=u, sample=sample):
            xs = w[:nx]
            dx = np.asarray(model.f(xs, p_true), dtype=float).reshape(nx) + \
                np.asarray(model.g(xs, p_true), dtype=float).reshape(nx, n) @ u
            if nz == 0:
                return dx
            dz = controller.state_derivative(tau, xs, w[nx:], reference(tau), sample)
            return np.concatenate([dx, dz])

        w = rk4_step(rhs, tk, np.concatenate([x, z]), dt)
        check_divergence([tk + dt], w[None], u[None], max_state)
        x, z = w[:nx], w[nx:]
        if progress is not None and (k + 1) % report_every == 0:
            progress((k + 1) / n_steps)
    return t, X, Z, U, S, Yh, R


def _run_compiled(model, controller, reference, p_true, x, z, dt, n_steps, progress, max_state):
    """The closed loop in C (:mod:`fjm_runtime.sim.compiled`, compiled once and cached); no progress."""
    from ..sim.compiled import run_compiled
    return run_compiled(model, controller, reference, p_true, x, z, dt, n_steps, max_state)


def _finish(model, controller, p_true, t, X, Z, U, S, Yh, R) -> SimulationResult:
    n = int(model.n)
    Y = _true_outputs(model, p_true, X)
    e1 = X[:, :n] - R[:, 0]
    delta = np.asarray(getattr(controller, "delta", np.full(n, np.inf)), dtype=float)
    metrics = compute_metrics(t, e1, U, S, delta)
    return SimulationResult(t=t, x=X, z=Z, u=U, y=Y, y_hat=Yh, ref=R, s=S, e1=e1,
                            delta=delta, metrics=metrics)


_MAPPED: dict = {}


def _mapped(fn, count: int):
    """``fn.map(count)``, built once per (function, count): building it costs ~10 ms a call."""
    key = (id(fn), int(count))
    hit = _MAPPED.get(key)
    if hit is None or hit[0] is not fn:
        if len(_MAPPED) > 64:
            _MAPPED.clear()
        hit = _MAPPED[key] = (fn, fn.map(int(count)))
    return hit[1]


def _true_outputs(model, p_true, X):
    """``T(x; p_true)`` for every row of ``X``, shape (N+1, 4, n)."""
    n = int(model.n)
    fns = casadi_functions(model)
    if fns is not None:
        T_all = _mapped(fns["T"], X.shape[0])
        return np.asarray(T_all(X.T, p_true)).T.reshape(-1, 4, n)
    return np.stack([np.asarray(model.T(xk, p_true), dtype=float).reshape(4, n) for xk in X])


def _run_fused(model, controller, reference, p_true, x0, z0, dt, n_steps, progress, max_state):
    """The zero-order-hold RK4 loop as one CasADi ``mapaccum`` (in chunks for progress); ``t, X, ..., R``."""
    nx, n, nz = int(model.nx), int(model.n), z0.size
    fns = casadi_functions(model)
    step = build_fused_step(fns, controller, nx, n, nz, p_true.size, dt)
    t = dt * np.arange(n_steps + 1)
    r_half = reference.sample(0.5 * dt * np.arange(2 * n_steps + 1)).reshape(2 * n_steps + 1, 5 * n)
    R = r_half[0::2].reshape(n_steps + 1, 5, n)
    n_chunks = 20 if (progress is not None and n_steps >= 200) else 1
    chunk = -(-n_steps // n_chunks)
    runners = {}
    W = np.empty((n_steps + 1, nx + nz))
    aux = np.empty((n_steps, 6 * n))
    W[0] = np.concatenate([x0, z0])
    k = 0
    while k < n_steps:
        m = min(chunk, n_steps - k)
        if m not in runners:
            runners[m] = step.mapaccum("closed_loop", m)
        cols = slice(2 * k, 2 * (k + m) + 1)
        rr = r_half[cols]
        w_out, a_out = runners[m](W[k], rr[0:-1:2].T, rr[1::2].T, rr[2::2].T, p_true)
        w_out, a_out = np.asarray(w_out).T, np.asarray(a_out).T
        W[k + 1:k + m + 1], aux[k:k + m] = w_out, a_out
        check_divergence(t[k + 1:k + m + 1], w_out, a_out[:, :n], max_state)
        k += m
        if progress is not None:
            progress(k / n_steps)
    return assemble(controller, t, W, aux, R, nx, n)


#: The closed-loop runners by ``backend`` name, each
#: ``(model, controller, reference, p_true, x0, z0, dt, n_steps, progress, max_state) -> (t, X, Z, U, S, Yh, R)``.
BACKENDS = {"python": _run_python, "casadi": _run_fused, "compiled": _run_compiled}


def stderr_progress(label: str) -> Callable[[float], None]:
    """A ``progress`` callback printing ``label: NN %`` to stderr."""
    def report(fraction: float) -> None:
        print(f"\r{label}: {100 * fraction:3.0f} %", end="\n" if fraction >= 1 else "",
              file=sys.stderr, flush=True)
    return report
