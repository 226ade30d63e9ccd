"""simulate_batch folds THE sample step: each row == simulate() on the same TRUE parameters and seed
(sensor noise generated in C == sensor.py's generator), scalar and SIMD, per-joint metrics included."""
import warnings

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.batch.runner import simulate_batch
from fjm_runtime.batch.sampled_runner import JOINT_METRICS, batch_seeds
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import make_reference
from fjm_runtime.sim import metrics as M
from fjm_runtime.sim.interface import CommandInterface
from fjm_runtime.sim.sensor import SensorModel
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.sim.step import SimulationDivergedError
from fjm_runtime.validation import FjmValueError

pytestmark = pytest.mark.slow

WHOLE = ("final_error", "rms_error", "rms_error_second_half", "max_abs_u", "total_variation_u")


def _joint(res):
    return {"rms_second_half": M.rms_second_half(res), "peak_torque": M.peak_torque(res),
            "time_at_limit": M.time_at_limit(res), "torque_jitter": M.torque_jitter(res)}


def _compare(model, ctrl, ref, P, duration, sensor, delay, predict, simd, interface=None):
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # a SIMD fallback would hide the SIMD path
        b = simulate_batch(model, ctrl, ref, P, duration=duration, sensor=sensor, delay_samples=delay,
                           predict=predict, simd=simd, threads=1, interface=interface)
    assert b.info["path"].startswith("simd") == simd
    assert not np.any(b.diverged)
    for i in range(P.shape[0]):
        r = simulate(model, ctrl, ref, duration=duration, true_params=P[i], sensor=sensor.with_seed(int(b.seeds[i])),
                     delay_samples=delay, predict=predict, substeps=b.info["substeps"], backend="compiled",
                     interface=interface)
        assert np.max(np.abs(r.x[-1] - b.x_final[i])) < 1e-9
        for k, v in _joint(r).items():
            assert np.allclose(b.joint_metrics[k][i], v, rtol=1e-9, atol=1e-9), k
        for k in WHOLE:
            assert b.metrics[k][i] == pytest.approx(getattr(r.metrics, k), rel=1e-9, abs=1e-9), k
    return b


@pytest.mark.parametrize("simd", [False, True])
def test_link1_torque_sensed_rows_equal_simulate(simd):
    m = fjm_runtime.load("link1")
    ctrl = make_controller("ismc", m, {}, sensing="torque", lam=20.0, k_s=50.0, delta=1.0, k_lin=10.0, u_max=50.0)
    ref = make_reference("sine", 1, amplitude=0.5, omega=2.0)
    P = np.tile(m.params_array({}), (3, 1))
    iK = m.param_names.index("K")
    P[:, iK] *= np.array([0.7, 1.0, 1.3])
    b = _compare(m, ctrl, ref, P, 0.3, SensorModel.panda_white(seed=11), 1, False, simd)
    assert np.any(b.joint_metrics["time_at_limit"] > 0) or np.all(b.joint_metrics["peak_torque"] < 50.0)
    assert len(set(b.joint_metrics["torque_jitter"][:, 0])) == 3   # each row its own noise and plant


@pytest.mark.parametrize("simd", [False, True])
@pytest.mark.parametrize("interface", [CommandInterface(current_bandwidth_hz=500.0, torque_rate_limit=300.0),
                                       CommandInterface(kind="joint_torque", lowpass_cutoff_hz=100.0, K_T=-0.5,
                                                        D_T=0.01, torque_rate_limit=400.0)])
def test_each_interface_rows_equal_simulate(simd, interface):
    """The current loop, the vendor filter, the rate limit, the nominal gravity and the inner torque loop
    in the batch engine (scalar and SIMD) equal the single runs."""
    m = fjm_runtime.load("planar2")
    ctrl = make_controller("ismc", m, {}, sensing="torque", lam=10.0, k_s=20.0, delta=0.5, u_max=200.0)
    ref = make_reference("sine", 2, amplitude=0.3, omega=1.5)
    P = np.tile(m.params_array({}), (2, 1))
    P[1, [m.param_names.index("K1"), m.param_names.index("K2")]] *= [0.8, 1.2]
    b = _compare(m, ctrl, ref, P, 0.2, SensorModel.franka_like(seed=3), 1, True, simd, interface)
    assert b.info["interface"] == interface.name


@pytest.mark.parametrize("simd", [False, True])
def test_planar2_state_feedback_prediction_rows_equal_simulate(simd):
    m = fjm_runtime.load("planar2")
    ctrl = make_controller("smc", m, {}, lam=10.0, k_s=20.0, delta=0.5, u_max=200.0)
    ref = make_reference("sine", 2, amplitude=0.3, omega=1.5)
    P = np.tile(m.params_array({}), (2, 1))
    P[1, [m.param_names.index("K1"), m.param_names.index("K2")]] *= [0.8, 1.2]
    sensor = SensorModel(q=1e-4, dq=1e-3, q_m=1e-4, dq_m=1e-3, q_quant=1e-5, seed=3)
    _compare(m, ctrl, ref, P, 0.2, sensor, 2, True, simd)


def test_seeds_array_and_default_seed_plus_index():
    s = SensorModel.panda_white(seed=40)
    assert batch_seeds(s, 3).tolist() == [40, 41, 42]
    assert batch_seeds(s, 2, [7, 9]).tolist() == [7, 9]
    with pytest.raises(FjmValueError, match="seeds"):
        batch_seeds(s, 2, [1])


def test_per_run_gains_equal_controllers_built_with_them():
    m = fjm_runtime.load("link1")
    ref = make_reference("sine", 1, amplitude=0.5, omega=2.0)
    kw = dict(sensing="torque", k_lin=10.0, u_max=50.0)
    a = make_controller("ismc", m, {}, lam=20.0, k_s=50.0, delta=1.0, **kw)
    c = make_controller("ismc", m, {}, lam=35.0, k_s=10.0, delta=0.2, **kw)
    P = np.tile(m.params_array({}), (2, 1))
    sensor = SensorModel.panda_white(seed=2)
    b = simulate_batch(m, a, ref, P, duration=0.2, sensor=sensor, gains=np.vstack([a.gains, c.gains]),
                       seeds=[5, 5], simd=False)
    one = simulate_batch(m, c, ref, P[:1], duration=0.2, sensor=sensor, seeds=[5], simd=False)
    assert np.max(np.abs(b.x_final[1] - one.x_final[0])) < 1e-12
    assert np.max(np.abs(b.x_final[0] - b.x_final[1])) > 1e-6     # the gains do act
    with pytest.raises(FjmValueError, match="gains"):
        simulate_batch(m, a, ref, P, duration=0.2, gains=np.zeros((2, 3)), simd=False)


@pytest.mark.filterwarnings("ignore")
def test_short_run_has_nan_jitter_and_divergence_is_flagged():
    m = fjm_runtime.load("link1")
    ref = make_reference("sine", 1, amplitude=0.5, omega=1.0)
    ctrl = make_controller("smc", m, {}, lam=10.0, k_s=50.0, delta=1.0)
    P = np.tile(m.params_array({}), (2, 1))
    P[1, m.param_names.index("K")] *= 1e7       # one RK4 step per sample cannot hold this spring
    b = simulate_batch(m, ctrl, ref, P[:1], duration=0.015, simd=False)
    assert np.isnan(b.joint_metrics["torque_jitter"][0, 0])    # 15 samples < the 21-sample window
    assert np.isfinite(b.joint_metrics["rms_second_half"][0, 0])
    long = simulate_batch(m, ctrl, ref, P, duration=1.0, simd=False, substeps=1)
    simulate(m, ctrl, ref, duration=1.0, true_params=P[0], substeps=1)
    with pytest.raises(SimulationDivergedError) as exc:
        simulate(m, ctrl, ref, duration=1.0, true_params=P[1], substeps=1)
    assert long.divergence_time[1] == pytest.approx(exc.value.t, abs=1e-12)
    assert long.diverged.tolist() == [False, True]
    assert all(np.isnan(long.joint_metrics[k][1]).all() for k in JOINT_METRICS)


@pytest.mark.exhaustive  # a cold Panda batch build (~20 s); batch/test_sampled.py builds the Panda step in make test
def test_panda_smoke():
    m = fjm_runtime.load("panda")
    u_max = [87.0] * 4 + [12.0] * 3
    ctrl = make_controller("ismc", m, {}, sensing="torque", lam=80.0, k_lin=400.0, k_s=2000.0, delta=10.0,
                           u_max=u_max)
    ref = make_reference("sine", 7, amplitude=0.2, omega=1.0)
    P = np.tile(m.params_array({}), (2, 1))
    P[1, [m.param_names.index(f"K{i + 1}") for i in range(7)]] *= 0.7
    sensor = SensorModel.panda_white(seed=1)
    b = simulate_batch(m, ctrl, ref, P, duration=0.2, sensor=sensor, delay_samples=1, simd=False, threads=2)
    r = simulate(m, ctrl, ref, duration=0.2, true_params=P[1], sensor=sensor.with_seed(2), delay_samples=1,
                 substeps=b.info["substeps"], backend="compiled")
    assert np.max(np.abs(r.x[-1] - b.x_final[1])) < 1e-9
    assert np.allclose(b.joint_metrics["torque_jitter"][1], M.torque_jitter(r), rtol=1e-9, atol=1e-9)
