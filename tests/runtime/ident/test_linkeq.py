"""The link equation's joint torque (fjm_runtime.ident.linkeq) from first principles.

On link1 it is the pendulum's ``J_l ddq + M g0 L sin q`` written out here; on planar2, at states whose
link acceleration is the plant's own (``f``'s link rows with the motors away from the links), it is the
spring torque ``K (q_m - q)`` that drives the links.
"""
import numpy as np

import fjm_runtime
from fjm_runtime.drives import linear_stiffness_indices
from fjm_runtime.ident.linkeq import link_torque
from support.numerics import random_params, random_state


def test_link1_is_the_pendulum_equation(link1):
    rng = np.random.default_rng(4)
    p = link1.params_array({"J_l": 0.7, "M": 1.3, "L": 0.9})
    q, dq, ddq = (rng.uniform(-2.0, 2.0, (50, 1)) for _ in range(3))
    tau = link_torque(link1, q, dq, ddq, p)
    assert tau.shape == (50, 1)
    assert np.allclose(tau, 0.7 * ddq + 1.3 * 9.8 * 0.9 * np.sin(q), rtol=1e-12, atol=1e-12)


def test_planar2_under_its_own_acceleration_is_the_spring_torque():
    m = fjm_runtime.load("planar2")
    rng = np.random.default_rng(9)
    n = m.n
    p = random_params(m, rng)
    X = np.array([random_state(m, rng) for _ in range(20)])
    ddq = np.array([np.asarray(m.f(x, p), dtype=float).ravel()[n:2 * n] for x in X])
    tau = link_torque(m, X[:, :n], X[:, n:2 * n], ddq, p)
    spring = p[linear_stiffness_indices(m, "the spring torque")] * (X[:, 2 * n:3 * n] - X[:, :n])
    assert np.max(np.abs(tau - spring)) < 1e-9 * max(1.0, np.max(np.abs(spring)))
