"""Test helpers for the sampled loop: a controller spy and a plain RK4 (no fjm code)."""
from __future__ import annotations

import numpy as np


class Spy:
    """Wraps a controller; records every measurement the law is given."""

    def __init__(self, inner):
        self.inner, self.seen = inner, []
        for name in ("sensing", "p_nom", "n", "n_states", "model"):
            setattr(self, name, getattr(inner, name))

    def evaluate(self, t, m, z, r):
        self.seen.append(np.array(m, dtype=float))
        return self.inner.evaluate(t, m, z, r)

    def state_derivative(self, *a):
        return self.inner.state_derivative(*a)

    def initial_state(self, *a):
        return self.inner.initial_state(*a)


def rk4(f, x, h, steps):
    """``steps`` classical RK4 steps of ``x' = f(x)`` of size ``h``."""
    for _ in range(steps):
        k1 = f(x); k2 = f(x + 0.5 * h * k1); k3 = f(x + 0.5 * h * k2); k4 = f(x + h * k3)  # noqa: E702
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x
