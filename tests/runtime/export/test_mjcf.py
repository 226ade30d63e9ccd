"""The MJCF export checked in MuJoCo, an engine nobody here wrote.

MuJoCo's ``qacc`` from the exported file (``mj_forward`` with ``qpos``/``qvel``
from fjm's ``x`` -- rotor angle ``theta = N q_m`` -- and ``ctrl = u``) must equal
fjm's ``f + g u``: every spatial model, link1 and the planar chains, reduced and
complete, with random parameter overrides. Also: the names (the contract), the
sensors, full precision, no damping/limits/contacts, the complete model with its
rotors on the world equals the reduced one, the refusals. (A closed loop with MuJoCo
as the plant: tests/scenarios/test_mujoco_closed_loop.py.)
"""

from __future__ import annotations

import numpy as np
import pytest

import mujoco

import fjm_runtime
from fjm_runtime.cli.main import main as fjm_main
from fjm_runtime.export.bridge import MujocoPlant
from fjm_runtime.export.mjcf import mjcf_text, write_mjcf
from fjm_runtime.validation import FjmValueError

REDUCED = ["link1", "planar2", "elbow3", "panda", "baxter",  # baxter: a tree (head pan, two arms)
           "link1_hd",  # a cubic spring: MuJoCo's polynomial tendon stiffness
           "arm1_hd",  # the datasheet curve: a custom numeric and the passive callback
           "panda_hd"]  # seven datasheet curves and motor frictions through the same callback
COMPLETE = ["link1_complete", "planar2_complete", "panda_complete"]
TOL = 1e-12


def _random_params(m, rng, complete: bool):
    """Random K, J_m, B_m (and the payload where there is one; gear ratios up for complete models)."""
    p = dict(m.default_params)
    for name, v in m.default_params.items():
        if name.rstrip("0123456789") in ("K", "Bm", "B_m") or name in ("K", "k1", "k3"):
            p[name] = (v if v > 0 else 1.0) * rng.uniform(0.5, 1.5)
        elif name.rstrip("0123456789") in ("Jm", "J_m"):
            p[name] = v * rng.uniform(0.6, 1.0)  # below the default: the rotors' baked I_t >= I_a / 2 holds
        elif complete and name.rstrip("0123456789") == "N":
            p[name] = v * rng.uniform(1.0, 3.0)
    if "m_load" in p:
        p.update(m_load=1.7, x_load=0.01, y_load=-0.02, z_load=0.12)
    if "F_c" in p:  # link1_hd's motor friction: the file's custom numerics and the bridge's passive callback
        p.update(F_c=rng.uniform(0.5, 1.5), F_s=rng.uniform(0.5, 2.0), v_s=rng.uniform(0.2, 1.0),
                 v_c=rng.uniform(0.2, 1.0))
    return p


def _worst(m, plant, params, rng, count=50):
    """Worst relative error of MuJoCo's accelerations against fjm's, per block (link, motor)."""
    n = m.n
    worst = 0.0
    for _ in range(count):
        x = rng.uniform(-1.0, 1.0, m.nx)
        x[n:2 * n] *= 2.0
        u = rng.uniform(-20.0, 20.0, n)
        ours = m.f(x, params) + m.g(x, params) @ u
        theirs = plant.xdot(x, u)
        for block in (slice(n, 2 * n), slice(3 * n, 4 * n)):
            worst = max(worst, np.max(np.abs(theirs[block] - ours[block])) / np.max(np.abs(ours[block])))
        assert np.array_equal(theirs[:n], x[n:2 * n])
    return worst


@pytest.mark.parametrize("name", REDUCED + COMPLETE)
def test_qacc_equals_fjm(name, tmp_path):
    m = fjm_runtime.load(name)
    rng = np.random.default_rng(sum(map(ord, name)))
    for params in (None, _random_params(m, rng, name in COMPLETE)):
        path = write_mjcf(m, tmp_path / f"{name}.xml", params)
        plant = MujocoPlant(m, path, params)
        assert _worst(m, plant, params, rng) < TOL


def test_motor_friction_through_the_passive_callback(tmp_path):
    """link1_hd with friction, gear ratio 3: MuJoCo's qacc equals fjm's to 1e-12 with the callback the file
    asks for, and misses by the friction itself without it (the callback is what carries it)."""
    m = fjm_runtime.load("link1_hd")
    p = dict(m.default_params, F_c=0.9, F_s=1.4, v_s=0.3, v_c=0.4, B_m=0.1)
    path = write_mjcf(m, tmp_path / "hd.xml", p, gear_ratio=3.0)
    assert 'numeric name="fjm_motor_friction:joint1_rotor" data="0.9 1.4 0.3 0.4 3.0"' in path.read_text()
    plant = MujocoPlant(m, path, p, gear_ratio=3.0)
    assert _worst(m, plant, p, np.random.default_rng(9)) < TOL
    x, u = np.array([0.1, -0.3, 0.15, 0.6]), np.array([2.0])
    plant.friction = []  # the same file without the callback: the motor row misses F(dq_m) / J_m
    miss = (m.f(x, p) + m.g(x, p) @ u - plant.xdot(x, u))[3] * p["J_m"]
    v = x[3]
    assert abs(miss + (0.9 + 0.5 * np.exp(-(v / 0.3) ** 2)) * np.tanh(v / 0.4)) < 1e-12
    assert "fjm_motor_friction" not in mjcf_text(m, None)  # no friction at the defaults: no numeric


@pytest.mark.parametrize("name", ["elbow3", "planar2"])
def test_reduced_with_gear_ratio(name, tmp_path):
    """The rotor angle is N q_m: the dynamics in fjm's coordinates do not depend on N."""
    m = fjm_runtime.load(name)
    rng = np.random.default_rng(5)
    path = write_mjcf(m, tmp_path / "m.xml", gear_ratio=37.0)
    plant = MujocoPlant(m, path, gear_ratio=37.0)
    assert _worst(m, plant, None, rng, count=20) < TOL
    x, u = rng.uniform(-1, 1, m.nx), rng.uniform(-1, 1, m.n)
    plant.xdot(x, u)
    n = m.n
    rotor = [plant.mj.joint(f"{j}_rotor").qposadr[0] for j in m.manifest["source"]["joints"]] \
        if "source" in m.manifest else [plant.mj.joint(f"joint{i + 1}_rotor").qposadr[0] for i in range(n)]
    assert np.allclose(plant.data.qpos[rotor], 37.0 * x[2 * n:3 * n], rtol=1e-15, atol=0)


@pytest.mark.parametrize("reduced, complete", [("panda", "panda_complete"), ("planar2", "planar2_complete")])
def test_complete_with_rotors_on_the_world_is_the_reduced_model(reduced, complete, tmp_path):
    mr, mc = fjm_runtime.load(reduced), fjm_runtime.load(complete)
    N = np.array([mc.default_params[f"N{i + 1}"] for i in range(mc.n)])
    world = tmp_path / "world.xml"
    world.write_text(mjcf_text(mc, rotor_mount="world"))
    plain = write_mjcf(mr, tmp_path / "reduced.xml", gear_ratio=N)
    onlink = write_mjcf(mc, tmp_path / "complete.xml")
    a, b, c = MujocoPlant(mc, world), MujocoPlant(mr, plain, gear_ratio=N), MujocoPlant(mc, onlink)
    rng = np.random.default_rng(11)
    gap = 0.0
    for _ in range(50):
        x, u = rng.uniform(-1, 1, mr.nx), rng.uniform(-10, 10, mr.n)
        xa, xb = a.xdot(x, u), b.xdot(x, u)
        assert np.max(np.abs(xa - xb)) <= TOL * np.max(np.abs(xb))
        gap = max(gap, np.max(np.abs(c.xdot(x, u) - xb)) / np.max(np.abs(xb)))
    assert gap > 1e-6  # the rotors on the links do change the dynamics (the test can tell them apart)


def test_names_sensors_and_nothing_extra(tmp_path):
    m = fjm_runtime.load("elbow3")
    p = dict(m.default_params, K2=812.5)
    path = write_mjcf(m, tmp_path / "e.xml", p, gear_ratio=[10.0, 20.0, 30.0])
    mj = mujoco.MjModel.from_xml_path(str(path))  # loads as it is
    joints = m.manifest["source"]["joints"]
    plant = MujocoPlant(m, path, p, gear_ratio=[10.0, 20.0, 30.0])
    rng = np.random.default_rng(2)
    x = rng.uniform(-1, 1, m.nx)
    plant.xdot(x, np.zeros(m.n))
    s = plant.sensors()
    n = m.n
    for i, j in enumerate(joints):
        assert mj.joint(j).type == mujoco.mjtJoint.mjJNT_HINGE and mj.joint(f"{j}_rotor").id >= 0
        assert mj.tendon(f"{j}_spring").id >= 0 and mj.actuator(f"{j}_motor").id >= 0
        K = p[f"K{i + 1}"]
        assert mj.tendon_stiffness[mj.tendon(f"{j}_spring").id] == K
        got = [s[f"{j}_q"], s[f"{j}_dq"], s[f"{j}_q_m"], s[f"{j}_dq_m"], s[f"{j}_tau_J"]]
        want = [x[i], x[n + i], x[2 * n + i], x[3 * n + i], K * (x[2 * n + i] - x[i])]
        assert np.allclose(got, want, rtol=1e-13, atol=1e-13)
        link = mj.joint(j)
        assert mj.dof_damping[link.dofadr[0]] == 0 and mj.dof_armature[link.dofadr[0]] == 0
        assert not mj.jnt_limited[link.id] and mj.dof_frictionloss[link.dofadr[0]] == 0
    assert mj.ngeom == 0 and mj.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    assert np.allclose(mj.opt.gravity, [0, 0, -m.default_params["g0"]], rtol=0, atol=0)


def test_full_precision(tmp_path):
    """A 17-digit parameter reaches MuJoCo unrounded (mj_saveLastXML would keep 6 digits)."""
    m = fjm_runtime.load("panda")
    K1, Jm7 = 10000.123456789012, 0.1234567890123456
    path = write_mjcf(m, tmp_path / "p.xml", {"K1": K1, "Jm7": Jm7})
    mj = mujoco.MjModel.from_xml_path(str(path))
    assert mj.tendon_stiffness[mj.tendon("panda_joint1_spring").id] == K1
    rotor = mj.joint("panda_joint7_rotor")
    total = mj.dof_armature[rotor.dofadr[0]] + mj.body_inertia[mj.body("panda_joint7_rotor").id][2]
    assert abs(total - Jm7) <= 2e-16 * Jm7


def test_link1_inertia_rules(tmp_path):
    m = fjm_runtime.load("link1")
    rng = np.random.default_rng(4)
    # the paper's defaults are a point mass (J_l = M L^2): exact with MuJoCo's inertia floor
    for p in (None, {"J_l": 1.3}, {"J_l": 2.0, "M": 2.0, "L": 1.0}):
        plant = MujocoPlant(m, write_mjcf(m, tmp_path / "l.xml", p), p)
        assert _worst(m, plant, p, rng, count=10) < TOL
    with pytest.raises(FjmValueError, match="J_l"):
        mjcf_text(m, {"J_l": 0.5})


def test_refusals(tmp_path):
    with pytest.raises(FjmValueError, match="transverse inertia"):
        mjcf_text(fjm_runtime.load("panda_complete"), {"Jm7": 1.0})  # I_a = 1e-4 > 2 I_t: no rigid rotor
    with pytest.raises(FjmValueError, match="reduced model"):
        mjcf_text(fjm_runtime.load("panda"), complete=True)
    with pytest.raises(FjmValueError, match="gear ratios"):
        mjcf_text(fjm_runtime.load("panda"), gear_ratio=[1.0, 2.0])
    with pytest.raises(FjmValueError, match="unknown parameter"):
        mjcf_text(fjm_runtime.load("panda"), {"Kx": 1.0})


def test_cli(tmp_path, capsys):
    out = tmp_path / "p.xml"
    assert fjm_main(["export", "mjcf", "panda", "--out", str(out), "--complete", "--param", "N7=300"]) == 0
    mj = mujoco.MjModel.from_xml_path(str(out))
    assert mj.actuator("panda_joint7_motor").gear[0] == 1.0 / 300.0
    assert mj.body(mj.body("panda_joint7_rotor").parentid[0]).name == "panda_link6"
    capsys.readouterr()
    for argv in (["export", "mjcf", "elbow3", "--out", str(out), "--complete"],
                 ["export", "mjcf", "panda", "--out", str(out), "--param", "Q=1"],
                 ["export", "mjcf", "panda", "--out", str(tmp_path / "missing" / "p.xml")]):
        assert fjm_main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("fjm: error: ") and err.count("\n") == 1


def test_three_segment_spring_through_the_passive_callback(tmp_path):
    """arm1_hd (the datasheet curve is no polynomial): the file states it as a custom numeric, the spring
    tendon has stiffness 0, and the callback applies psi; qacc equals fjm's to 1e-12 at gear ratio 5
    (deflections over both breakpoints), and without the callback the link row misses psi / D."""
    m = fjm_runtime.load("arm1_hd")
    p = dict(m.default_params, K_2=1.8e4, T_2=40.0, F_c=0.5, F_s=0.9)
    path = write_mjcf(m, tmp_path / "arm.xml", p, gear_ratio=5.0)
    text = path.read_text()
    assert 'numeric name="fjm_spring_three_segment:joint1_spring" data="13000.0 18000.0 20000.0 14.0 40.0 0.0002"' \
        in text and '<fixed name="joint1_spring" stiffness="0.0"' in text
    plant = MujocoPlant(m, path, p, gear_ratio=5.0)
    rng = np.random.default_rng(12)
    worst = 0.0
    for phi in np.concatenate([rng.uniform(-0.006, 0.006, 30), [1.077e-3, 1.1e-3, -2.9e-3]]):
        x = np.array([rng.uniform(-2, 2), rng.uniform(-2, 2), 0.0, rng.uniform(-2, 2)])
        x[2] = x[0] + phi
        u = rng.uniform(-30, 30, 1)
        ours, theirs = m.f(x, p) + m.g(x, p) @ u, plant.xdot(x, u)
        worst = max(worst, *(abs(theirs[i] - ours[i]) / abs(ours[i]) for i in (1, 3)))
    assert worst < TOL, worst
    x, u = np.array([0.3, 0.1, 0.3 + 2e-3, -0.4]), np.array([5.0])
    plant.springs = []  # the same file without the spring in the callback: the link row misses psi / D
    miss = (m.f(x, p) + m.g(x, p) @ u - plant.xdot(x, u))[1]
    J = p["I1"] + p["m1"] * p["r1"] ** 2
    assert abs(miss * J - float(m.spring_functions["spring"](2e-3, m.params_array(p))[0])) < 1e-9
