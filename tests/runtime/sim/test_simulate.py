"""simulate (fjm_runtime.sim.simulate), THE sampled-data loop: zero-order hold, the delay against a reference loop
written here, noise reproducibility and equality across backends, bad input named by its field, divergence
reported with its time."""
import numpy as np
import pytest

from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.laws import SlidingModeController
from fjm_runtime.control.references import Sinusoid
from fjm_runtime.sim.sensor import SensorModel
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.sim.step import SimulationDivergedError
from fjm_runtime.validation import FjmValueError
from support.numerics import rk4
from support.sampled_loop import ismc_controller


def test_zero_order_hold_and_once_per_sample_controller_state(link1):
    """u is constant within a sample: the plant under u_k equals a hand-written RK4 under that constant."""
    ctrl = ismc_controller(link1)
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
    ctrl = ismc_controller(link1)
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
    ctrl = ismc_controller(m)
    ref = Sinusoid(0.5, 1.0, n=m.n)
    runs = {b: simulate(m, ctrl, ref, duration=0.3, backend=b, sensor=SENSOR, delay_samples=2, predict=True,
                        substeps=3) for b in ("python", "casadi", "compiled")}
    for b in ("casadi", "compiled"):
        assert np.max(np.abs(runs[b].x - runs["python"].x)) < 1e-9
        assert np.max(np.abs(runs[b].u - runs["python"].u)) < 1e-9
        assert np.max(np.abs(runs[b].z - runs["python"].z)) < 1e-9


def test_noise_is_reproducible_by_seed_and_changes_the_run(planar2):
    ctrl = ismc_controller(planar2)
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
        simulate(link1, ismc_controller(link1), Sinusoid(0.5, 1.0), duration=0.01, **kw)
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
        simulate(link1, ismc_controller(link1), Sinusoid(0.5, 1.0), duration=0.01, loop=loop)
    msg = str(exc.value)
    assert "\n" not in msg and f"loop = {loop!r}" in msg
    assert msg.endswith("expected 'sampled'")


@pytest.mark.parametrize("kwargs, field", [
    ({"duration": 0.0}, "duration"),
    ({"duration": float("inf")}, "duration"),
    ({"dt": 0.0}, "dt"),
    ({"dt": 2.0}, "dt"),
    ({"x0": np.zeros(3)}, "x0"),
    ({"x0": [0.0, np.nan, 0.0, 0.0]}, "x0"),
    ({"true_params": {"K": np.nan}}, "true_params"),
    ({"true_params": {"K": -100.0}}, "true_params"),
    ({"true_params": np.ones(3)}, "true_params"),
    ({"backend": "gpu"}, "backend"),
])
def test_simulate_rejects_bad_inputs(link1, kwargs, field):
    args = {"duration": 1.0}
    args.update(kwargs)
    ctrl = SlidingModeController(link1, {}, lam=5.0, k_s=10.0, delta=1.0)
    with pytest.raises(ValueError, match=field):
        simulate(link1, ctrl, Sinusoid(0.5, 1.0), **args)


def test_simulate_rejects_reference_for_wrong_joint_count(link1):
    ctrl = SlidingModeController(link1, {}, lam=5.0, k_s=10.0, delta=1.0)
    with pytest.raises(ValueError, match="reference"):
        simulate(link1, ctrl, Sinusoid(0.5, 1.0, n=2), duration=1.0)


@pytest.mark.parametrize("backend", ["casadi", "python"])
def test_divergence_reports_time(link1, backend):
    # a linear gain far beyond what a 1 ms zero-order hold can take: the sampled loop is unstable
    ctrl = SlidingModeController(link1, {}, lam=5.0, mode="fl", k_lin=5.0e3)
    with pytest.raises(SimulationDivergedError, match=r"diverged at t = \d") as info:
        simulate(link1, ctrl, Sinusoid(0.5, 1.0), duration=2.0, backend=backend)
    assert 0.0 < info.value.t < 2.0
