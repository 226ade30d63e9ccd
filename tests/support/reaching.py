"""Reaching checks shared by the tune tests: a state from nominal coordinates, sgn(s) s' on a trajectory.

Independent of fjm_runtime.analysis.certificates.certify: Newton with finite-difference Jacobians of the model's
``T``; ``s'`` by central differences of the simulated ``s``.
"""
from __future__ import annotations

import numpy as np


def state_at(model, nominal, y_hat):
    """x with T(x; p_nom) = y_hat (Newton on the motor half, independent of fjm_runtime.analysis.certificates.certify)."""
    n = model.n
    pn = model.params_array(nominal)
    x = np.concatenate([y_hat[:2 * n], y_hat[:2 * n]])
    for _ in range(20):
        r = model.T(x, pn)[2 * n:] - y_hat[2 * n:]
        J = np.empty((2 * n, 2 * n))
        for j in range(2 * n):
            dx = np.zeros(4 * n); dx[2 * n + j] = 1e-6
            J[:, j] = (model.T(x + dx, pn)[2 * n:] - model.T(x - dx, pn)[2 * n:]) / 2e-6
        x[2 * n:] -= np.linalg.solve(J, r)
    assert np.max(np.abs(model.T(x, pn) - y_hat)) < 1e-8
    return x


def trajectory_check(res, E, eta, c):
    """``sgn(s) s' <= -eta / 2`` on a simulated run wherever the errors are in the box ``E`` and
    ``|s| > delta`` (at least 20 such samples, else the check would be vacuous); the worst value."""
    s = res.s
    dt = res.t[1] - res.t[0]
    sdot = (s[2:] - s[:-2]) / (2 * dt)
    e = res.y_hat - res.ref[:, :4]
    inside = np.all(np.abs(e) <= np.asarray(E)[None, :, None] * (1 + 1e-9), axis=1)      # (N+1, n)
    ok = inside[1:-1] & inside[2:] & inside[:-2]
    out = (np.abs(s[1:-1]) > res.delta) & (np.abs(s[2:]) > res.delta) & (np.abs(s[:-2]) > res.delta)
    mask = ok & out
    assert mask.sum() >= 20, f"only {mask.sum()} samples outside the layer inside the box: vacuous check"
    worst = np.max(np.sign(s[1:-1][mask]) * sdot[mask])
    assert worst <= -0.5 * eta, f"sgn(s) s' = {worst:.3g} > -eta/2 on the trajectory"
    return worst
