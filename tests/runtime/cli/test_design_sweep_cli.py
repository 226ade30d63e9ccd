"""fjm design's exit status and verdict on the terminal, its flags' one-line errors, and fjm sweep's
sampled-loop settings (sensing, rate, delay, prediction, noise, gains file) on a dask cluster."""
import json

import numpy as np
import pytest

from fjm_runtime.cli.main import main
from fjm_runtime.sim.interface import CommandInterface

QUICK = ["--draws", "3", "--duration", "0.3", "--screen-draws", "3", "--screen-duration", "0.2", "--rounds", "1",
         "--seed", "5", "--task", "sine"]


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_design_that_misses_exits_1_names_the_miss_and_records_it(tmp_path, capsys):
    out = tmp_path / "g.json"
    rc = main(["design", "link1", "--noise", "panda_white", "--recheck-draws", "2", "--out", str(out), *QUICK])
    err = capsys.readouterr().err
    assert rc == 1
    rec = json.loads(out.read_text())
    assert rec["meets"] is False and rec["misses"] and rec["recheck"]["draws"] == 0
    jit = [m for m in rec["misses"] if m["threshold"] == "jitter"][0]
    assert jit["joint"] == 1 and jit["limit"] == 3.0 and jit["value"] > 3.0
    assert f"jitter {jit['value']:.3g} N m on joint 1 > 3 N m by {jit['excess']:.3g} N m (draw {jit['draw']}" in err
    assert '"meets": false' in err and rec["noise"] == "panda_white" and rec["sensor"]["name"] == "panda_white"


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_design_that_meets_exits_0_after_the_recheck(tmp_path, capsys):
    out = tmp_path / "g.json"
    rc = main(["design", "link1", "--noise", "ideal", "--max-rms", "0.5", "--max-jitter", "1e4", "--max-at-limit",
               "100", "--recheck-draws", "2", "--out", str(out), *QUICK])
    err = capsys.readouterr().err
    rec = json.loads(out.read_text())
    assert rc == 0 and rec["meets"] is True and rec["misses"] == []
    assert rec["recheck"]["draws"] == 2 and rec["recheck"]["meets"] is True and "re-checked on 2 fresh draws" in err
    assert rec["thresholds"] == {"max_rms": 0.5, "max_jitter": 1e4, "max_at_limit": 1.0, "jitter_joints": [1]}


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_design_params_file_reaches_the_controller_and_the_record(tmp_path, capsys):
    params = tmp_path / "p.toml"
    params.write_text("[parameters]\nK = 180.0\n\n[spread]\nstiffness = 0.1\nJ_m = 0.0\n")
    out = tmp_path / "g.json"
    main(["design", "link1", "--noise", "ideal", "--params", str(params), "--recheck-draws", "0", "--out", str(out),
          *QUICK])
    rec = json.loads(out.read_text())
    assert rec["params"] == {"source": str(params), "nominal": {"K": 180.0}, "relative": {"K": 0.1, "J_m": 0.0},
                             "absolute": {}}
    assert rec["recheck"]["draws"] == 0


@pytest.mark.parametrize("argv, must", [
    (["--jitter-joints", "2-5"], ["--jitter-joints", "joint"]),
    (["--jitter-joints", "a"], ["--jitter-joints", "'a'"]),
    (["--max-jitter", "-1"], ["--max-jitter", "> 0"]),
    (["--max-at-limit", "150"], ["--max-at-limit", "percentage"]),
    (["--noise", "franka"], ["--noise", "franka_like"]),
    (["--params", "/nonexistent/p.toml"], ["--params", "not found"]),
    (["--duration", "1e9"], ["--duration/--rate", "GB"]),
    (["--recheck-draws", "-1"], ["--recheck-draws"]),
    (["--scheduler", "tcp://127.0.0.1:1"], ["--scheduler", "cannot connect"]),
])
def test_design_bad_flags_are_one_line_errors(capsys, argv, must):
    assert main(["design", "planar2", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("fjm: error:") and "Traceback" not in err, err
    for word in must:
        assert word in err, (word, err)


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


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_cli_sweep_with_a_gains_file_and_the_sampled_settings(tmp_path, capsys):
    gains = tmp_path / "g.json"
    gains.write_text(json.dumps({"kind": "ismc", "sensing": "torque", "predict": True,
                                 "gains": {"lam": 10.0, "k_lin": [50.0], "k_s": [100.0], "delta": [1.0]}}))
    out = tmp_path / "s.csv"
    rc = main(["sweep", "link1", "--samples", "4", "--chunk", "2", "--duration", "0.4", "--rate", "500",
               "--delay-samples", "1", "--noise", "panda_white", "--gains", str(gains), "--workers", "2",
               "--out", str(out)])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["settings"] == {"controller": "ismc", "sensing": "torque", "rate": 500.0, "delay_samples": 1,
                                   "predict": True, "noise": "panda_white", "sensor": "panda_white",
                                   "interface": CommandInterface.motor().as_dict(),   # the default, recorded
                                   "reference": "sine", "gains": str(gains)}
    header = out.read_text().splitlines()[0].split(",")
    assert "torque_jitter_1" in header and "time_at_rate_limit_1" in header and summary["runs"] == 4


@pytest.mark.parametrize("argv, must", [
    (["--rate", "500", "--dt", "0.001"], ["--rate and --dt"]),
    (["--noise", "nope"], ["--noise", "preset"]),
    (["--delay-samples", "-1"], ["--delay-samples"]),
    (["--rate", "1e12"], ["GB"]),
])
def test_cli_sweep_bad_settings_are_one_line_errors(tmp_path, capsys, argv, must):
    assert main(["sweep", "link1", "--samples", "2", "--out", str(tmp_path / "s.csv"), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    for word in must:
        assert word in err, (word, err)


def test_cli_sweep_gains_file_with_a_non_number(tmp_path, capsys):
    gains = tmp_path / "g.json"
    gains.write_text(json.dumps({"kind": "ismc", "gains": {"lam": "fast"}}))
    assert main(["sweep", "link1", "--samples", "2", "--gains", str(gains), "--out", str(tmp_path / "s.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert "gains.lam = 'fast'" in err and err.count("\n") == 0
