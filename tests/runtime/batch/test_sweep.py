"""Dask sweep on a local 2-worker cluster == simulate_batch on the same samples."""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.batch.runner import simulate_batch
from fjm_runtime.batch.sweep import SweepSpec, _build, sample_parameters, sweep, write_table

SPEC = SweepSpec(model="link1", controller="smc", controller_options={"lam": 6.0, "k_s": 20.0, "delta": 0.5},
                 reference="sine", reference_options={"amplitude": 0.5, "omega": 1.0}, duration=1.0, dt=1e-3)


def test_sampling_is_seeded_and_within_bounds():
    m = fjm_runtime.load("link1")
    P = sample_parameters(m, 50, seed=3)
    np.testing.assert_array_equal(P, sample_parameters(m, 50, seed=3))
    K = P[:, m.param_names.index("K")]
    Jl = P[:, m.param_names.index("J_l")]
    assert K.min() >= 100 and K.max() <= 200 and K.std() > 10
    assert Jl.min() >= 0.8 and Jl.max() <= 1.2
    with pytest.raises(ValueError, match="k_range"):
        sample_parameters(m, 5, k_range=(200, 100))
    with pytest.raises(ValueError, match="n_samples"):
        sample_parameters(m, 0)


def test_dask_sweep_equals_simulate_batch(tmp_path):
    model, controller, reference = _build(SPEC)
    P = sample_parameters(model, 6, seed=1)
    done = []
    got = sweep(SPEC, P, chunk_size=2, n_workers=2, progress=lambda d, t: done.append((d, t)))
    ref = simulate_batch(model, controller, reference, P, duration=SPEC.duration, dt=SPEC.dt)
    assert done[-1] == (3, 3)
    for k, v in ref.metrics.items():
        np.testing.assert_allclose(got[k], v, rtol=1e-12, atol=1e-12, err_msg=k)
    assert not got["diverged"].any()
    path = write_table(tmp_path / "sweep.csv", model, P, got)
    lines = path.read_text().splitlines()
    assert len(lines) == 7 and lines[0].startswith("run,J_l,J_m,K")


def test_cli_sweep_writes_the_table(tmp_path, capsys):
    from fjm_runtime.cli.main import main
    out = tmp_path / "s.csv"
    rc = main(["sweep", "link1", "--samples", "4", "--chunk", "2", "--duration", "0.5", "--out", str(out)])
    assert rc == 0
    rows = out.read_text().splitlines()
    assert len(rows) == 5 and "rms_error_second_half" in rows[0]
    assert '"runs": 4' in capsys.readouterr().out


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_sampled_sweep_on_a_cluster_equals_one_local_batch():
    """Noise, delay, prediction and torque sensing on 2 threaded workers, 3 chunks == simulate_batch, bit for bit."""
    from dask.distributed import Client, LocalCluster
    from fjm_runtime.batch.runner import simulate_batch
    from fjm_runtime.batch.sweep import SweepSpec, _build, resolve_spec, sample_parameters, sweep
    from fjm_runtime.sim.sensor import SensorModel
    spec = SweepSpec(model="planar2", controller="ismc", controller_options={"lam": 10.0, "k_s": 100.0, "delta": 1.0},
                     reference_options={"amplitude": 0.3, "omega": 1.0}, duration=0.4, dt=2e-3, sensing="torque",
                     sensor=SensorModel.panda_white(seed=7), delay_samples=1, predict=True)
    model, controller, reference = _build(spec)
    P = sample_parameters(model, 7, seed=2, k_range=(100.0, 3000.0))    # rows that need 4..6 substeps
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cl, \
            Client(cl) as client:
        got = sweep(spec, P, chunk_size=3, scheduler=client)
    subs = resolve_spec(spec, P).substeps
    ref = simulate_batch(model, controller, reference, P, duration=0.4, dt=2e-3, sensor=spec.sensor, delay_samples=1,
                         predict=True, substeps=subs, seeds=7 + np.arange(7))
    for k, v in ref.metrics.items():
        np.testing.assert_array_equal(got[k], v, err_msg=k)
    for k, v in ref.joint_metrics.items():
        for j in range(2):
            np.testing.assert_array_equal(got[f"{k}_{j + 1}"], v[:, j], err_msg=k)
    shifted = simulate_batch(model, controller, reference, P, duration=0.4, dt=2e-3, sensor=spec.sensor,
                             delay_samples=1, predict=True, substeps=subs, seeds=8 + np.arange(7))
    assert not np.any(ref.diverged) and subs == 6
    assert not np.array_equal(shifted.metrics["rms_error"], got["rms_error"])  # the seeds matter
