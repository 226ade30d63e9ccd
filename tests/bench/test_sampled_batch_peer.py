"""The sampled-batch section's CasADi map peer does THE batch's work, run by run (bench/sampled_batch.py)."""
import numpy as np

from bench.sampled_batch import DELAY, DT, PEER_TOLERANCE, casadi_map_peer


def test_map_peer_gives_each_run_its_own_parameters_and_seed():
    """Three link1 plants with different K, torque sensing with noise, one-sample delay: the peer
    equals simulate_batch to rounding run by run (it used to feed run i the parameters of run
    (i N + k) % B at sample k: CasADi tiles a B-column input of a map of a mapaccum)."""
    import fjm_runtime
    from fjm_runtime.batch.runner import simulate_batch
    from fjm_runtime.control.factory import make_controller
    from fjm_runtime.control.references import make_reference
    from fjm_runtime.sim.sensor import SensorModel
    m = fjm_runtime.load("link1")
    ctrl = make_controller("ismc", m, {}, sensing="torque", lam=8.0, k_s=1000.0, delta=5.0)
    ref = make_reference("sine", 1, amplitude=0.5, omega=1.0)
    P = np.tile(m.params_array({}), (3, 1))
    P[:, list(m.param_names).index("K")] = [100.0, 150.0, 200.0]
    sensor = SensorModel.panda_white(seed=5)
    x0 = np.array([0.1, 0.0, 0.1, 0.0])
    seeds = 5 + np.arange(3)
    b = simulate_batch(m, ctrl, ref, P, duration=0.02, dt=DT, sensor=sensor, delay_samples=DELAY, simd=False,
                       seeds=seeds, x0=x0, substeps=4)
    _, x_fin = casadi_map_peer(m, ctrl, ref, P, sensor, 4, 1, 0.02, x0, seeds)
    assert np.max(np.abs(x_fin - b.x_final)) <= PEER_TOLERANCE
    _, x_off = casadi_map_peer(m, ctrl, ref, P, sensor, 4, 1, 0.02, x0, seeds + 1)   # seeds off by one
    assert np.max(np.abs(x_off - b.x_final)) > 1e3 * PEER_TOLERANCE
