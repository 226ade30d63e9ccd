"""The sampled-data closed loop folded over samples, by backend (python, casadi, compiled).

Each runner folds the ONE sample step of :mod:`fjm_runtime.sim.sample_step` over the samples
``k = 0..N`` and returns ``(W, AUX)``: ``W`` (N+1, nw) the step states ``w_0..w_N`` and ``AUX``
(N+1, 6n) the step outputs ``[u; s; y_hat]`` of every sample (the state after the last sample
is discarded). The signature of every runner is
``(model, controller, layout, p_true, w0, t, R, NOISE, progress, max_state)`` with ``R``
(N+1, 5n) the reference rows and ``NOISE`` (N+1, nm) the scaled sensor noise.
"""
from __future__ import annotations

import numpy as np

from .sample_step import python_sample_step, sample_step_function
from .step_layout import StepLayout
from .step import check_divergence

__all__ = ["BACKENDS", "run_casadi", "run_compiled", "run_python"]


def run_python(model, controller, L: StepLayout, p_true, w0, t, R, NOISE, progress, max_state):
    """A plain loop through ``model.f``/``model.g`` and the controller's ``evaluate``; ``(W, AUX)``."""
    n_rows, n = t.size, L.n
    W = np.empty((n_rows, L.nw)); AUX = np.empty((n_rows, 6 * n))
    report_every = max(1, (n_rows - 1) // 20)
    w = np.asarray(w0, dtype=float)
    for k in range(n_rows):
        W[k] = w
        w_next, sample = python_sample_step(model, controller, L, w, float(t[k]), R[k], NOISE[k], p_true)
        u = np.asarray(sample.u, dtype=float)
        AUX[k] = np.concatenate([u, np.asarray(sample.s, dtype=float),
                                 np.asarray(sample.y_hat, dtype=float).reshape(-1)])
        if k == n_rows - 1:
            break
        check_divergence(t[k + 1:k + 2], w_next[None], u[None], max_state, AUX[:k, :n])
        w = w_next
        if progress is not None and (k + 1) % report_every == 0:
            progress((k + 1) / (n_rows - 1))
    return W, AUX


def run_casadi(model, controller, L: StepLayout, p_true, w0, t, R, NOISE, progress, max_state):
    """The sample step's ``mapaccum`` (in chunks for progress); ``(W, AUX)``."""
    step = sample_step_function(model, controller, L)
    n_rows, n = t.size, L.n
    n_chunks = 20 if (progress is not None and n_rows >= 200) else 1
    chunk = -(-n_rows // n_chunks)
    runners = {}
    W = np.empty((n_rows + 1, L.nw)); AUX = np.empty((n_rows, 6 * n))
    W[0] = w0
    k = 0
    while k < n_rows:
        m = min(chunk, n_rows - k)
        if m not in runners:
            runners[m] = step.mapaccum("fjm_sampled_loop", m)
        w_out, a_out = runners[m](W[k], R[k:k + m].T, NOISE[k:k + m].T, p_true)
        W[k + 1:k + m + 1], AUX[k:k + m] = np.asarray(w_out).T, np.asarray(a_out).T
        last = min(k + m, n_rows - 1)        # the state after the last sample is not checked
        if last > k:
            check_divergence(t[k + 1:last + 1], W[k + 1:last + 1], AUX[k:last, :n], max_state, AUX[:k, :n])
        k += m
        if progress is not None:
            progress(k / n_rows)
    return W[:n_rows], AUX


def run_compiled(model, controller, L: StepLayout, p_true, w0, t, R, NOISE, progress, max_state):
    """The sample step in C (:mod:`fjm_runtime.sim.compiled`, compiled once and cached); no progress."""
    from .compiled import sampled_loop_library
    loop = sampled_loop_library(model, controller, L)
    W, AUX = loop(w0, R, NOISE, p_true)
    n = L.n
    W = np.vstack([np.asarray(w0, dtype=float)[None], W])
    check_divergence(t[1:], W[1:t.size], AUX[:t.size - 1, :n], max_state)
    return W[:t.size], AUX


#: The sampled-data runners by ``backend`` name (signature in the module docstring).
BACKENDS = {"python": run_python, "casadi": run_casadi, "compiled": run_compiled}
