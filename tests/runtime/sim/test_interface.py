"""The command interface, checked from first principles and across backends.

- the current loop's motor torque after ``k`` substeps of a unit command is ``1 - exp(-w_c k h)``;
- the vendor's low-pass is libfranka's recursion ``c_k = a tau_k + (1 - a) c_{k-1}``, ``a = 0.386`` at 1 kHz;
- the command never moves more than ``R T`` per tick (motor and joint_torque);
- with ``joint_torque`` a held ``tau_d = 0`` holds the arm still against gravity, which the robot adds
  (the gravity is the potential's gradient: finite differences of the energy, and ``M g0 L sin q`` for link1);
- numpy, CasADi and compiled steps agree with every interface;
- the metric counts the samples at the rate limit, and an error integral is frozen while the limit holds
  the command back (conditional integration).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime import make_controller, make_reference, simulate
from fjm_runtime.control.laws import ControlSample
from fjm_runtime.sim.metrics import time_at_rate_limit
from fjm_runtime.sim.interface import CommandInterface, gravity_function
from fjm_runtime.sim.sample_step import initial_step_state, python_sample_step
from fjm_runtime.sim.step_layout import make_layout
from fjm_runtime.sim.sensor import SensorModel


class _Sequence:
    """A law that commands ``values[k]`` at sample ``k`` (python backend), no state."""

    sensing, n_states = "state", 0

    def __init__(self, model, values):
        self.model, self.n = model, int(model.n)
        self.p_nom = model.params_array({})
        self.values, self.dt = np.asarray(values, dtype=float).reshape(len(values), self.n), 1e-3

    def evaluate(self, t, m, z, r):
        k = min(int(round(t / self.dt)), len(self.values) - 1)
        zero = np.zeros(self.n)
        return ControlSample(u=self.values[k], u_cmd=self.values[k], s=zero, y_hat=np.zeros(4 * self.n), e=zero,
                             saturated=np.zeros(self.n, dtype=bool))

    def initial_state(self, *a):
        return np.zeros(0)


def _steps(model, law, L, w, n_steps, p):
    """``n_steps`` python samples; the step states ``w_0..w_N`` and the commands, each a list."""
    W, U = [w], []
    for k in range(n_steps):
        w, sample = python_sample_step(model, law, L, w, k * L.T, np.zeros(5 * L.n), np.zeros(L.nm), p)
        W.append(w); U.append(np.asarray(sample.u, dtype=float))  # noqa: E702
    return W, U


@pytest.mark.parametrize("T, substeps", [(1e-3, 4), (2.5e-4, 1)])
def test_current_loop_step_response_is_first_order(link1, T, substeps):
    """From rest at q = 0 (no gravity, no spring torque: motor torque 0), a unit command: the motor torque
    after each substep h is 1 - exp(-w_c k h), w_c = 2 pi 2 kHz."""
    law = _Sequence(link1, np.ones((8, 1)))
    law.dt = T
    L = make_layout(link1, law, T, substeps, SensorModel.ideal(), 0, False, interface=CommandInterface.motor())
    p = link1.params_array({})
    W, _ = _steps(link1, law, L, initial_step_state(link1, L, np.zeros(4), np.zeros(0), p), 6, p)
    cur = np.array([w[L.extra_slices()[3]][0] for w in W])
    t = T * np.arange(cur.size)
    assert np.allclose(cur, 1.0 - np.exp(-2 * math.pi * 2000.0 * t), rtol=0, atol=1e-14)
    assert cur[1] < 1.0 - 1e-6                                 # a lag, not a step


def test_lowpass_is_libfrankas_recursion(link1):
    """libfranka's lowpassFilter: a = T / (T + 1 / (2 pi f_c)) = 0.386 at 1 kHz and 100 Hz, each command
    against the last one sent."""
    rng = np.random.default_rng(3)
    tau_d = rng.normal(0.0, 5.0, (40, 1))
    law = _Sequence(link1, tau_d)
    iface = CommandInterface(kind="joint_torque", lowpass_cutoff_hz=100.0)
    L = make_layout(link1, law, 1e-3, 2, SensorModel.ideal(), 0, False, interface=iface)
    p = link1.params_array({})
    x0 = np.array([0.3, 0.0, 0.3 + 9.8 * math.sin(0.3) / 150.0, 0.0])     # at rest against gravity
    _, U = _steps(link1, law, L, initial_step_state(link1, L, x0, np.zeros(0), p, controller=law), 40, p)
    a = 1e-3 / (1e-3 + 1.0 / (2 * math.pi * 100.0))
    assert round(a, 3) == 0.386 and L.lowpass_alpha == pytest.approx(a, rel=1e-15)
    c, expected = 0.0, []                                        # the rest's command without gravity: 0
    for k in range(40):
        c = a * tau_d[k, 0] + (1 - a) * c
        expected.append(c)
    assert np.allclose(np.array(U)[:, 0], expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("iface", [CommandInterface(torque_rate_limit=150.0),
                                   CommandInterface(kind="joint_torque", lowpass_cutoff_hz=300.0,
                                                    torque_rate_limit=150.0)])
def test_rate_limit_never_moves_more_than_the_limit_per_tick(link1, iface):
    rng = np.random.default_rng(5)
    law = _Sequence(link1, np.cumsum(rng.normal(0.0, 2.0, (60, 1)), axis=0) * 3)
    L = make_layout(link1, law, 1e-3, 2, SensorModel.ideal(), 0, False, interface=iface)
    p = link1.params_array({})
    x0 = np.array([0.3, 0.0, 0.3 + 9.8 * math.sin(0.3) / 150.0, 0.0])
    _, U = _steps(link1, law, L, initial_step_state(link1, L, x0, np.zeros(0), p, controller=law), 60, p)
    du = np.abs(np.diff(np.array(U)[:, 0]))
    assert np.all(du <= 150.0 * 1e-3 * (1 + 1e-12))
    assert np.mean(du >= 0.15 * (1 - 1e-9)) > 0.3                # the sequence does push it


def test_gravity_is_the_potentials_gradient(link1, panda):
    """link1: M g0 L sin q (its model equation); panda: central differences of the energy at rest."""
    g1 = gravity_function(link1)
    for q in (-1.0, 0.4, 2.0):
        assert float(g1(q, link1.params_array({}))) == pytest.approx(1.0 * 9.8 * 1.0 * math.sin(q), rel=1e-13)
    p = panda.params_array({})
    q = np.array([0.1, -0.6, 0.3, -2.0, 0.2, 1.4, 0.5])
    n, eps = 7, 1e-6
    fd = np.empty(n)
    for i in range(n):
        dq = np.zeros(n); dq[i] = eps  # noqa: E702
        e = [panda.energy(np.r_[q + s * dq, np.zeros(n), q, np.zeros(n)], p) for s in (1, -1)]
        fd[i] = (e[0] - e[1]) / (2 * eps)
    g = np.asarray(gravity_function(panda)(q, p)).ravel()
    assert np.allclose(g, fd, rtol=1e-6, atol=1e-6) and np.max(np.abs(g)) > 5.0


def _rest_against_gravity(model, q0):
    """The rest state at ``q0`` whose springs carry the gravity: ``q_m = q + K^-1 g(q)`` (nominal plant)."""
    n, p = int(model.n), model.params_array({})
    g = np.asarray(gravity_function(model)(q0, p)).ravel()
    K = p[[list(model.param_names).index(f"K{i + 1}") for i in range(n)]] if n > 1 else p[2]
    return np.r_[q0, np.zeros(n), q0 + g / K, np.zeros(n)], g


def test_zero_joint_torque_holds_the_arm_against_gravity(panda):
    """franka: tau_d = 0 held; the robot adds the nominal gravity, its inner loop and the current loop
    keep the nominal Panda still (the arm would fall under a zero MOTOR torque)."""
    q0 = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
    x0, g = _rest_against_gravity(panda, q0)
    assert np.max(np.abs(g)) > 10.0                               # gravity does load the arm
    law = _Sequence(panda, np.zeros((1, 7)))
    res = simulate(panda, law, make_reference("constant", 7, q_d=q0), duration=0.15, dt=1e-3, x0=x0,
                   backend="python", interface="franka")
    assert np.max(np.abs(res.x[:, :7] - q0)) < 1e-9
    fall = simulate(panda, law, make_reference("constant", 7, q_d=q0), duration=0.05, dt=1e-3, x0=x0,
                    backend="python", interface="ideal")
    assert np.max(np.abs(fall.x[:, :7] - q0)) > 1e-3


@pytest.mark.parametrize("iface", [CommandInterface.ideal(), CommandInterface.motor(),
                                   CommandInterface(current_bandwidth_hz=800.0, torque_rate_limit=400.0),
                                   CommandInterface(kind="joint_torque", lowpass_cutoff_hz=100.0, K_T=-0.5,
                                                    D_T=0.01, torque_rate_limit=500.0)])
def test_numpy_equals_compiled_with_each_interface(link1, iface):
    ctrl = make_controller("ismc", link1, nominal_params={"K": 140.0}, lam=30, k_s=300, delta=5, sensing="torque",
                           u_max=60)
    ref = make_reference("step", 1, q_d=0.5, rise_time=0.1)
    sensor = SensorModel.franka_like(seed=4)
    runs = [simulate(link1, ctrl, ref, duration=0.3, dt=1e-3, sensor=sensor, delay_samples=1, predict=True,
                     interface=iface, backend=b) for b in ("python", "casadi", "compiled")]
    for r in runs[1:]:
        assert np.max(np.abs(r.x - runs[0].x)) < 1e-9 and np.max(np.abs(r.u - runs[0].u)) < 1e-9
    assert runs[0].settings["interface"] == iface.name


def test_franka_on_the_panda_numpy_equals_compiled(panda):
    ctrl = make_controller("ismc", panda, nominal_params={}, lam=20, k_s=50, delta=5, sensing="torque")
    q0 = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
    x0, _ = _rest_against_gravity(panda, q0)
    ref = make_reference("step", 7, q_d=q0 + 0.02, q0=q0, rise_time=0.2)
    runs = [simulate(panda, ctrl, ref, duration=0.04, dt=1e-3, x0=x0, interface="franka", backend=b)
            for b in ("python", "compiled")]
    assert np.max(np.abs(runs[1].x - runs[0].x)) < 1e-9 and np.max(np.abs(runs[1].u - runs[0].u)) < 1e-9


def test_rate_limit_holds_sample_by_sample(link1):
    ctrl = make_controller("ismc", link1, nominal_params={}, lam=30, k_s=300, delta=5, sensing="torque", u_max=60)
    ref = make_reference("step", 1, q_d=1.0, rise_time=0.05)
    R, T = 150.0, 1e-3
    sensor, iface = SensorModel.franka_like(seed=2), CommandInterface.motor().with_rate_limit(R)
    runs = [simulate(link1, ctrl, ref, duration=0.4, dt=T, sensor=sensor, interface=iface, backend=b)
            for b in ("casadi", "python")]
    du = np.abs(np.diff(runs[0].u[:-1], axis=0))
    assert np.all(du <= R * T * (1 + 1e-12))
    frac = time_at_rate_limit(runs[0])[0]
    assert frac == pytest.approx(np.mean(np.r_[False, du[:, 0] >= R * T * (1 - 1e-9)]), abs=1e-12)
    assert frac > 0.05                                       # the step does push the limit
    assert np.max(np.abs(runs[0].u - runs[1].u)) < 1e-9
    free = simulate(link1, ctrl, ref, duration=0.4, dt=T, sensor=sensor, interface=iface.with_rate_limit(math.inf))
    assert np.max(np.abs(np.diff(free.u[:-1], axis=0))) > 2 * R * T   # without the limit it moves faster


def test_error_integral_is_frozen_while_the_rate_limit_holds_the_torque_back(link1):
    """Conditional integration under the rate limit: on samples where the applied torque lags the law's in
    the direction the error asks for, the integral state z does not move; on the others it moves by T e1
    (the ismc law's z' = e1). Both backends agree. Broken (z integrating through the limit), the frozen
    samples would change z by T |e1|, about 1e-4 here."""
    ctrl = make_controller("ismc", link1, nominal_params={}, lam=30, k_s=300, delta=5, sensing="torque")
    ref = make_reference("step", 1, q_d=1.0, rise_time=0.05)    # no torque limit: only the rate limit acts
    T, R = 1e-3, 150.0
    iface = CommandInterface.ideal().with_rate_limit(R)     # no lag: the law's u against the applied one
    runs = [simulate(link1, ctrl, ref, duration=0.3, dt=T, interface=iface, backend=b) for b in ("casadi", "python")]
    assert np.max(np.abs(runs[0].z - runs[1].z)) < 1e-12
    res = runs[0]
    u_law = np.array([ctrl.evaluate(t, np.r_[res.x[k, :2], 150.0 * (res.x[k, 2] - res.x[k, 0]),
                                               150.0 * (res.x[k, 3] - res.x[k, 1]), res.x[k, 3]],
                                    res.z[k], res.ref[k]).u[0] for k, t in enumerate(res.t[:-1])])
    e1 = res.x[:-1, 0] - res.ref[:-1, 0, 0]
    lag = u_law - res.u[:-1, 0]                                # zero to rounding where the limit is not hit
    held = ((lag > 1e-9) & (e1 < 0)) | ((lag < -1e-9) & (e1 > 0))
    dz = np.diff(res.z[:, 0])
    assert 10 <= held.sum() < held.size - 10                   # both kinds of samples occur
    assert np.all(dz[held] == 0.0)
    assert np.allclose(dz[~held], T * e1[~held], rtol=1e-9, atol=1e-15)
    assert np.max(np.abs(T * e1[held])) > 1e-5                 # what integrating would have added


def test_the_current_loop_keeps_rk4_fourth_order():
    """The plant's RK4 stages take the current loop's exact response at their times: halving the substep
    divides the error against a 40x finer run by about 16 (a held mean torque would give 4)."""
    planar2 = fjm_runtime.load("planar2")
    ctrl = make_controller("ismc", planar2, {}, lam=8.0, k_s=100.0, delta=2.0)
    ref = make_reference("sine", 2, amplitude=0.5, omega=1.0)
    stiff = {"K1": 4e4, "K2": 4e4}
    xs = [simulate(planar2, ctrl, ref, duration=1.0, true_params=stiff, substeps=s, interface="motor").x
          for s in (11, 22, 440)]
    e1, e2 = (np.max(np.abs(x[:, :2] - xs[2][:, :2])) for x in xs[:2])
    assert e1 / e2 > 12.0 and e1 < 1e-7


def test_prediction_on_joint_torque_runs_the_robots_torque_loop(link1):
    """Exact nominal model, no noise, a joint_torque layer without current loop: the predictor runs the robot's
    torque loop and gravity on the nominal model under the commands sent, so predicting 2 samples ahead
    gives the undelayed loop to a small fraction of what the delay alone changes (a predictor that took
    the commands for motor torques would leave out the 9.8 sin q gravity the robot adds)."""
    ctrl = make_controller("smc", link1, {}, lam=8.0, k_s=100.0, delta=2.0)
    ref = make_reference("sine", 1, amplitude=0.5, omega=1.0, offset=0.3)
    iface = CommandInterface(kind="joint_torque", current_bandwidth_hz=math.inf, lowpass_cutoff_hz=100.0,
                             K_T=-0.4, D_T=0.01)
    x0 = np.array([0.3, 0.0, 0.3 + 9.8 * math.sin(0.3) / 150.0, 0.0])
    kw = dict(duration=0.3, substeps=2, x0=x0, interface=iface)
    base = simulate(link1, ctrl, ref, **kw)
    pred = simulate(link1, ctrl, ref, delay_samples=2, predict=True, **kw)
    late = simulate(link1, ctrl, ref, delay_samples=2, **kw)
    k0 = 50
    gap, delay_effect = np.max(np.abs(pred.x[k0:] - base.x[k0:])), np.max(np.abs(late.x[k0:] - base.x[k0:]))
    assert gap < 1e-6 * delay_effect and delay_effect > 1e-4
