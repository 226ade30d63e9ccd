"""The motor-side impedance law (``control_impedance``, :class:`ImpedanceController`) and the full measurement.

* The emitted law equals its formula written here in NumPy around the emitted feedforward: u_cmd, the
  clamp, the integral with conditional integration at the torque limit (link1, panda_hd). The joint
  impedance (``control_joint_impedance``, the joint-torque interface's law) likewise, its rigid feedforward
  ``D(q_d) q_d'' + C(q_d, q_d') q_d'`` being the feedforward's ``tau_Jd`` less its value at rest (gravity),
  and ``D(q_d) q_d''`` at ``q_d' = 0``.
* The default gains place the motor's mode with the link held (``J_m s^2 + K_d s + K_p + (1 + K_T) K``) at
  damping 0.7; on the Panda K_p = 1000 / 300 N m/rad.
* ``sensing = 'full'``: the measurement is ``[q; dq; q_m; dq_m; tau_J; dtau_J]`` of the plant state (the true
  spring, linear or a drive's curve), its noise slot ``j`` is generator channel ``j`` (the SIGNALS order),
  velocities differentiated and dtau_J filtered leave their slots silent.
* The Panda at 1 kHz, one sample of delay with prediction, franka_like sensing (its rate limit on), the
  task from rest holding gravity: the nominal plant and K x0.7 / x1.3 with a 1 kg payload hold, worst RMS
  <= 1 mrad (measured 0.32 mrad, K x1.3 + 1 kg, joint 4; never at a limit); the compiled loop equals the
  NumPy one to 1e-9, the export's controller step the simulator to 1e-12, a batch row its single run.
"""
from __future__ import annotations

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.control.design import task_start
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.impedance import (ImpedanceController, JointImpedanceController, default_impedance_gains,
                                           default_joint_impedance_gains)
from fjm_runtime.sim.sample_step import initial_measurement
from fjm_runtime.sim.step_layout import make_layout
from fjm_runtime.sim.sensor import SIGNALS, SensorModel, noise_slots
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.validation import FjmValueError


def _formula(model, m, z, r, p, g):
    """``(u, u_cmd, z_dot)`` of the law's definition (module docstring of fjm_runtime.control.impedance)."""
    n = model.n
    tau_d, theta, dtheta, _, u_ff = model.feedforward(r, p)
    q, qm, dqm, tau = m[:n], m[2 * n:3 * n], m[3 * n:4 * n], m[4 * n:5 * n]
    u_cmd = u_ff + g["K_p"] * (theta - qm) + g["K_d"] * (dtheta - dqm) + g["K_T"] * (tau_d - tau) + g["K_i"] * z
    u = np.clip(u_cmd, -g["u_max"], g["u_max"])
    e = r[:n] - q
    frozen = ((u_cmd > g["u_max"]) & (e > 0)) | ((u_cmd < -g["u_max"]) & (e < 0))
    return u, u_cmd, np.where(frozen, 0.0, e)


@pytest.mark.parametrize("name", ["link1", "panda_hd"])
def test_emitted_law_is_its_formula(name):
    model = fjm_runtime.load(name)
    n = model.n
    rng = np.random.default_rng(3)
    p = model.params_array(None)
    law = make_controller("impedance", model, p, u_max=5.0)
    fn, zdot = law.law_functions()
    seen_frozen = seen_free = 0
    for _ in range(20):
        g = {"K_p": rng.uniform(0, 2e3, n), "K_d": rng.uniform(0, 50, n), "K_T": rng.uniform(-0.9, 1, n),
             "K_i": rng.uniform(0, 1e4, n), "u_max": np.full(n, 5.0)}
        ctrl = ImpedanceController(model, p, u_max=5.0, **{k: v for k, v in g.items() if k != "u_max"})
        m = rng.uniform(-0.3, 0.3, 6 * n)
        z, r = rng.uniform(-1e-3, 1e-3, n), rng.uniform(-0.3, 0.3, 5 * n)
        u, s, z_dot, u_cmd, y_hat = (np.asarray(v).ravel() for v in fn(m, z, r, p, ctrl.gains))
        u_ref, ucmd_ref, zdot_ref = _formula(model, m, z, r, p, g)
        scale = max(1.0, np.max(np.abs(ucmd_ref)))
        assert np.max(np.abs(u_cmd - ucmd_ref)) <= 1e-12 * scale
        assert np.max(np.abs(u - u_ref)) <= 1e-12 * scale
        assert np.array_equal(z_dot, zdot_ref)
        assert np.array_equal(np.asarray(zdot(m, z, r, p, ctrl.gains, u_cmd, u)).ravel(), zdot_ref)
        assert np.allclose(s, model.feedforward(r, p)[1] - m[2 * n:3 * n], rtol=0, atol=1e-12)
        assert np.array_equal(y_hat, np.r_[m[:2 * n], np.zeros(2 * n)])
        seen_frozen += int(np.sum(zdot_ref == 0))
        seen_free += int(np.sum(zdot_ref != 0))
    assert seen_frozen and seen_free  # both branches of the anti-windup were exercised


def test_default_gains_damp_the_motor_mode():
    model = fjm_runtime.load("panda")
    p = model.params_array(None)
    g = default_impedance_gains(model, p)
    K, Jm = p[:7], p[7:14]
    assert [name[:1] for name in model.param_names[:14]] == ["K"] * 7 + ["J"] * 7
    assert np.allclose(g["K_p"], [1000] * 4 + [300] * 3) and np.all(g["K_T"] == -0.7)
    for i in range(7):  # J_m s^2 + K_d s + (K_p + (1 + K_T) K): damping ratio 0.7
        roots = np.roots([Jm[i], g["K_d"][i], g["K_p"][i] + (1 + g["K_T"][i]) * K[i]])
        assert -roots[0].real / abs(roots[0]) == pytest.approx(0.7, rel=1e-12)
    assert np.allclose(g["K_i"], g["K_p"] * 2 * np.pi)


def test_bad_gains_and_sensing_are_refused():
    model = fjm_runtime.load("link1")
    with pytest.raises(ValueError, match="K_T"):
        make_controller("impedance", model, {}, K_T=-1.0)
    with pytest.raises(ValueError, match="sensing = 'full'"):
        make_controller("ismc", model, {}, sensing="full", lam=8.0)
    with pytest.raises(ValueError, match="sensing = 'full'"):
        make_controller("impedance", model, {}, sensing="torque")
    with pytest.raises(FjmValueError, match="no emitted impedance law"):
        ImpedanceController(fjm_runtime.load("planar2_complete"), {})


@pytest.mark.parametrize("name", ["planar2", "link1_hd"])
def test_full_measurement_of_the_state(name):
    model = fjm_runtime.load(name)
    n = model.n
    ctrl = make_controller("impedance", model, {})
    L = make_layout(model, ctrl, 1e-3, 1, SensorModel.ideal(), 0, False)
    assert (L.sensing, L.nm, ctrl.measurement_size) == ("full", 6 * n, 6 * n)
    rng = np.random.default_rng(1)
    p = model.params_array(None)
    x = rng.uniform(-0.02, 0.02, 4 * n)
    m = initial_measurement(model, L, x, p)
    q, dq, qm, dqm = (x[i * n:(i + 1) * n] for i in range(4))
    if model.spring_functions is None:
        K = np.array([p[list(model.param_names).index(f"K{i + 1}")] for i in range(n)])
        tau, dtau = K * (qm - q), K * (dqm - dq)
    else:  # the drive's curve at the deflection, its slope times the deflection rate
        psi, dpsi, _ = (np.asarray(v).ravel() for v in model.spring_functions["spring"](qm - q, p))
        tau, dtau = psi, dpsi * (dqm - dq)
    assert np.allclose(m, np.r_[q, dq, qm, dqm, tau, dtau], rtol=1e-14, atol=1e-14)


def test_full_noise_slots_are_the_signals_in_order():
    n = 3
    chans, levels = noise_slots(SensorModel.panda_white(), "full", n)
    assert chans.tolist() == list(range(6 * n))
    white = SensorModel.panda_white()
    expected = [getattr(white, s) for s in SIGNALS]
    expected[5] = 0.0  # dtau_J filtered from tau_J: its slot is silent
    assert np.allclose(levels, np.repeat(expected, n))
    chans, levels = noise_slots(SensorModel.franka_like(), "full", n)
    fr = SensorModel.franka_like()
    assert chans.tolist() == list(range(6 * n))  # differentiated velocities: silent slots, not moved angles
    assert np.allclose(levels, np.repeat([fr.q, 0.0, fr.q_m, 0.0, fr.tau_J, 0.0], n))


def _panda_run(true_params, backend, duration):
    model = fjm_runtime.load("panda")
    p_nom = model.params_array(None)
    ctrl = make_controller("impedance", model, p_nom, u_max=model.limits.effort)
    ref = model.task.reference()
    x0 = task_start(model, ref, "holding gravity", p_nom)
    return simulate(model, ctrl, ref, duration=duration, dt=1e-3, true_params=true_params, x0=x0,
                    sensor=SensorModel.franka_like(seed=3), delay_samples=1, predict=True, backend=backend)


def _plant(scale_K: float, load: float) -> dict:
    model = fjm_runtime.load("panda")
    p = model.default_params
    return {**{f"K{i}": p[f"K{i}"] * scale_K for i in range(1, 8)}, "m_load": load}


@pytest.mark.slow
@pytest.mark.parametrize("label,scale_K,load", [("nominal", 1.0, 0.0), ("K x0.7 + 1 kg", 0.7, 1.0),
                                                ("K x1.3 + 1 kg", 1.3, 1.0)])
def test_panda_holds_under_franka_like_sensing(label, scale_K, load):
    res = _panda_run(_plant(scale_K, load), "compiled", 3.0)
    rms = np.sqrt(np.mean(res.e1 ** 2, axis=0))
    at_limit = np.mean(np.abs(res.u) >= 0.999 * fjm_runtime.load("panda").limits.effort)
    print(f"panda impedance, {label}: RMS {np.round(rms * 1e3, 3).tolist()} mrad, at a limit {at_limit:.1%}")
    assert np.all(np.isfinite(res.x))
    assert np.max(rms) <= 1e-3
    assert at_limit == 0.0


@pytest.mark.slow
def test_panda_compiled_equals_python():
    a = _panda_run(_plant(0.7, 1.0), "python", 0.15)
    b = _panda_run(_plant(0.7, 1.0), "compiled", 0.15)
    assert np.max(np.abs(a.x - b.x)) <= 1e-9
    assert np.max(np.abs(a.u - b.u)) <= 1e-9 * max(1.0, np.max(np.abs(a.u)))
    assert np.max(np.abs(a.z - b.z)) <= 1e-9


@pytest.mark.slow
def test_exported_step_is_the_simulators():
    """The C export's controller step (fjm_runtime.export.controller_step) with the full measurement: from the
    simulator's controller state and the raw reading of each of 20 samples it gives the run's torques to 1e-12
    (the Panda, franka_like, one sample of delay with prediction)."""
    from types import SimpleNamespace

    from fjm_runtime.export.controller_step import ControllerLayout, controller_functions
    from support.controller_runs import Run, relative

    model = fjm_runtime.load("panda")
    p_nom = model.params_array(None)
    ctrl = make_controller("impedance", model, p_nom, u_max=model.limits.effort)
    sensor = SensorModel.franka_like(seed=5)
    L = make_layout(model, ctrl, 1e-3, 2, sensor, 1, True)
    design = SimpleNamespace(model=model, layout=L, sensor=sensor, controller=ctrl, cstate=ControllerLayout(L))
    ref = model.task.reference()
    run = Run(design, 0.02, reference=ref, x0=task_start(model, ref, "holding gravity", p_nom))
    step, _ = controller_functions(model, ctrl, L, "panda_impedance")
    g = np.asarray(ctrl.gains)
    U = np.stack([np.asarray(step(run.C[k], run.M[k], run.R[k], p_nom, g)[0]).ravel() for k in range(run.M.shape[0])])
    rel = relative(U, run.U)
    print(f"panda impedance: exported step vs simulator, 20 samples: {rel:.3g}")
    assert rel <= 1e-12


@pytest.mark.parametrize("name", ["planar2", "panda_hd"])
def test_emitted_joint_impedance_is_its_formula(name):
    model = fjm_runtime.load(name)
    n = model.n
    rng = np.random.default_rng(8)
    p = model.params_array(None)
    seen_frozen = 0
    for k in range(12):
        g = {"K_q": rng.uniform(0, 2e3, n), "D_q": rng.uniform(0, 80, n), "K_i": rng.uniform(0, 6e3, n)}
        ctrl = JointImpedanceController(model, p, u_max=20.0, **g)
        fn, zdot = ctrl.law_functions()
        m = rng.uniform(-0.3, 0.3, 6 * n)
        z, r = rng.uniform(-1e-2, 1e-2, n), rng.uniform(-0.5, 0.5, 5 * n)
        if k == 0:
            r[n:2 * n] = 0.0  # at rest: the rigid feedforward is D(q_d) q_d'' alone
        rest = np.r_[r[:n], np.zeros(4 * n)]
        rigid = model.feedforward(r, p)[0] - model.feedforward(rest, p)[0]
        if k == 0:
            x_d = np.r_[r[:n], np.zeros(3 * n)]
            assert np.allclose(rigid, model.inertia(x_d, p) @ r[2 * n:3 * n], rtol=1e-12, atol=1e-12)
        e = r[:n] - m[:n]
        u_cmd_ref = rigid + g["K_q"] * e + g["D_q"] * (r[n:2 * n] - m[n:2 * n]) + g["K_i"] * z
        u, s, z_dot, u_cmd, y_hat = (np.asarray(v).ravel() for v in fn(m, z, r, p, ctrl.gains))
        scale = max(1.0, np.max(np.abs(u_cmd_ref)))
        assert np.max(np.abs(u_cmd - u_cmd_ref)) <= 1e-12 * scale
        assert np.max(np.abs(u - np.clip(u_cmd_ref, -20.0, 20.0))) <= 1e-12 * scale
        frozen = ((u_cmd_ref > 20.0) & (e > 0)) | ((u_cmd_ref < -20.0) & (e < 0))
        assert np.array_equal(z_dot, np.where(frozen, 0.0, e))
        assert np.array_equal(np.asarray(zdot(m, z, r, p, ctrl.gains, u_cmd, u)).ravel(), z_dot)
        assert np.array_equal(s, e) and np.array_equal(y_hat, np.r_[m[:2 * n], np.zeros(2 * n)])
        seen_frozen += int(np.sum(frozen))
    assert seen_frozen


def test_joint_impedance_default_gains():
    model = fjm_runtime.load("panda")
    p = model.params_array(None)
    g = default_joint_impedance_gains(model, p)
    D0 = np.diag(model.inertia(np.zeros(model.nx), p))
    assert np.allclose(g["K_q"], np.r_[[1e4 / 6] * 4, [3e3 / 6] * 3]) and np.allclose(g["K_i"], 3 * g["K_q"])
    for i in range(7):  # D_ii(0) s^2 + D_q s + K_q: damping ratio 0.7
        roots = np.roots([D0[i], g["D_q"][i], g["K_q"][i]])
        assert -roots[0].real / abs(roots[0]) == pytest.approx(0.7, rel=1e-12)
    ctrl = make_controller("joint_impedance", model, p, u_max=model.limits.effort)
    assert (ctrl.law_kind, ctrl.sensing, ctrl.n_states) == ("joint_impedance", "full", 7)
    assert np.array_equal(ctrl.gain_values()["K_q"], g["K_q"])


@pytest.mark.slow
def test_batch_rows_are_the_single_runs():
    """The batch engine runs the impedance law unchanged: each row (planar2, K x0.7 / x1.3 on one joint,
    franka_like, one sample of delay with prediction) equals simulate's run of its plant and seed."""
    from fjm_runtime.batch.runner import simulate_batch
    from fjm_runtime.control.references import Sinusoid

    model = fjm_runtime.load("planar2")
    p = model.params_array(None)
    ctrl = make_controller("impedance", model, p, u_max=200.0)
    ref = Sinusoid(0.3, 2.0, n=2)
    P = np.tile(p, (3, 1))
    P[1, model.param_names.index("K1")] *= 0.7
    P[2, model.param_names.index("K2")] *= 1.3
    sensor = SensorModel.franka_like(seed=2)
    _, theta, dtheta, _, _ = model.feedforward(ref(0.0), p)
    x0 = np.r_[ref(0.0)[0], ref(0.0)[1], theta, dtheta]
    batch = simulate_batch(model, ctrl, ref, P, duration=0.5, sensor=sensor, delay_samples=1, predict=True, x0=x0)
    for i in range(3):
        run = simulate(model, ctrl, ref, duration=0.5, true_params=P[i], sensor=sensor.with_seed(sensor.seed + i),
                       delay_samples=1, predict=True, backend="compiled", x0=x0)
        assert batch.metrics["rms_error"][i] == pytest.approx(run.metrics.as_dict()["rms_error"], rel=1e-9)
        assert batch.metrics["max_abs_u"][i] == pytest.approx(run.metrics.as_dict()["max_abs_u"], rel=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("label,scale_K,scale_Jm,load", [("nominal", 1.0, 1.0, 0.0), ("K x0.7, J_m x0.8 + 1 kg", 0.7, 0.8, 1.0),
                                                         ("K x1.3, J_m x1.2 + 1 kg", 1.3, 1.2, 1.0)])
def test_panda_joint_impedance_holds_through_the_franka_interface(label, scale_K, scale_Jm, load):
    """The joint impedance's tau_d through the franka interface (libfranka's 100 Hz filter and 1 N m per tick,
    nominal gravity added, the inner torque loop): worst RMS <= 3 mrad (measured 0.49 mrad nominal, 1.45 mrad
    at K x0.7, J_m x0.8 + 1 kg; default gains)."""
    model = fjm_runtime.load("panda")
    p_nom = model.params_array(None)
    ctrl = make_controller("joint_impedance", model, p_nom, u_max=model.limits.effort)
    ref = model.task.reference()
    p = model.default_params
    true = {**{f"K{i}": p[f"K{i}"] * scale_K for i in range(1, 8)},
            **{f"Jm{i}": p[f"Jm{i}"] * scale_Jm for i in range(1, 8)}, "m_load": load}
    res = simulate(model, ctrl, ref, duration=3.0, dt=1e-3, true_params=true,
                   x0=task_start(model, ref, "holding gravity", p_nom), sensor=SensorModel.franka_like(seed=7),
                   delay_samples=1, predict=True, backend="compiled", interface="franka")
    rms = np.sqrt(np.mean(res.e1 ** 2, axis=0))
    print(f"panda joint impedance, franka interface, {label}: RMS {np.round(rms * 1e3, 3).tolist()} mrad")
    assert np.all(np.isfinite(res.x))
    assert np.max(rms) <= 3e-3
