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

