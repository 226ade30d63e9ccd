"""Tree-structured robots against Pinocchio on the very same URDF.

* ``baxter`` (generated: head pan and two 7-joint arms, grippers fixed in the
  trimmed URDF, merged by Pinocchio too): at 24 random states, default and
  perturbed parameters, ``inertia`` == ``crba``, the bias ``h`` recovered from
  ``f`` == ``rnea(q, dq, 0)`` and the link accelerations of ``f`` ==
  ``aba(q, dq, K (q_m - q))``, each to a relative 1e-12.
* a synthetic Y (joint 1 carries two branches, joints 2 and 3, one of them on
  an oblique axis, plus a massive link fixed to the trunk), built with
  :func:`derive.spatial.spatial.make_spatial` and converted to CasADi without the
  full derivation: D, h and the forward dynamics against Pinocchio, and the
  CRBA's tree sparsity (D_23 is exactly zero: neither joint is an ancestor of
  the other).

Pinocchio orders its joints by its own traversal of the URDF; they are mapped
by name.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin

import fjm_runtime
from derive.emit.sx import SympyToSX
from derive.spatial.spatial import make_spatial
from derive.spatial.spatial_params import elastic_params
from derive.spatial.urdf import load_urdf
from support.paths import REPO

RTOL = 1e-12

Y_URDF = """<?xml version="1.0"?>
<robot name="y3">
  <link name="base"/>
  <link name="trunk"><inertial><origin xyz="0.01 0.02 0.2" rpy="0.1 0 0.2"/><mass value="2.0"/>
    <inertia ixx="0.05" ixy="0.001" ixz="0.002" iyy="0.04" iyz="-0.001" izz="0.03"/></inertial></link>
  <link name="box"><inertial><origin xyz="0 0.05 0"/><mass value="0.7"/>
    <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.003" iyz="0" izz="0.001"/></inertial></link>
  <link name="left"><inertial><origin xyz="0.15 0 0.01" rpy="0 0.3 0"/><mass value="1.2"/>
    <inertia ixx="0.004" ixy="0.0002" ixz="0" iyy="0.02" iyz="0.0001" izz="0.02"/></inertial></link>
  <link name="right"><inertial><origin xyz="0 -0.12 0.03"/><mass value="0.9"/>
    <inertia ixx="0.01" ixy="0" ixz="0.0005" iyy="0.003" iyz="0" izz="0.011"/></inertial></link>
  <link name="left_tip"/>
  <joint name="j1" type="revolute"><origin xyz="0 0 0.1"/><parent link="base"/><child link="trunk"/>
    <axis xyz="0 0 1"/><limit effort="1" lower="-3" upper="3" velocity="1"/></joint>
  <joint name="box_fixed" type="fixed"><origin xyz="0.05 0 0.3" rpy="0 0 0.5"/><parent link="trunk"/>
    <child link="box"/></joint>
  <joint name="j2" type="revolute"><origin xyz="0.1 0.05 0.4" rpy="0.2 -0.1 0.3"/><parent link="trunk"/>
    <child link="left"/><axis xyz="0 1 0"/><limit effort="1" lower="-3" upper="3" velocity="1"/></joint>
  <joint name="j3" type="continuous"><origin xyz="-0.1 0 0.4" rpy="0 0.4 0"/><parent link="trunk"/>
    <child link="right"/><axis xyz="0.3 -0.5 0.8"/></joint>
  <joint name="left_end" type="fixed"><origin xyz="0.3 0 0"/><parent link="left"/><child link="left_tip"/></joint>
</robot>
"""


def _pinocchio(urdf, joints, g0):
    model = pin.buildModelFromUrdf(str(urdf))
    model.gravity.linear[:] = [0.0, 0.0, -g0]
    names = [model.names[j] for j in range(1, model.njoints)]
    assert sorted(names) == sorted(joints), (names, joints)
    nqs = [model.joints[j].nq for j in range(1, model.njoints)]
    order = [names.index(j) for j in joints]  # our joint i is Pinocchio's order[i]
    return model, model.createData(), order, nqs


def _to_pin(v, order):
    out = np.zeros(len(order))
    out[order] = v
    return out


def _q_pin(q_ordered, nqs):
    out = []
    for qi, nq in zip(q_ordered, nqs):
        out += [np.cos(qi), np.sin(qi)] if nq == 2 else [qi]
    return np.array(out)


def _reference(model, data, order, nqs, q, dq, tau):
    """Pinocchio's D, h and ddq, in our joint order."""
    qp, dqp = _q_pin(_to_pin(q, order), nqs), _to_pin(dq, order)
    M = pin.crba(model, data, qp)
    M = (np.triu(M) + np.triu(M, 1).T)[np.ix_(order, order)]
    b = pin.rnea(model, data, qp, dqp, np.zeros(len(q)))[order]
    a = pin.aba(model, data, qp, dqp, _to_pin(tau, order))[order]
    return M, b, a


def rel(a, b):
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / max(1e-300, np.max(np.abs(b))))


def test_baxter_matches_pinocchio_on_the_trimmed_urdf():
    m = fjm_runtime.load("baxter")
    src = m.manifest["source"]
    assert len(src["tips"]) == 3 and m.n == 15
    n = m.n
    model, data, order, nqs = _pinocchio(REPO / src["urdf"], src["joints"], m.default_params["g0"])
    rng = np.random.default_rng(15)
    worst = {"crba": 0.0, "rnea": 0.0, "aba": 0.0}
    for k in range(24):
        p = dict(m.default_params)
        if k % 2:  # other stiffnesses, motor inertias, damping and gravity too
            for key in p:
                p[key] = p[key] * rng.uniform(0.5, 2.0) if not key.startswith("Bm") else rng.uniform(0, 1)
        model.gravity.linear[:] = [0.0, 0.0, -p["g0"]]
        q, dq = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n)
        qm, dqm = q + rng.uniform(-0.05, 0.05, n), dq + rng.uniform(-0.5, 0.5, n)
        x = np.concatenate([q, dq, qm, dqm])
        K = np.array([p[f"K{i + 1}"] for i in range(n)])
        M, b, a = _reference(model, data, order, nqs, q, dq, K * (qm - q))
        D = m.inertia(x, p)
        ddq = m.f(x, p)[n:2 * n]
        h = -D @ ddq - K * (q - qm)
        worst["crba"] = max(worst["crba"], rel(D, M))
        # h is a difference of terms of size |D ddq| ~ |K (q - q_m)|: relative to the largest
        worst["rnea"] = max(worst["rnea"], float(np.max(np.abs(h - b)))
                            / max(np.max(np.abs(b)), np.max(np.abs(K * (q - qm)))))
        worst["aba"] = max(worst["aba"], rel(ddq, a))
    print({k: f"{v:.1e}" for k, v in worst.items()})
    assert max(worst.values()) <= RTOL, worst
    # the two arms do not couple through D: only through the fixed torso (nothing moves it)
    assert np.all(D[1:8, 8:] == 0) and np.all(D[0, 1:] == 0)


def test_synthetic_y_tree_matches_pinocchio(tmp_path):
    path = tmp_path / "y3.urdf"
    path.write_text(Y_URDF)
    chain = load_urdf(path, "base", ["left_tip", "right"])
    assert chain.joints == ("j1", "j2", "j3")
    params = elastic_params(3, [300.0, 200.0, 100.0], [0.2, 0.1, 0.05], [0.0] * 3, 9.81)
    fm = make_spatial(chain.description, "y3", params, "test")
    x = ca.SX.sym("x", 12)
    g0 = ca.SX.sym("g0")
    bind = {s: x[i] for i, s in enumerate(fm.state)}
    bind[fm.param_symbols[-1]] = g0
    conv = SympyToSX(bind, dict(fm.program.definitions))
    fun = ca.Function("Dh", [x, g0], [conv(fm.D), conv(fm.h)])
    assert fm.D[1, 2] == 0 and fm.D[2, 1] == 0  # j2 and j3 are on different branches
    model, data, order, nqs = _pinocchio(path, chain.joints, 9.81)
    rng = np.random.default_rng(3)
    for _ in range(20):
        q, dq, tau = rng.uniform(-np.pi, np.pi, 3), rng.uniform(-2, 2, 3), rng.uniform(-5, 5, 3)
        D, h = (np.array(v) for v in fun(np.concatenate([q, dq, q, dq]), 9.81))
        M, b, a = _reference(model, data, order, nqs, q, dq, tau)
        assert rel(D, M) <= RTOL and rel(h.ravel(), b) <= RTOL, (rel(D, M), rel(h.ravel(), b))
        assert rel(np.linalg.solve(D, tau - h.ravel()), a) <= RTOL
