"""Classical fixed-step fourth-order Runge-Kutta integration.

The simulator integrates the plant state and the controller's internal state
together as one vector, so everything here works on flat 1-D arrays.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

Rhs = Callable[[float, np.ndarray], np.ndarray]


def rk4_step(rhs: Rhs, t: float, w: np.ndarray, dt: float) -> np.ndarray:
    """Advance ``w' = rhs(t, w)`` by one classical RK4 step.

    Parameters
    ----------
    rhs : callable
        ``rhs(t, w) -> (m,)`` array, the time derivative.
    t : float
        Time at the start of the step.
    w : ndarray, shape (m,)
        State at time ``t``.
    dt : float
        Step size (> 0).

    Returns
    -------
    ndarray, shape (m,)
        State at time ``t + dt``.
    """
    half = 0.5 * dt
    k1 = rhs(t, w)
    k2 = rhs(t + half, w + half * k1)
    k3 = rhs(t + half, w + half * k2)
    k4 = rhs(t + dt, w + dt * k3)
    return w + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def integrate(rhs: Rhs, w0, t0: float, dt: float, n_steps: int):
    """Integrate ``w' = rhs(t, w)`` with ``n_steps`` RK4 steps of size ``dt``.

    Parameters
    ----------
    rhs : callable
        ``rhs(t, w) -> (m,)``.
    w0 : array_like, shape (m,)
        Initial state.
    t0 : float
        Initial time.
    dt : float
        Step size, > 0.
    n_steps : int
        Number of steps, >= 0.

    Returns
    -------
    t : ndarray, shape (n_steps + 1,)
        Time grid ``t0 + k dt``.
    w : ndarray, shape (n_steps + 1, m)
        States on the grid.

    Raises
    ------
    ValueError
        If ``dt <= 0``, ``n_steps < 0`` or ``w0`` is not a finite 1-D array.
    """
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt = {dt!r}: expected a finite step size > 0")
    if int(n_steps) != n_steps or n_steps < 0:
        raise ValueError(f"n_steps = {n_steps!r}: expected an integer >= 0")
    w = np.asarray(w0, dtype=float)
    if w.ndim != 1 or not np.all(np.isfinite(w)):
        raise ValueError(f"w0 with shape {w.shape}: expected a finite 1-D array")
    n_steps = int(n_steps)
    out = np.empty((n_steps + 1, w.size))
    out[0] = w
    for k in range(n_steps):
        w = rk4_step(rhs, t0 + k * dt, w, dt)
        out[k + 1] = w
    return t0 + dt * np.arange(n_steps + 1), out
