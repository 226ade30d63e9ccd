"""The spatial chain builder (derive/spatial/spatial.py): equal to the planar formulas where they
apply, right for general axes and rotations, energy-conserving, deterministic."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import fjm_runtime
from derive.emit.functions import QUANTITIES, build_functions
from derive.core.linearize import linearize
from derive.spatial.chain import planar_description, rpy_matrix
from derive.planar.planar import make_planar
from derive.spatial.spatial import make_spatial
from derive.spatial.spatial_params import elastic_params
from derive.spatial.urdf import load_urdf
from support.numerics import energy_drifts, random_state

from support.paths import REPO  # noqa: E402
NAMES = [q for q, _ in QUANTITIES]


def spatial_functions(desc, name, K, Jm, Bm, g0):
    n = len(desc.revolute_names)
    return build_functions(linearize(make_spatial(desc, name, elastic_params(n, K, Jm, Bm, g0), "test")))


def test_planar3_through_the_spatial_builder_equals_planar3():
    """planar3's description (joints about z, links along -y, base turned so that -z is the
    plane's -y) gives the same eight functions as the generated planar3, to 1e-12."""
    ref = fjm_runtime.load("planar3")
    d = ref.default_params
    n = 3
    desc = planar_description(n, [d[f"m{i}"] for i in (1, 2, 3)], [d[f"l{i}"] for i in (1, 2, 3)],
                              [d[f"r{i}"] for i in (1, 2, 3)], [d[f"I{i}"] for i in (1, 2, 3)])
    K, Jm, Bm = ([d[f"{g}{i}"] for i in (1, 2, 3)] for g in ("K", "Jm", "Bm"))
    fs = spatial_functions(desc, "sp3", K, Jm, Bm, d["g0"])
    p = np.array(K + Jm + Bm + [d["g0"]])
    rng = np.random.default_rng(33)
    worst = 0.0
    for _ in range(20):
        x = random_state(ref, rng, scale=2.0)
        for q in NAMES:
            a = np.array(fs[q](x, p)).squeeze()
            b = getattr(ref, q)(x, None)
            err = np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b)))
            worst = max(worst, err)
            assert err <= 1e-12, (q, err)


def test_planar2_other_parameters_and_damping():
    """Same with non-default masses, lengths, centres of mass, inertias and motor damping."""
    vals = {"m1": 2.0, "m2": 0.7, "l1": 0.8, "l2": 0.6, "r1": 0.3, "r2": 0.45, "I1": 0.05, "I2": 0.02,
            "K1": 300.0, "K2": 120.0, "Jm1": 1.5, "Jm2": 0.4, "Bm1": 0.3, "Bm2": 0.1, "g0": 9.81}
    planar = build_functions(linearize(make_planar(2, defaults=vals)))
    pp = np.array([p.default for p in make_planar(2, defaults=vals).params])
    desc = planar_description(2, [2.0, 0.7], [0.8, 0.6], [0.3, 0.45], [0.05, 0.02])
    fs = spatial_functions(desc, "sp2", [300.0, 120.0], [1.5, 0.4], [0.3, 0.1], 9.81)
    ps = np.array([300.0, 120.0, 1.5, 0.4, 0.3, 0.1, 9.81])
    rng = np.random.default_rng(4)
    for _ in range(10):
        x = rng.uniform(-2, 2, 8)
        for q in NAMES:
            a, b = np.array(fs[q](x, ps)), np.array(planar[q](x, pp))
            assert np.max(np.abs(a - b)) <= 1e-12 * max(1.0, np.max(np.abs(b))), q


def test_rpy_matches_pinocchio():
    rng = np.random.default_rng(8)
    for _ in range(50):
        rpy = rng.uniform(-np.pi, np.pi, 3)
        np.testing.assert_allclose(rpy_matrix(rpy), pin.rpy.rpyToMatrix(*rpy), atol=1e-15)
    # multiples of pi/2 written as decimals become exact permutations
    R = rpy_matrix((1.5707963267948966, 0, -1.5707963267948966))
    assert set(np.unique(R)) <= {-1.0, 0.0, 1.0}


GENERAL = """<?xml version="1.0"?>
<robot name="general">
  <link name="base"/>
  <link name="a"><inertial><origin xyz="0.02 -0.01 0.1" rpy="0.4 -0.2 0.9"/><mass value="1.3"/>
    <inertia ixx="0.03" ixy="0.002" ixz="-0.001" iyy="0.025" iyz="0.0015" izz="0.012"/></inertial></link>
  <link name="b"><inertial><origin xyz="0.15 0.03 -0.02" rpy="-0.3 0.5 0.1"/><mass value="0.9"/>
    <inertia ixx="0.004" ixy="-0.0003" ixz="0.0002" iyy="0.02" iyz="0.0001" izz="0.019"/></inertial></link>
  <link name="c"><inertial><origin xyz="0.01 0.02 0.08"/><mass value="0.4"/>
    <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.001"/></inertial></link>
  <joint name="ja" type="revolute"><origin xyz="0.1 0 0.2" rpy="0.1 0.2 0.3"/>
    <parent link="base"/><child link="a"/><axis xyz="0.3 -0.5 0.8"/>
    <limit effort="1" lower="-3" upper="3" velocity="1"/></joint>
  <joint name="jb" type="revolute"><origin xyz="0 0.05 0.3" rpy="-0.7 0.0 1.1"/>
    <parent link="a"/><child link="b"/><axis xyz="-1 0 0"/>
    <limit effort="1" lower="-3" upper="3" velocity="1"/></joint>
  <joint name="jc" type="revolute"><origin xyz="0.3 0 0" rpy="0 1.5707963267948966 0"/>
    <parent link="b"/><child link="c"/><axis xyz="0 -1 0"/>
    <limit effort="1" lower="-3" upper="3" velocity="1"/></joint>
</robot>
"""


def test_general_axes_and_rotations_match_pinocchio(tmp_path):
    """Oblique and negative axes, arbitrary rpy on joints and inertials: D, f against Pinocchio."""
    path = tmp_path / "general.urdf"
    path.write_text(GENERAL)
    desc = load_urdf(path, "base", "c").description
    K, Jm = [300.0, 200.0, 100.0], [0.2, 0.1, 0.05]
    fs = spatial_functions(desc, "general", K, Jm, [0.1, 0.2, 0.3], 9.81)
    p = np.array(K + Jm + [0.1, 0.2, 0.3, 9.81])
    model = pin.buildModelFromUrdf(str(path))
    model.gravity.linear[:] = [0, 0, -9.81]
    data = model.createData()
    rng = np.random.default_rng(9)
    for _ in range(50):
        x = rng.uniform(-np.pi, np.pi, 12)
        q, dq, qm = x[:3], x[3:6], x[6:9]
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        D = np.array(fs["inertia"](x, p))
        assert np.max(np.abs(D - M)) <= 1e-12 * np.max(np.abs(M))
        a = pin.aba(model, data, q, dq, np.array(K) * (qm - q))
        ddq = np.array(fs["f"](x, p)).ravel()[3:6]
        assert np.max(np.abs(ddq - a)) <= 1e-10 * np.max(np.abs(a))


@pytest.mark.parametrize("name", ["elbow3"])
def test_energy_is_conserved_without_damping_or_input(name):
    """B_m = 0, u = 0: energy drift of RK4 is O(dt^4) (halving dt: ~16x smaller)."""
    drifts = energy_drifts(fjm_runtime.load(name), (1e-3, 5e-4), 0.5)
    assert drifts[1] < 1e-7, drifts
    assert drifts[0] / max(drifts[1], 1e-300) > 8 or drifts[1] < 1e-12, drifts


def test_derive_of_a_spatial_arm_is_byte_identical_across_hash_seeds(tmp_path):
    outs, procs = [], []
    for seed in ("0", "4242"):
        out = tmp_path / f"s{seed}"
        env = dict(os.environ, PYTHONHASHSEED=seed,
                   PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        procs.append(subprocess.Popen([sys.executable, "-m", "derive", "--models", "elbow3", "--out", str(out)],
                                      cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                      text=True))
        outs.append(out / "elbow3")
    for proc in procs:
        log, _ = proc.communicate(timeout=300)
        assert proc.returncode == 0, log
    files = sorted(p.name for p in outs[0].iterdir())
    assert files == sorted(p.name for p in outs[1].iterdir()) and "manifest.json" in files
    for f in files:
        assert (outs[0] / f).read_bytes() == (outs[1] / f).read_bytes(), f
        assert (outs[0] / f).read_bytes() == (REPO / "generated" / "elbow3" / f).read_bytes(), f


def test_jacobian_form_equals_crba_rnea_form():
    """The two formulations of docs/spatial.md (CRBA + RNEA emitted, Jacobian kept for the
    comparison) give the same D, h and potential on elbow3."""
    import casadi as ca
    from derive.emit.sx import SympyToSX
    from derive.spatial.spatial_jacobian import make_spatial_jacobian
    desc = load_urdf(REPO / "derive/robots/elbow3/elbow3.urdf", "base_link", "tool0").description
    P = elastic_params(3, [500.0] * 3, [0.2] * 3, [0.0] * 3, 9.81)
    x = ca.SX.sym("x", 12)
    g0 = ca.SX.sym("g0")
    out = []
    for make in (make_spatial, make_spatial_jacobian):
        m = make(desc, "e", P, "test")
        bind = {s: x[i] for i, s in enumerate(m.state)}
        bind[m.param_symbols[-1]] = g0
        conv = SympyToSX(bind, dict(m.program.definitions))
        out.append(ca.Function("f", [x, g0], [conv(m.D), conv(m.h), conv(m.potential)]))
    rng = np.random.default_rng(12)
    for _ in range(10):
        xv = rng.uniform(-2, 2, 12)
        for a, b in zip(out[0](xv, 9.81), out[1](xv, 9.81)):
            a, b = np.array(a), np.array(b)
            assert np.max(np.abs(a - b)) <= 1e-12 * max(1.0, np.max(np.abs(b)))
