"""The regrouped inertials (derive/emit/regroup.py) and the CRBA on them (derive/emit/crba.py): same torques, same D.

The recursion's own tests (test_rnea_jets: AD of the programme, finite differences of Pinocchio)
run on the regrouped bodies; these check the regrouping by itself, against the bodies as the
model states them.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from derive.emit.dynamics import _converter, _stated_body_numbers
from derive.emit.regroup import regroup
from derive.emit.rnea_jets import rnea_jets
from derive.registry import build


@pytest.mark.parametrize("name", ["panda", "baxter"])
def test_regrouped_bodies_give_the_stated_bodies_torques_and_derivatives(name):
    m = build(name)
    n = m.n
    q, dq, a, ar = (ca.SX.sym(s, n) for s in ("q", "dq", "a", "ar"))
    p = ca.SX.sym("p", len(m.params))
    stated = _stated_body_numbers(m, _converter(m, q, dq, p))
    g0 = p[list(m.param_names).index("g0")]
    f = ca.Function("f", [q, dq, a, ar, p],
                    rnea_jets(stated, q, [dq, a, ar], g0, 2) + rnea_jets(regroup(stated), q, [dq, a, ar], g0, 2))
    rng = np.random.default_rng(5)
    pv = np.array([pp.default for pp in m.params])
    if "m_load" in m.param_names:  # a payload off the flange axis: symbolic inertials on the last body
        names = list(m.param_names)
        pv[names.index("m_load")], pv[names.index("x_load")], pv[names.index("z_load")] = 2.0, 0.05, 0.1
    for _ in range(3):
        out = [np.asarray(o, float).ravel() for o in f(*[rng.uniform(-2, 2, n) for _ in range(4)], pv)]
        for k in range(3):
            scale_k = max(1.0, np.max(np.abs(out[k])))
            assert np.max(np.abs(out[k] - out[3 + k])) < 1e-12 * scale_k, (name, k)


def test_each_regrouped_body_keeps_no_mass_no_axial_moment_and_no_yy_inertia():
    for name in ("panda", "baxter"):
        m = build(name)
        n = m.n
        conv = _converter(m, ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("p", len(m.params)))
        for R0, p, mass, h, I, parent in regroup(_stated_body_numbers(m, conv)):
            assert mass == 0.0 and h[2] == 0.0 and I[1][1] == 0.0


def test_a_point_mass_on_the_axis_moves_to_the_parent_whole():
    # body 1 hangs at p = (0.3, 0, 0) from the root; its only inertial is a point mass at its origin
    R0 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    zero3 = [[0.0] * 3 for _ in range(3)]
    root = (R0, (0.0, 0.0, 0.0), 0.0, [0.0, 0.0, 0.0], zero3, -1)
    tip = (R0, (0.3, 0.0, 0.0), 2.0, [0.0, 0.0, 0.0], zero3, 0)
    new_root, new_tip = regroup([root, tip])
    assert new_tip[2] == 0.0 and new_tip[3] == [0.0, 0.0, 0.0]
    # on the root body, it is the point mass 2 kg at (0.3, 0, 0): h = m p, I = m (|p|^2 E - p p^T); the
    # root's own carried part (mass, h_z, I_yy) then went to the base
    assert new_root[3] == [0.6, 0.0, 0.0]
    # I = diag(0, 0.18, 0.18) before the root's own I_yy = 0.18 leaves it (from I_xx too)
    assert np.allclose(np.array(new_root[4], float), np.diag([-0.18, 0.0, 0.18]), rtol=0, atol=1e-15)


@pytest.mark.parametrize("name", ["panda", "baxter"])
def test_the_crba_on_regrouped_bodies_is_the_models_joint_inertia(name):
    from derive.emit.crba import joint_inertia
    from derive.emit.dynamics import programme
    m = build(name)
    n = m.n
    q, dq, p = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("p", len(m.params))
    stated = _stated_body_numbers(m, _converter(m, q, dq, p))
    f = ca.Function("f", [q, p], [joint_inertia(regroup(stated), q), programme(m)(q, dq, ca.SX.zeros(n), p)[0]])
    pv = np.array([pp.default for pp in m.params])
    if "m_load" in m.param_names:
        names = list(m.param_names)
        pv[names.index("m_load")], pv[names.index("y_load")], pv[names.index("z_load")] = 1.5, -0.04, 0.1
    rng = np.random.default_rng(8)
    for _ in range(3):
        ours, model_D = (np.asarray(x, float) for x in f(rng.uniform(-2.5, 2.5, n), pv))
        assert np.max(np.abs(ours - model_D)) < 1e-13 * max(1.0, np.max(np.abs(model_D)))


def test_the_crba_refuses_bodies_that_still_carry_mass():
    from derive.emit.crba import joint_inertia
    R0 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="regrouped bodies"):
        joint_inertia([(R0, (0.0, 0.0, 0.0), 1.0, [0.0] * 3, [[0.0] * 3] * 3, -1)], [0.0])
