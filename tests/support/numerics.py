"""Numerical helpers shared by the derivation tests (finite differences, random states)."""

from __future__ import annotations

import numpy as np

ALL_MODELS = ("link1",) + tuple(f"planar{n}" for n in range(1, 8)) + ("elbow3", "panda")


def directional(fun, x, v, rel_step=1e-3):
    """Derivative of ``fun`` at ``x`` along ``v``: ``(d fun/dx) v``.

    Fourth-order central differences along the *direction* v, with the step
    scaled by |x| and |v|: the state blocks (angles, velocities, and the
    vector fields' entries) differ by orders of magnitude, so a fixed
    per-coordinate step would be wrong for some of them.
    """
    x = np.asarray(x, float)
    v = np.asarray(v, float)
    nv = np.linalg.norm(v)
    if nv == 0:
        return np.zeros_like(np.asarray(fun(x), float))
    h = rel_step * max(1.0, np.linalg.norm(x)) / nv
    f = lambda s: np.asarray(fun(x + s * v), float)
    return (8 * (f(h) - f(-h)) - (f(2 * h) - f(-2 * h))) / (12 * h)


def random_state(model, rng, scale=0.8):
    """A state with angles O(1) rad, rates O(1) rad/s, spring deflection O(0.1) rad."""
    n = model.n
    q = rng.uniform(-scale, scale, n) * np.pi / 2
    dq = rng.uniform(-1, 1, n)
    qm = q + rng.uniform(-0.1, 0.1, n)
    dqm = dq + rng.uniform(-0.5, 0.5, n)
    return np.concatenate([q, dq, qm, dqm])


def random_params(model, rng, damping=True):
    """Physical parameters: defaults perturbed by up to +-30 %, some motor damping."""
    p = dict(model.default_params)
    for k, v in p.items():
        if k == "g0":
            continue
        if k.startswith("B"):
            p[k] = rng.uniform(0.0, 0.5) if damping else 0.0
        else:
            p[k] = v * rng.uniform(0.7, 1.3)
    for k in list(p):  # keep each centre of mass on its link
        if k.startswith("r") and k[1:].isdigit():
            p[k] = min(p[k], p["l" + k[1:]])
    return np.array([p[k] for k in model.param_names])


def rk4(fun, x0, dt, steps):
    """Classic fixed-step RK4 of ``x' = fun(x)``; returns (steps + 1, nx)."""
    xs = np.empty((steps + 1, len(x0)))
    xs[0] = x = np.asarray(x0, float)
    for k in range(steps):
        k1 = fun(x)
        k2 = fun(x + dt / 2 * k1)
        k3 = fun(x + dt / 2 * k2)
        k4 = fun(x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        xs[k + 1] = x
    return xs


def energy_drifts(model, steps_dt, duration, seed=2):
    """Relative energy drift of an undamped, unforced run (RK4) per step size in ``steps_dt``.

    From a random state and random parameters without damping (``seed``), ``duration`` s with each
    step size; the drift is ``max |E - E_0| / max(1, |E_0|)`` over about 50 samples of the run.
    """
    rng = np.random.default_rng(seed)
    p = random_params(model, rng, damping=False)
    x0 = random_state(model, rng)
    drifts = []
    for dt in steps_dt:
        steps = int(round(duration / dt))
        xs = rk4(lambda x: model.f(x, p), x0, dt, steps)
        E = np.array([model.energy(x, p) for x in xs[:: max(1, steps // 50)]])
        drifts.append(np.max(np.abs(E - E[0])) / max(1.0, abs(E[0])))
    return drifts
