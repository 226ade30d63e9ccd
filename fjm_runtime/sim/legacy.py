"""The former loop (``simulate(..., loop='legacy')``): one RK4 step per sample, ``[x; z]`` integrated together.

Kept only so that the batch engine (:mod:`fjm_runtime.batch`), which still folds
:func:`fjm_runtime.sim.step.symbolic_closed_loop_rk4`, can be compared with a single run of the
same loop until it folds the sample step of :mod:`fjm_runtime.sim.sample_step`. It integrates the
plant at the control period and the controller state continuously (which a digital controller
cannot do); no sensor model, no delay. Every runner returns ``t, X, Z, U, S, Yh, R``.
"""
from __future__ import annotations

import numpy as np

from .rk4 import rk4_step
from .step import assemble, build_fused_step, casadi_functions, check_divergence

__all__ = ["LEGACY_LOOPS"]


def run_python(model, controller, reference, p_true, x, z, dt, n_steps, progress, max_state):
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


def run_fused(model, controller, reference, p_true, x0, z0, dt, n_steps, progress, max_state):
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



def run_compiled(model, controller, reference, p_true, x, z, dt, n_steps, progress, max_state):
    """The former closed loop in C (:func:`fjm_runtime.sim.compiled.run_compiled`); no progress."""
    from .compiled import run_compiled as compiled_loop
    return compiled_loop(model, controller, reference, p_true, x, z, dt, n_steps, max_state)


#: The former runners by backend name,
#: ``(model, controller, reference, p_true, x0, z0, dt, n_steps, progress, max_state) -> (t, X, Z, U, S, Yh, R)``.
LEGACY_LOOPS = {"python": run_python, "casadi": run_fused, "compiled": run_compiled}
