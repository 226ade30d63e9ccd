"""The sampled-data loop: substep convergence, zero-order hold, the delay against a reference loop
written here, noise reproducibility and equality across backends, the substep warning, bad input."""
import warnings

import numpy as np
import pytest

from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import Sinusoid
from fjm_runtime.sim.sensor import SensorModel
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.sim.substeps import CoarseIntegrationWarning, fastest_mode, resolve_substeps
from fjm_runtime.validation import FjmValueError
from support.numerics import rk4


def _ismc(m, **kw):
    kw.setdefault("lam", 8.0)
    kw.setdefault("k_s", 100.0)
    kw.setdefault("delta", 2.0)
    return make_controller("ismc", m, {}, **kw)


def test_fastest_mode_equals_the_link1_formula(link1):
    # link1: D = J_l, so omega^2 = K / J_l + K / J_m (independent of q)
    p = link1.params_array({"K": 180.0, "J_l": 0.7, "J_m": 1.9})
    x0 = np.array([0.4, 0.1, -0.2, 0.3])
    assert fastest_mode(link1, x0, p) == pytest.approx(np.sqrt(180.0 / 0.7 + 180.0 / 1.9), rel=1e-12)


def test_fastest_mode_uses_the_inverse_inertia_diagonal(planar2):
    p = planar2.params_array({})
    x0 = np.array([0.3, -0.5, 0, 0, 0.3, -0.5, 0, 0], dtype=float)
    D = np.asarray(planar2.inertia(x0, p), dtype=float).reshape(2, 2)
    K = p[[planar2.param_names.index("K1"), planar2.param_names.index("K2")]]
    Jm = p[[planar2.param_names.index("Jm1"), planar2.param_names.index("Jm2")]]
    expected = np.max(np.sqrt(K * np.diag(np.linalg.inv(D)) + K / Jm))
    assert fastest_mode(planar2, x0, p) == pytest.approx(expected, rel=1e-9)


def test_substeps_converge_to_a_ten_times_finer_reference(planar2):
    """The default rule's plant equals a 10x finer one to 1e-8 rad (planar2, 2 s at 1 kHz, stiff joints)."""
    ctrl = _ismc(planar2)
    stiff = {"K1": 4e4, "K2": 4e4}
    ref = Sinusoid(0.5, 1.0, n=2)
    S = resolve_substeps(None, planar2, np.zeros(8), planar2.params_array(stiff), 1e-3)
    assert S > 1                                   # the rule asks for substeps on this stiff plant
    ideal = "ideal"                                # the rule is for the plant under a held torque
    a = simulate(planar2, ctrl, ref, duration=2.0, true_params=stiff, interface=ideal)
    b = simulate(planar2, ctrl, ref, duration=2.0, true_params=stiff, substeps=10 * S, interface=ideal)
    with pytest.warns(CoarseIntegrationWarning):  # deliberately coarse: the warning is part of the contract
        c = simulate(planar2, ctrl, ref, duration=2.0, true_params=stiff, substeps=1, interface=ideal)
    assert a.settings["substeps"] == S
    err = np.max(np.abs(a.x[:, :2] - b.x[:, :2]))
    assert err < 1e-8
    assert np.max(np.abs(c.x[:, :2] - b.x[:, :2])) > 10 * err   # one step per sample is measurably worse


def test_coarse_substeps_warn_in_one_line(planar2):
    stiff = {"K1": 4e4, "K2": 4e4}
    with pytest.warns(CoarseIntegrationWarning) as rec:
        simulate(planar2, _ismc(planar2), Sinusoid(0.5, 1.0, n=2), duration=0.01, true_params=stiff, substeps=1)
    msg = str(rec[0].message)
    assert "\n" not in msg and "omega_max" in msg and "rule" in msg
    with warnings.catch_warnings():
        warnings.simplefilter("error", CoarseIntegrationWarning)
        simulate(planar2, _ismc(planar2), Sinusoid(0.5, 1.0, n=2), duration=0.01, true_params=stiff)


def test_zero_order_hold_and_once_per_sample_controller_state(link1):
    """u is constant within a sample: the plant under u_k equals a hand-written RK4 under that constant."""
    ctrl = _ismc(link1)
    res = simulate(link1, ctrl, Sinusoid(0.5, 1.0), duration=0.05, substeps=4, true_params={"K": 120.0},
                   backend="python", interface="ideal")
    p = link1.params_array({"K": 120.0})
    T, h = 1e-3, 1e-3 / 4
    for k in (0, 17, 42):
        x = res.x[k].copy()
        u = res.u[k]
        rhs = lambda w: np.asarray(link1.f(w, p)).ravel() + np.asarray(link1.g(w, p)).reshape(4, 1) @ u
        x = rk4(rhs, x, h, 4)[-1]
        assert np.max(np.abs(x - res.x[k + 1])) < 1e-13
        # z_{k+1} = z_k + T e1_k (the integrator of a digital controller, e1 from the measurement)
        e1 = res.x[k, 0] - res.ref[k, 0, 0]
        assert res.z[k + 1, 0] == pytest.approx(res.z[k, 0] + T * e1, abs=1e-15)


def _reference_delay_loop(m, ctrl, ref, p_true, d, n_samples):
    """A plain loop: the law at sample k sees x_{k-d} (x_0 before the start), RK4 under held u."""
    n, nx = m.n, m.nx
    x = np.zeros(nx); x[0] = x[2] = ref(0.0)[0, 0]
    z = np.zeros(ctrl.n_states)
    hist, us = [x.copy()] * d, []
    for k in range(n_samples):
        seen = hist[0] if d else x
        hist = (hist[1:] + [x.copy()]) if d else hist
        r = ref(k * 1e-3)
        smp = ctrl.evaluate(k * 1e-3, seen, z, r)
        z = z + 1e-3 * ctrl.state_derivative(k * 1e-3, seen, z, r, smp)
        us.append(smp.u)
        rhs = lambda w, u=smp.u: np.asarray(m.f(w, p_true)).ravel() + np.asarray(m.g(w, p_true)).reshape(nx, n) @ u
        x = rk4(rhs, x, 1e-3, 1)[-1]
    return np.array(us)


@pytest.mark.parametrize("d", [1, 3])
def test_delay_shifts_the_controller_input(link1, d):
    ctrl = _ismc(link1)
    ref = Sinusoid(0.5, 1.0)
    p = link1.params_array({"K": 130.0})
    res = simulate(link1, ctrl, ref, duration=0.1, true_params=p, delay_samples=d, substeps=1, interface="ideal")
    u_ref = _reference_delay_loop(link1, ctrl, ref, p, d, 100)
    assert np.max(np.abs(res.u[:100, 0] - u_ref[:, 0])) < 1e-9
    undelayed = simulate(link1, ctrl, ref, duration=0.1, true_params=p, substeps=1, interface="ideal")
    assert np.max(np.abs(res.u - undelayed.u)) > 1e-3          # the delay is not a no-op


def test_prediction_undoes_the_delay_with_an_exact_model(link1):
    """Exact nominal model, no noise: predicting d samples ahead gives the undelayed loop."""
    ctrl = make_controller("smc", link1, {}, lam=8.0, k_s=100.0, delta=2.0)
    ref = Sinusoid(0.5, 1.0)
    kw = dict(duration=0.2, substeps=2, interface="ideal")   # the predictor's model has no current loop
    base = simulate(link1, ctrl, ref, **kw)
    pred = simulate(link1, ctrl, ref, delay_samples=2, predict=True, **kw)
    late = simulate(link1, ctrl, ref, delay_samples=2, **kw)
    # after the first d samples (the fictitious history before t = 0) the prediction is exact
    k0 = 50
    assert np.max(np.abs(pred.u[k0:] - base.u[k0:])) < 1e-3 * np.max(np.abs(late.u[k0:] - base.u[k0:]))


SENSOR = SensorModel(q=1e-3, dq=1e-2, q_m=2e-3, dq_m=1e-2, q_quant=1e-4, q_m_quant=2e-4, seed=11)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["link1", "planar2"])
def test_backends_agree_with_noise_delay_and_substeps(name, request):
    m = request.getfixturevalue(name)
    ctrl = _ismc(m)
    ref = Sinusoid(0.5, 1.0, n=m.n)
    runs = {b: simulate(m, ctrl, ref, duration=0.3, backend=b, sensor=SENSOR, delay_samples=2, predict=True,
                        substeps=3) for b in ("python", "casadi", "compiled")}
    for b in ("casadi", "compiled"):
        assert np.max(np.abs(runs[b].x - runs["python"].x)) < 1e-9
        assert np.max(np.abs(runs[b].u - runs["python"].u)) < 1e-9
        assert np.max(np.abs(runs[b].z - runs["python"].z)) < 1e-9


def test_noise_is_reproducible_by_seed_and_changes_the_run(planar2):
    ctrl = _ismc(planar2)
    ref = Sinusoid(0.5, 1.0, n=2)
    a = simulate(planar2, ctrl, ref, duration=0.1, sensor=SENSOR)
    b = simulate(planar2, ctrl, ref, duration=0.1, sensor=SENSOR)
    c = simulate(planar2, ctrl, ref, duration=0.1, sensor=SENSOR.with_seed(12))
    clean = simulate(planar2, ctrl, ref, duration=0.1)
    assert np.array_equal(a.u, b.u)
    assert np.max(np.abs(a.u - c.u)) > 1e-6
    assert np.max(np.abs(a.u - clean.u)) > 1e-6


@pytest.mark.parametrize("kw, text", [
    ({"delay_samples": -1}, "delay_samples"),
    ({"delay_samples": 1.5}, "delay_samples"),
    ({"substeps": 0}, "substeps"),
    ({"sensor": "panda"}, "SensorModel"),
])
def test_bad_settings_are_one_line_errors(link1, kw, text):
    with pytest.raises(FjmValueError) as exc:
        simulate(link1, _ismc(link1), Sinusoid(0.5, 1.0), duration=0.01, **kw)
    assert text in str(exc.value) and "\n" not in str(exc.value)


def test_one_substep_and_a_stateless_law_is_the_former_single_step_loop(link1):
    """substeps=1, ideal sensor, no delay, a stateless law: one RK4 step of x per sample under the law's
    u_k = law(x_k) held (the retired loop='legacy'), written here as the plain loop above with d = 0."""
    ctrl = make_controller("smc", link1, {}, lam=8.0, k_s=100.0, delta=2.0)
    ref = Sinusoid(0.5, 1.0)
    p = link1.params_array({"K": 130.0})
    res = simulate(link1, ctrl, ref, duration=0.2, true_params=p, substeps=1, backend="compiled", interface="ideal")
    us = _reference_delay_loop(link1, ctrl, ref, p, 0, 200)
    assert np.max(np.abs(res.u[:200] - us)) < 1e-9 * max(1.0, np.max(np.abs(us)))


@pytest.mark.parametrize("loop", ["legacy", "continuous"])
def test_only_the_sampled_loop_is_accepted(link1, loop):
    """loop='sampled' is the one loop: the retired 'legacy' and any other name are a one-line error."""
    with pytest.raises(FjmValueError) as exc:
        simulate(link1, _ismc(link1), Sinusoid(0.5, 1.0), duration=0.01, loop=loop)
    msg = str(exc.value)
    assert "\n" not in msg and f"loop = {loop!r}" in msg
    assert msg.endswith("expected 'sampled'")
