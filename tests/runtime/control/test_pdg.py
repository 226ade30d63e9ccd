"""The motor-side PD law with gravity compensation (fjm_runtime.control.pdg): the contract the simulators rely on."""
from __future__ import annotations

import numpy as np

import fjm_runtime
from fjm_runtime.control.factory import make_controller
from fjm_runtime.drives import linear_stiffness_indices


def test_pdg_controller_holds_gravity_at_the_set_point():
    m = fjm_runtime.load("planar2")
    n = m.n
    p = m.params_array(None)
    K = p[linear_stiffness_indices(m, "torque sensing")]
    q_d = np.array([0.4, -0.3])
    # gravity from the plant: relaxed spring at rest, ddq = -D^-1 G
    x0 = np.concatenate([q_d, np.zeros(n), q_d, np.zeros(n)])
    G = -m.inertia(x0, p) @ m.f(x0, p)[n:2 * n]
    c = make_controller("pdg", m, {}, k_p=5 * K, k_d=np.sqrt(K), u_max=1e3)
    assert (c.sensing, c.measurement_size, c.n_states, c.law_kind) == ("state", 4 * n, 0, "pdg")
    r = np.zeros((5, n))
    r[0] = q_d
    x_star = np.concatenate([q_d, np.zeros(n), q_d + G / K, np.zeros(n)])
    smp = c.evaluate(0.0, x_star, np.zeros(0), r)
    assert np.allclose(smp.u, G, rtol=1e-10, atol=0) and np.allclose(smp.s, 0.0, atol=1e-12)
    assert np.max(np.abs(m.xdot(x_star, smp.u, p))) < 1e-8
    # motor side only: moving the links leaves u unchanged; moving the motor does not
    x_l = x_star.copy()
    x_l[:2 * n] += 0.1
    assert np.allclose(c.evaluate(0.0, x_l, np.zeros(0), r).u, smp.u, rtol=0, atol=1e-12)
    x_m = x_star.copy()
    x_m[2 * n] += 0.01
    assert abs(c.evaluate(0.0, x_m, np.zeros(0), r).u[0] - smp.u[0] + 0.01 * 5 * K[0]) < 1e-9 * K[0]
