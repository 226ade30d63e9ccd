"""A two-link planar model file with a drive per joint (``[spring.default]``, ``[spring.2]``, ``[friction.1]``):
derived through the several-joint emitter, checked from first principles and against MuJoCo.

Joint 1 has the three-segment datasheet curve and motor friction, joint 2 a cubic spring and none. With
both curves made linear and no friction the model IS planar2 (f, T, alpha, beta to 1e-12); with them, the
spring functions are the laws written out, the Lie identities hold by AD of the emitted T, the torque-sensed
functions equal the state ones at the implied measurement, and MuJoCo (custom-numeric curve, polynomial
tendon, friction callback) gives the same accelerations to 1e-12.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import fjm_runtime
import mujoco  # noqa: F401 - the dev extra, as in test_mjcf.py: a missing install must fail, not skip
from derive.emit.spring import write_spring_model
from derive.core.spring import linearize_spring
from derive.model_file import parse_model_text
from support.model_files import THREE_SEGMENT_SPRING
from tests.runtime.test_arm1_hd_runtime import datasheet

TEXT = f"""
[model]
name = "planar2_hd"
links = 2

[parameters]
m1 = 4.0
m2 = 2.0

[spring.default]
{THREE_SEGMENT_SPRING}
[spring.2]
law = "cubic"
range = 0.05
k1 = 5e3
k3 = 2e7

[friction.1]
F_c = 0.6
F_s = 0.9
"""


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    root = tmp_path_factory.mktemp("planar2_hd")
    m = parse_model_text(TEXT, "planar2_hd.toml").build()
    write_spring_model(linearize_spring(m), root / "planar2_hd")
    return fjm_runtime.load(str(root / "planar2_hd")), fjm_runtime.load("planar2")


def test_the_file_gives_each_joint_its_drive(models):
    hd, _ = models
    names = list(hd.param_names)
    assert names[:8] == ["m1", "m2", "l1", "l2", "r1", "r2", "I1", "I2"]
    assert ["K_1_1", "K_2_1", "K_3_1", "T_1_1", "T_2_1", "w_blend_1", "k1_2", "k3_2"] == names[8:16]
    assert names[-4:] == ["F_c_1", "F_s_1", "v_s_1", "v_c_1"] and "K1" not in names and "K2" not in names
    assert [j["law"] for j in hd.manifest["springs"]["joints"]] == ["three_segment", "cubic"]


def test_linear_curves_without_friction_are_planar2(models):
    hd, p2 = models
    d = dict(hd.default_params, K_2_1=1.3e4, K_3_1=1.3e4, k3_2=0.0, F_c_1=0.0, F_s_1=0.0)
    pl = dict(p2.default_params, m1=4.0, m2=2.0, K1=1.3e4, K2=5e3)
    rng = np.random.default_rng(2)
    for _ in range(4):
        x = rng.uniform(-1, 1, 8)
        for name in ("f", "T", "alpha", "beta", "energy", "ad"):
            a, b = np.asarray(getattr(hd, name)(x, d)), np.asarray(getattr(p2, name)(x, pl))
            assert np.max(np.abs(a - b)) <= 1e-12 * max(1.0, np.max(np.abs(b))), name


def _state(rng):
    q = rng.uniform(-1.5, 1.5, 2)
    phi = np.array([rng.uniform(-6e-3, 6e-3), rng.uniform(-0.05, 0.05)])
    return np.concatenate([q, rng.normal(0, 1, 2), q + phi, rng.normal(0, 1, 2)])


def test_laws_lie_identities_and_the_torque_form(models):
    hd, _ = models
    d = hd.default_params
    pv = hd.params_array(d)
    rng = np.random.default_rng(3)
    x, u = ca.SX.sym("x", 8), ca.SX.sym("u", 2)
    xd = hd.functions["f"](x, pv) + ca.mtimes(hd.functions["g"](x, pv), u)
    dT = ca.Function("dT", [x, u], [ca.jtimes(hd.functions["T"](x, pv), x, xd)])
    for _ in range(6):
        s = _state(rng)
        phi = s[4:6] - s[0:2]
        psi, dpsi, _ = (np.asarray(v).ravel() for v in hd.spring_functions["spring"](phi, pv))
        want1 = datasheet(phi[0], *(d[f"{c}_1"] for c in ("K_1", "K_2", "K_3", "T_1", "T_2", "w_blend")))
        assert np.allclose([psi[0], dpsi[0]], want1, rtol=1e-12)
        assert np.allclose([psi[1], dpsi[1]], [5e3 * phi[1] + 2e7 * phi[1] ** 3, 5e3 + 6e7 * phi[1] ** 2], rtol=1e-12)
        nu = rng.normal(0, 2, 2)
        uu = np.asarray(hd.alpha(s, d)).ravel() + np.asarray(hd.beta(s, d)) @ nu
        dy = np.asarray(dT(s, uu)).ravel()
        scale = np.max(np.abs(np.asarray(dT(s, np.zeros(2))).ravel()[6:])) + 1.0
        assert np.max(np.abs(dy[6:] - nu)) <= 1e-12 * scale
        m = np.concatenate([s[:4], psi, dpsi * (s[6:] - s[2:4]), s[6:]])
        for tau, state in (("alpha_tau", "alpha"), ("beta_tau", "beta")):
            a, b = np.asarray(hd.torque_functions[tau](m, pv)), np.asarray(hd.functions[state](s, pv))
            assert np.max(np.abs(a - b)) <= 1e-9 * max(1.0, np.max(np.abs(b))), tau


def test_mujoco_accelerations_equal_fjm(models, tmp_path):
    from fjm_runtime.export.bridge import MujocoPlant
    from fjm_runtime.export.mjcf import write_mjcf
    hd, _ = models
    p = dict(hd.default_params, K_2_1=1.8e4, F_c_1=0.8, k3_2=1e7)
    path = write_mjcf(hd, tmp_path / "p2.xml", p, gear_ratio=4.0)
    plant = MujocoPlant(hd, path, p, gear_ratio=4.0)
    rng = np.random.default_rng(4)
    worst = 0.0
    for _ in range(30):
        s, u = _state(rng), rng.uniform(-30, 30, 2)
        ours, theirs = np.asarray(hd.f(s, p)).ravel() + np.asarray(hd.g(s, p)) @ u, plant.xdot(s, u)
        for block in (slice(2, 4), slice(6, 8)):
            worst = max(worst, np.max(np.abs(theirs[block] - ours[block])) / np.max(np.abs(ours[block])))
    assert worst < 1e-12, worst
