"""sim/rest.py: the state at rest holding gravity, for every model form.

At the returned state with the motor torque equal to the spring torque ``u = K (q_m - q)`` the whole
state derivative ``f + g u`` vanishes (links and motors at rest): checked for the single link (whose
stiffness is named ``K``), a planar chain, the Panda and the complete Panda (coupled inertia 2n x 2n).
"""
from __future__ import annotations

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.sim.rest import rest_state
from fjm_runtime.drives import linear_stiffness_indices


@pytest.mark.parametrize("name", ["link1", "planar2", "panda", "panda_complete"])
def test_rest_state_is_an_equilibrium_under_the_spring_torque(name):
    m = fjm_runtime.load(name)
    n = int(m.n)
    p = np.asarray(m.params_array({}), dtype=float)
    q = np.linspace(0.2, -0.5, n)
    x = rest_state(m, q, p)
    assert np.array_equal(x[:n], q) and not np.any(x[n:2 * n]) and not np.any(x[3 * n:])
    u = p[linear_stiffness_indices(m, "the spring torque")] * (x[2 * n:3 * n] - x[:n])
    assert np.max(np.abs(u)) > 1e-3                      # gravity does load the springs here
    xdot = np.asarray(m.f(x, p), dtype=float).ravel() + np.asarray(m.g(x, p), dtype=float) @ u
    assert np.max(np.abs(xdot)) < 1e-9 * (1.0 + np.max(np.abs(u)))
