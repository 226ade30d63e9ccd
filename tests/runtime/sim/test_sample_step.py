"""The simulated torque sensor from first principles, on every sample of whole runs.

A torque-sensed arm measures its springs: ``tau_J = K_true (q_m - q)`` and ``dtau_J = K_true (dq_m - dq)``
per joint, at the TRUE stiffness of the plant (not the controller's nominal one), and for a nonlinear
spring ``tau_J = psi_true(q_m - q)``, ``dtau_J = psi_true'(q_m - q) (dq_m - dq)``. Those formulas are
written out here (the stiffness read from the TRUE parameter vector by name, the cubic ``k1 phi + k3 phi^3``
by hand) and checked, with the noise off and no delay, against the sample step as ``simulate`` runs it
(the CasADi backend, the default): the law fed the written-out measurement of the logged state ``x_k``
gives the torque the run applied at sample ``k``, on every sample, on a two-joint arm with a different
TRUE stiffness per joint. The same law fed the NOMINAL stiffness would give torques off by newtons, so a
sensor that measured the nominal spring (or swapped the joints' stiffnesses) fails.
"""
from __future__ import annotations

import numpy as np

import fjm_runtime
from fjm_runtime import make_controller, make_reference, simulate
from fjm_runtime.sim.sample_step import initial_step_state, python_sample_step
from fjm_runtime.sim.sensor import SensorModel
from fjm_runtime.sim.step_layout import make_layout

from support.spy import Spy


def _measurement(x, n, psi):
    """``[q; dq; tau_J; dtau_J; dq_m]`` of the state ``x`` (4n,) with the spring ``psi(phi) -> (tau, dtau/dphi)``."""
    q, dq, qm, dqm = x[:n], x[n:2 * n], x[2 * n:3 * n], x[3 * n:]
    tau, slope = psi(qm - q)
    return np.concatenate([q, dq, tau, slope * (dqm - dq), dqm])


def _replayed_torques(ctrl, res, n, psi):
    """The law on the written-out measurement of each logged state: u_k = law(m(x_k), z_k, r_k)."""
    return np.array([ctrl.evaluate(float(t), _measurement(res.x[k], n, psi), res.z[k], res.ref[k]).u
                     for k, t in enumerate(res.t[:-1])])


def _linear(K):
    K = np.asarray(K, dtype=float)
    return lambda phi: (K * phi, K * np.ones_like(phi))


def test_linear_springs_measured_at_the_true_stiffness_on_every_sample():
    m = fjm_runtime.load("planar2")
    K_true = {"K1": 118.0, "K2": 173.0}                    # nominal 150 each: the truth differs per joint
    p_true = {**K_true, "Jm1": 1.7, "Bm2": 0.2}
    ctrl = make_controller("ismc", m, nominal_params={}, lam=15, k_s=50, delta=5, sensing="torque")
    ref = make_reference("sine", 2, amplitude=0.4, omega=2.0)
    res = simulate(m, ctrl, ref, duration=0.3, dt=1e-3, true_params=p_true, sensor=SensorModel.ideal())
    assert res.settings["backend"] == "casadi" and res.settings["sensing"] == "torque"
    n = m.n
    # K_true read from the TRUE parameter vector by name: the stiffness of joint i is K<i>
    p = m.params_array(p_true)
    K = np.array([p[m.param_names.index(f"K{i + 1}")] for i in range(n)])
    assert K.tolist() == [118.0, 173.0]
    phi = res.x[:, 2 * n:3 * n] - res.x[:, :n]
    assert np.max(np.abs(phi)) > 1e-3                       # the springs do deflect
    u_true = _replayed_torques(ctrl, res, n, _linear(K))
    scale = np.max(np.abs(res.u[:-1]))
    assert np.max(np.abs(u_true - res.u[:-1])) <= 1e-9 * scale
    u_nominal = _replayed_torques(ctrl, res, n, _linear([150.0, 150.0]))
    assert np.max(np.abs(u_nominal - res.u[:-1])) > 1e-3 * scale       # the nominal spring is not what it measures
    u_swapped = _replayed_torques(ctrl, res, n, _linear(K[::-1]))
    assert np.max(np.abs(u_swapped - res.u[:-1])) > 1e-3 * scale       # nor the other joint's


def test_the_python_step_hands_the_law_the_same_measurement():
    """The numpy step (the reference of the CasADi one) at states far from rest: the measurement the law is
    given equals the written-out one to rounding, per joint."""
    m = fjm_runtime.load("planar2")
    p_true = m.params_array({"K1": 118.0, "K2": 173.0})
    spy = Spy(make_controller("ismc", m, nominal_params={}, lam=15, k_s=50, delta=5, sensing="torque"))
    L = make_layout(m, spy, 1e-3, 4, SensorModel.ideal(), 0, False)
    rng = np.random.default_rng(11)
    for _ in range(5):
        x = rng.uniform(-1.0, 1.0, 8)
        w = initial_step_state(m, L, x, np.zeros(L.nz), p_true)
        python_sample_step(m, spy, L, w, 0.0, np.zeros(10), np.zeros(L.nm), p_true)
        expected = _measurement(x, 2, _linear([118.0, 173.0]))
        assert np.allclose(spy.seen[-1], expected, rtol=1e-14, atol=1e-14)


def test_a_nonlinear_spring_measured_through_the_true_psi_on_every_sample():
    hd = fjm_runtime.load("link1_hd")
    k1, k3 = 60.0, 3500.0                                   # nominal 75, 2500
    ctrl = make_controller("ismc", hd, nominal_params={}, lam=20, k_s=100, delta=5, sensing="torque")
    ref = make_reference("sine", 1, amplitude=0.5, omega=3.0)
    res = simulate(hd, ctrl, ref, duration=0.3, dt=1e-3, true_params={"k1": k1, "k3": k3},
                   sensor=SensorModel.ideal())
    assert res.settings["backend"] == "casadi"

    def psi(phi):
        return k1 * phi + k3 * phi ** 3, k1 + 3.0 * k3 * phi ** 2
    phi = res.x[:, 2] - res.x[:, 0]
    assert k3 * np.max(np.abs(phi)) ** 2 > 1e-3 * k1       # the cubic term is in play
    u_true = _replayed_torques(ctrl, res, 1, psi)
    scale = np.max(np.abs(res.u[:-1]))
    assert np.max(np.abs(u_true - res.u[:-1])) <= 1e-9 * scale
    linear = _replayed_torques(ctrl, res, 1, _linear([k1]))
    assert np.max(np.abs(linear - res.u[:-1])) > 1e-6 * scale   # the cubic term is measured, not dropped

