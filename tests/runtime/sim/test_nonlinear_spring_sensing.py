"""Torque sensing of a nonlinear spring in the sampled loop, checked from first principles.

The spring is written out here (link1_hd's cubic ``k1 phi + k3 phi^3``; its inverse by the real root of
the cubic, not by the generated Newton iteration), and compared with what the sample step does:
- the torque sensor measures the TRUE spring ``psi_true(q_m - q)`` and its rate
  ``psi_true'(q_m - q) (dq_m - dq)``, not the nominal ones;
- the predictor reconstructs ``q_m = q + psi_nom^-1(tau_J)`` and integrates the NOMINAL model with the
  nominal parameters (a law built on a linear model keeps its ``q_m = q + tau_J / K_nom``);
- the CasADi (and compiled) steps equal the Python step on a run with delay, prediction and noise.
Each fails when its property is broken (sensor given the nominal spring, predictor given the truth).
"""
from __future__ import annotations

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime import make_controller, make_reference, simulate
from fjm_runtime.sim.sample_step import initial_step_state, python_sample_step
from fjm_runtime.sim.step_layout import make_layout
from fjm_runtime.sim.sensor import SensorModel

from support.numerics import rk4
from support.spy import Spy


@pytest.fixture(scope="module")
def hd():
    return fjm_runtime.load("link1_hd")


def _cubic(phi, k1, k3):
    return k1 * phi + k3 * phi ** 3, k1 + 3 * k3 * phi ** 2


def _cubic_inverse(tau, k1, k3):
    """The real root of ``k3 phi^3 + k1 phi - tau`` (psi' > 0: exactly one)."""
    roots = np.roots([k3, 0.0, k1, -tau])
    return float(roots[np.argmin(np.abs(roots.imag))].real)


def _law(model, nominal=None):
    return make_controller("ismc", model, nominal_params=nominal or {}, lam=20, k_s=100, delta=5, sensing="torque")


def test_torque_sensor_measures_the_true_nonlinear_spring(hd):
    true = {"k1": 60.0, "k3": 3500.0}
    p_true = hd.params_array(true)
    spy = Spy(_law(hd))                                          # nominal k1 = 75, k3 = 2500
    L = make_layout(hd, spy, 1e-3, 4, SensorModel.ideal(), 0, False)
    assert L.nm == 5                                             # torque sensing: [q; dq; tau_J; dtau_J; dq_m]
    x = np.array([0.3, -0.2, 0.5, 0.7])                          # phi = 0.2: the cubic term matters
    w = initial_step_state(hd, L, x, np.zeros(L.nz), p_true)
    python_sample_step(hd, spy, L, w, 0.0, np.zeros(5), np.zeros(L.nm), p_true)
    q, dq, qm, dqm = x
    psi, dpsi = _cubic(qm - q, 60.0, 3500.0)
    assert spy.seen[0][2] == pytest.approx(psi, rel=1e-14)             # tau_J = psi_true(q_m - q)
    assert spy.seen[0][3] == pytest.approx(dpsi * (dqm - dq), rel=1e-14)
    assert abs(spy.seen[0][2] - _cubic(qm - q, 75.0, 2500.0)[0]) > 0.5  # the nominal would differ


@pytest.mark.parametrize("nominal_model", ["link1_hd", "link1"])
def test_predictor_uses_the_controllers_spring_with_nominal_parameters(hd, nominal_model):
    """link1_hd's own law: q_m = q + psi_nom^-1(tau_J); a law built on link1 (linear K = 150) on the
    link1_hd plant: q_m = q + tau_J / K_nom. Either way the nominal model is integrated, not the plant."""
    p_true = hd.params_array({"k1": 60.0, "k3": 3500.0, "J_m": 2.5, "B_m": 0.2})
    ctrl_model = fjm_runtime.load(nominal_model)
    spy = Spy(_law(ctrl_model))
    T, subs = 1e-3, 3
    L = make_layout(hd, spy, T, subs, SensorModel.ideal(), 1, True)
    x0 = np.array([0.1, 0.4, 0.25, -0.3])
    w = initial_step_state(hd, L, x0, np.zeros(L.nz), p_true)
    u_prev = np.array([4.0])
    w[L.slices()[3]] = u_prev
    python_sample_step(hd, spy, L, w, 0.0, np.zeros(5), np.zeros(L.nm), p_true)
    m_old = w[L.slices()[2]]
    q, dq, tau, dqm = m_old[0], m_old[1], m_old[2], m_old[4]
    p_nom = ctrl_model.params_array(None)

    def predicted(model, p, spring):
        phi = spring[1](tau)
        f = lambda x: model.f(x, p) + model.g(x, p) @ u_prev  # noqa: E731
        xh = rk4(f, np.array([q, dq, q + phi, dqm]), T / subs, subs)[-1]
        psi, dpsi = spring[0](xh[2] - xh[0])
        return np.array([xh[0], xh[1], psi, dpsi * (xh[3] - xh[1]), xh[3]])

    if nominal_model == "link1_hd":
        nominal = ((lambda a: _cubic(a, 75.0, 2500.0)), lambda t: _cubic_inverse(t, 75.0, 2500.0))
    else:
        nominal = ((lambda a: (150.0 * a, 150.0)), lambda t: t / 150.0)
    expected = predicted(ctrl_model, p_nom, nominal)
    assert np.allclose(spy.seen[0], expected, rtol=1e-12, atol=1e-12), (spy.seen[0], expected)
    truth = ((lambda a: _cubic(a, 60.0, 3500.0)), lambda t: _cubic_inverse(t, 60.0, 3500.0))
    assert np.max(np.abs(predicted(hd, p_true, truth) - expected)) > 1e-3    # the true ones would differ


@pytest.mark.parametrize("name", ["link1_hd", "arm1_hd"])
def test_backends_agree_on_a_torque_sensed_nonlinear_run(name):
    """Delay 1 with prediction, noise, true spring off nominal: casadi and python steps equal."""
    model = fjm_runtime.load(name)
    d = model.default_params
    true = {"k1": 0.8 * d["k1"], "k3": 1.3 * d["k3"]} if name == "link1_hd" else \
        {k: 1.1 * d[k] for k in ("K_1", "K_2", "K_3")}
    ctrl = _law(model)
    ref = make_reference("sine", 1, amplitude=0.3, omega=2.0)
    runs = [simulate(model, ctrl, ref, duration=0.05, dt=1e-3, true_params=true, delay_samples=1, predict=True,
                     sensor=SensorModel.panda(), backend=b) for b in ("casadi", "python")]
    assert np.all(np.isfinite(runs[0].u))
    assert np.max(np.abs(runs[0].u - runs[1].u)) <= 1e-9 * (1 + np.max(np.abs(runs[1].u)))
    assert np.max(np.abs(runs[0].x - runs[1].x)) <= 1e-10
