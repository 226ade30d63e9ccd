"""The sampled loop's sensors, predictor and torque-rate limit, checked from first principles.

Each property is computed here independently of the sample step (spring law, RK4 of the nominal
model, the filter's impulse response, the rate bound) and compared with what the step does:
- the torque sensor measures the TRUE spring ``K_true (q_m - q)``, not the nominal one;
- the law sees only the measurement, and the predictor integrates the controller's NOMINAL model
  with its nominal parameters (not the plant's, not the true ones), also for a complete plant;
- a velocity differentiated from a quantized encoder on a ramp has the ramp's slope as mean and
  the noise of quantization through the difference filter;
- the torque sensor's offset is one constant per run.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime import make_controller, make_reference, simulate
from fjm_runtime.control.laws import ControlSample
from fjm_runtime.sim.interface import CommandInterface
from fjm_runtime.sim.sample_step import initial_step_state, python_sample_step
from fjm_runtime.sim.step_layout import make_layout
from fjm_runtime.sim.sensor import SensorModel, noise_array, offset_normals, sensor_from_spec
from fjm_runtime.validation import FjmValueError
from support.numerics import rk4
from support.spy import Spy


def _torque_law(m, K_nom):
    return make_controller("ismc", m, nominal_params={"K": K_nom}, lam=20, k_s=100, delta=5, sensing="torque")


def test_torque_sensor_measures_the_true_spring(link1):
    p_true = link1.params_array({"K": 110.0})
    spy = Spy(_torque_law(link1, 150.0))
    L = make_layout(link1, spy, 1e-3, 4, SensorModel.ideal(), 0, False)
    x = np.array([0.3, -0.2, 0.45, 0.7])
    w = initial_step_state(link1, L, x, np.zeros(L.nz), p_true)
    python_sample_step(link1, spy, L, w, 0.0, np.zeros(5), np.zeros(L.nm), p_true)
    q, dq, qm, dqm = x
    assert spy.seen[0][2] == pytest.approx(110.0 * (qm - q), rel=1e-14)      # tau_J = K_true (q_m - q)
    assert spy.seen[0][3] == pytest.approx(110.0 * (dqm - dq), rel=1e-14)
    assert abs(spy.seen[0][2] - 150.0 * (qm - q)) > 1.0                       # the nominal would differ


def test_predictor_integrates_the_nominal_model_with_nominal_parameters(link1):
    K_nom, p_true = 150.0, link1.params_array({"K": 105.0, "J_m": 2.6, "B_m": 0.3})
    p_nom = link1.params_array({"K": K_nom})
    spy = Spy(_torque_law(link1, K_nom))
    T, subs = 1e-3, 3
    L = make_layout(link1, spy, T, subs, SensorModel.ideal(), 1, True)
    x0 = np.array([0.1, 0.4, 0.25, -0.3])
    w = initial_step_state(link1, L, x0, np.zeros(L.nz), p_true)
    u_prev = np.array([4.0])
    w[L.slices()[3]] = u_prev                               # the torque sent one sample ago
    python_sample_step(link1, spy, L, w, 0.0, np.zeros(5), np.zeros(L.nm), p_true)

    m_old = w[L.slices()[2]]                                 # the measurement of one sample ago
    q, dq, tau, dqm = m_old[0], m_old[1], m_old[2], m_old[4]

    def predicted(p, K):
        xh = np.array([q, dq, q + tau / K, dqm])
        f = lambda x: link1.f(x, p) + link1.g(x, p) @ u_prev  # noqa: E731
        xh = rk4(f, xh, T / subs, subs)[-1]
        return np.array([xh[0], xh[1], K * (xh[2] - xh[0]), K * (xh[3] - xh[1]), xh[3]])

    expected = predicted(p_nom, K_nom)
    assert np.allclose(spy.seen[0], expected, rtol=1e-13, atol=1e-13)
    assert np.max(np.abs(predicted(p_true, 105.0) - expected)) > 1e-3      # the true ones would differ


def test_prediction_with_a_complete_plant_uses_the_controllers_model():
    """The plant is the complete Panda (more parameters than the law's model); prediction runs and
    predicts with the reduced nominal model (python and CasADi steps agree)."""
    from fjm_runtime.control.coupling import complete_plant
    plant = complete_plant("panda_complete")
    red = fjm_runtime.load("panda")
    ctrl = make_controller("ismc", red, nominal_params={}, lam=40, k_s=200, delta=10, sensing="torque")
    from fjm_runtime.sim.rest import rest_state
    q0 = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
    x0 = rest_state(red, q0, None)                          # the reduced rest state, as the demo
    ref = make_reference("constant", 7, q_d=q0)
    runs = [simulate(plant, ctrl, ref, duration=0.004, x0=x0, delay_samples=1, predict=True, backend=b)
            for b in ("casadi", "python")]
    assert np.all(np.isfinite(runs[0].u))
    assert np.max(np.abs(runs[0].u - runs[1].u)) < 1e-9


def _kinematic_model(n=1):
    """A fake plant whose angles move at constant velocity (f = [dq; 0; dq_m; 0], no input)."""
    class Ramp:
        name, nx, param_names = "ramp", 4 * n, ()

        def f(self, x, p):
            return np.concatenate([x[n:2 * n], np.zeros(n), x[3 * n:4 * n], np.zeros(n)])

        def g(self, x, p):
            return np.zeros((4 * n, n))
    m = Ramp()
    m.n = n
    return m


class _Zero:
    sensing, n_states, p_nom = "state", 0, np.zeros(0)

    def __init__(self):
        self.seen = []

    def evaluate(self, t, m, z, r):
        self.seen.append(np.array(m))
        z1 = np.zeros(1)
        return ControlSample(u=z1, u_cmd=z1, s=z1, y_hat=np.zeros((4, 1)), e=np.zeros((4, 1)),
                             saturated=np.zeros(1, dtype=bool))


def test_velocity_from_a_quantized_ramp_has_the_slope_as_mean_and_quantization_noise():
    step, T, cutoff, v = 1e-3, 1e-3, 300.0, 0.7318          # v T / step = 0.73...: the error is well mixed
    sensor = SensorModel(q_quant=step, q_m_quant=step, velocity_mode="differentiated", velocity_cutoff=cutoff)
    model, law = _kinematic_model(), _Zero()
    L = make_layout(model, law, T, 1, sensor, 0, False, interface=CommandInterface.ideal())   # g = 0: no actuator
    w = initial_step_state(model, L, np.array([0.0, v, 0.0, v]), np.zeros(0), np.zeros(0))
    N = 20000
    for k in range(N):
        w, _ = python_sample_step(model, law, L, w, k * T, np.zeros(5), np.zeros(4), np.zeros(0))
    dq = np.array([m[1] for m in law.seen[1000:]])
    # first principles: e_k uniform white (variance step^2 / 12) through (1 - z^-1) / T and the
    # first-order filter a / (1 - (1 - a) z^-1): var = step^2 / 12 * sum_j g_j^2
    a = 1 - math.exp(-cutoff * T)
    h = a * (1 - a) ** np.arange(2000)
    g = np.concatenate([h, [0.0]]) - np.concatenate([[0.0], h])
    std_theory = math.sqrt(step ** 2 / 12 * np.sum((g / T) ** 2))
    assert abs(np.mean(dq) - v) < 0.01 * v
    assert abs(np.std(dq) / std_theory - 1) < 0.15
    assert np.std(dq) > 0.2 * step / T * a                   # not a filter that hides the steps


def test_velocity_noise_is_the_angle_noise_differentiated():
    """With velocity_mode='differentiated' the dq slot is silent and dq_m's slot carries q_m's noise."""
    s = SensorModel(q=1e-3, dq=5.0, q_m=2e-3, dq_m=7.0, tau_J=0.1, velocity_mode="differentiated", seed=4)
    n = 2
    noise = noise_array(s, "torque", n, 3)
    assert np.all(noise[:, n:2 * n] == 0)                    # no independent dq noise
    same = noise_array(replace(s, velocity_mode="measured", dq_m=0.0), "state", n, 3)
    assert np.allclose(noise[:, 4 * n:5 * n], same[:, 2 * n:3 * n])   # q_m's own numbers and level


def test_tau_offset_is_one_constant_per_run(link1):
    spy = Spy(_torque_law(link1, 150.0))
    sensor = SensorModel(tau_J_offset=0.3, seed=9)
    L = make_layout(link1, spy, 1e-3, 1, sensor, 0, False)
    x = np.array([0.3, 0.0, 0.31, 0.0])
    p = link1.params_array({})
    w = initial_step_state(link1, L, x, np.zeros(L.nz), p, seed=9, sensor=sensor)
    for k in range(3):
        w, _ = python_sample_step(link1, spy, L, w, k * 1e-3, np.zeros(5), np.zeros(L.nm), p)
    offset = 0.3 * offset_normals(9, 1)[0]
    true_tau = [150.0 * (wk[2] - wk[0]) for wk in [x]]
    assert spy.seen[0][2] - true_tau[0] == pytest.approx(offset, abs=1e-12)
    assert abs(offset) > 1e-3
    w2 = initial_step_state(link1, L, x, np.zeros(L.nz), p, seed=10, sensor=sensor)
    assert w2[L.extra_slices()[1]][0] != pytest.approx(offset)     # another run, another offset


def test_presets_and_files(tmp_path):
    f = sensor_from_spec("franka_like")
    assert (f.velocity_mode, f.name) == ("differentiated", "franka_like")
    assert sensor_from_spec("ideal").is_ideal() and not f.is_ideal()
    assert sensor_from_spec("panda") == SensorModel.panda_white()
    path = tmp_path / "arm.toml"
    path.write_text('preset = "franka_like"\ntau_J = 0.1\nq = [1e-5, 2e-5]\n')
    s = sensor_from_spec(str(path), seed=5)
    assert (s.tau_J, s.q, s.seed, s.name) == (0.1, (1e-5, 2e-5), 5, "arm")
    assert s.velocity_mode == "differentiated"
    assert SensorModel.from_dict(s.as_dict()) == s


@pytest.mark.parametrize("text, needle", [
    ('tau_J = "loud"', "tau_J"), ("tau_J = -1.0", "tau_J"), ('preset = "robot"', "preset"),
    ("volume = 3", "volume"), ("torque_rate_limit = 0", "torque_rate_limit"), ('torque_rate_limit = "inf"', "interface"),
    ("q = [", "TOML"),
    ('velocity_mode = "guess"', "velocity_mode")])
def test_bad_sensor_files_are_one_line_errors(tmp_path, text, needle):
    path = tmp_path / "bad.toml"
    path.write_text(text + "\n")
    with pytest.raises(FjmValueError) as exc:
        sensor_from_spec(str(path))
    assert "\n" not in str(exc.value) and needle in str(exc.value) and "bad.toml" in str(exc.value)


def test_unknown_preset_names_the_choices():
    with pytest.raises(FjmValueError, match="franka_like"):
        sensor_from_spec("franka")
