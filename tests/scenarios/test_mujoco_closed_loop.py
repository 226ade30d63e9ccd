"""A closed loop with MuJoCo as the plant (the MJCF export, fjm_runtime.export.bridge) equals fjm_runtime.simulate
on the same substeps: linear springs, through each command interface, the cubic and the datasheet springs, the
Panda's drives."""
from __future__ import annotations

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.export.bridge import MujocoPlant, run_closed_loop
from fjm_runtime.export.mjcf import write_mjcf
from fjm_runtime.sim.interface import CommandInterface


def _mujoco_equals_simulate(m, ref, true, tmp_path, dt=1e-3, sub=10, x0=None):
    """ismc at ``dt`` on ``sub`` plant substeps, MuJoCo (RK4, held ctrl) vs fjm's simulate: fjm's run."""
    path = write_mjcf(m, tmp_path / f"{m.name}.xml", true, timestep=dt / sub)

    def ctrl():
        return fjm_runtime.make_controller("ismc", m, None, lam=10.0, k_s=50.0, delta=0.25)
    kw = dict(duration=1.0, dt=dt, substeps=sub, x0=x0, interface="ideal")   # held ctrl: MuJoCo's RK4 stages
    res = fjm_runtime.simulate(m, ctrl(), ref, true_params=true, **kw)
    t, X, U = run_closed_loop(MujocoPlant(m, path, true), ctrl(), ref, **kw)
    assert np.array_equal(t, res.t)
    assert np.max(np.abs(X - res.x)) < 1e-9 * max(1.0, np.max(np.abs(res.x)))
    assert np.max(np.abs(U - res.u)) < 1e-9 * max(1.0, np.max(np.abs(res.u)))
    return res


def test_closed_loop_equals_simulate(tmp_path):
    """ismc on elbow3 at 1 kHz, plant on 10 substeps: MuJoCo (RK4, held ctrl) vs fjm's simulate."""
    m = fjm_runtime.load("elbow3")
    ref = fjm_runtime.make_reference("sine", m.n, amplitude=0.4, omega=2.0)
    res = _mujoco_equals_simulate(m, ref, dict(m.default_params, K1=m.default_params["K1"] * 1.2), tmp_path)
    assert np.max(np.abs(res.x[:, :m.n])) > 0.2 and np.ptp(res.u) > 1.0  # the loop moves the arm: not a trivial match


@pytest.mark.parametrize("interface", [CommandInterface.motor(),
                                       CommandInterface(kind="joint_torque", lowpass_cutoff_hz=100.0, K_T=-0.5,
                                                        D_T=0.005, torque_rate_limit=2000.0)])
def test_closed_loop_through_the_interface_follows_simulate(tmp_path, interface):
    """The interface between the law and MuJoCo's motors (the current loop's mean per MuJoCo step, the vendor
    layer with the nominal gravity and the inner loop on MuJoCo's state) follows fjm's simulate to the
    quadrature of the lag (MuJoCo's RK4 holds ctrl over a step), far inside what the interface changes."""
    m = fjm_runtime.load("elbow3")
    ref = fjm_runtime.make_reference("sine", m.n, amplitude=0.4, omega=2.0)
    path = write_mjcf(m, tmp_path / "elbow3.xml", None, timestep=5e-5)
    ctrl = lambda: fjm_runtime.make_controller("ismc", m, None, lam=10.0, k_s=50.0, delta=0.25)  # noqa: E731
    kw = dict(duration=0.5, dt=1e-3, substeps=20)
    res = fjm_runtime.simulate(m, ctrl(), ref, interface=interface, **kw)
    ideal = fjm_runtime.simulate(m, ctrl(), ref, interface="ideal", **kw)
    t, X, U = run_closed_loop(MujocoPlant(m, path), ctrl(), ref, interface=interface, **kw)
    gap, effect = np.max(np.abs(X - res.x)), np.max(np.abs(ideal.x - res.x))
    assert gap < 1e-3 * effect and effect > 1e-6


def test_closed_loop_on_the_cubic_spring_equals_simulate(tmp_path):
    """link1_hd, true k1 x1.2 and k3 x0.8 and Coulomb/Stribeck motor friction: the law derived for the cubic spring (nominal k1, k3) at 1 kHz on
    10 substeps, MuJoCo's polynomial tendon stiffness vs fjm's simulate; the deflection reaches the stiff
    part of the curve (k3 phi^2 > k1 somewhere)."""
    m = fjm_runtime.load("link1_hd")
    d = m.default_params
    true = dict(d, k1=1.2 * d["k1"], k3=0.8 * d["k3"], F_c=0.8, F_s=1.2, v_s=0.1, v_c=0.02)  # and motor friction
    res = _mujoco_equals_simulate(m, fjm_runtime.make_reference("sine", 1, amplitude=1.0, omega=3.0), true, tmp_path)
    phi = res.x[:, 2] - res.x[:, 0]
    assert np.max(true["k3"] * 3 * phi ** 2) > true["k1"], np.max(np.abs(phi))


def test_closed_loop_on_the_datasheet_spring_equals_simulate(tmp_path):
    """arm1_hd, true stiffnesses x1.15 and friction: the law derived for the curve (nominal values) at 1 kHz on
    10 substeps, MuJoCo with the passive callback vs fjm's simulate; the deflection crosses phi_1."""
    m = fjm_runtime.load("arm1_hd")
    d = m.default_params
    true = dict(d, K_1=1.15 * d["K_1"], K_2=1.15 * d["K_2"], K_3=1.15 * d["K_3"], F_c=1.0, F_s=1.3)
    ref = fjm_runtime.make_reference("sine", 1, amplitude=0.5, omega=5.0, offset=np.pi / 2)
    # at rest against gravity at horizontal: q_m = q + psi^-1(m1 g0 r1) (the true curve)
    phi0 = float(m.spring_functions["spring_inverse"](true["m1"] * true["g0"] * true["r1"], m.params_array(true)))
    x0 = np.array([np.pi / 2, 2.5, np.pi / 2 + phi0, 2.5])
    res = _mujoco_equals_simulate(m, ref, true, tmp_path, x0=x0)
    phi = res.x[:, 2] - res.x[:, 0]
    assert np.max(np.abs(phi)) > true["T_1"] / true["K_1"], np.max(np.abs(phi))


def test_closed_loop_on_the_panda_drives_equals_simulate(tmp_path):
    """panda_hd, true curves x1.1 on every joint and the friction x1.4: the state-sensed ismc derived for the
    curves (datasheet values, the shipped Panda design's gains) at 1 kHz on 14 substeps (the rule's), MuJoCo with the
    passive callback (seven curves, seven motor frictions) vs fjm's simulate, 0.5 s from rest against
    gravity; a drive's deflection passes its first breakpoint."""
    from fjm_runtime.control.design import Design
    from fjm_runtime.experiments import panda as P
    m = fjm_runtime.load("panda_hd")
    d = m.default_params
    true = dict(d, **{k: 1.1 * v for k, v in d.items() if k[:3] in ("K_1", "K_2", "K_3")},
                **{k: 1.4 * v for k, v in d.items() if k[:3] in ("F_c", "F_s")})
    ref = P.reference(m.n)
    x0 = P.rest_state(m, ref(0.0)[0], true)
    path = write_mjcf(m, tmp_path / "panda_hd.xml", true, timestep=1e-3 / 14)
    design = Design.shipped("panda", "ismc", "torque", 1000, 1)

    def ctrl():
        return fjm_runtime.make_controller("ismc", m, None, u_max=design.gains["u_max"], **design.law_gains())
    kw = dict(duration=0.5, dt=1e-3, substeps=14, x0=x0, interface="ideal")  # held ctrl: MuJoCo's RK4 stages
    res = fjm_runtime.simulate(m, ctrl(), ref, true_params=true, **kw)
    t, X, U = run_closed_loop(MujocoPlant(m, path, true), ctrl(), ref, **kw)
    assert np.array_equal(t, res.t)
    assert np.max(np.abs(X - res.x)) < 1e-9 * max(1.0, np.max(np.abs(res.x)))
    assert np.max(np.abs(U - res.u)) < 1e-9 * max(1.0, np.max(np.abs(res.u)))
    reach = np.max(np.abs(res.x[:, 2 * m.n:3 * m.n] - res.x[:, :m.n]), axis=0)
    phi_1 = np.array([true[f"T_1_{j}"] / true[f"K_1_{j}"] for j in range(1, m.n + 1)])
    assert np.any(reach > phi_1), (reach, phi_1)  # some drive runs past its first breakpoint
