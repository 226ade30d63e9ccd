"""fjm sweep (fjm_runtime.cli.sweep): the sampled-loop settings (sensing, rate, delay, prediction, noise, gains
file) and their one-line errors, the stiffness default on arms whose nominal is far from 100..200, the summary."""
import json
import warnings

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.cli.main import main
from fjm_runtime.cli.sweep import stiffness_range, summary
from fjm_runtime.sim.interface import CommandInterface
from fjm_runtime.validation import FjmValueError


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


def test_sweep_stiffness_default_follows_the_nominal():
    link1, panda = fjm_runtime.load("link1"), fjm_runtime.load("panda")
    assert stiffness_range(link1, None, None, None) == ((100.0, 200.0), None)
    k_range, k_rel = stiffness_range(panda, None, None, None)
    assert k_rel == (0.7, 1.3)  # relative to each joint's nominal 3e3..1e4, not 100..200 N m/rad
    assert stiffness_range(panda, None, None, [0.9, 1.1])[1] == (0.9, 1.1)
    with pytest.raises(FjmValueError, match="--k-rel"):
        stiffness_range(panda, 100.0, 200.0, None)
    assert stiffness_range(panda, 2000.0, 20000.0, None) == ((2000.0, 20000.0), None)


def test_sweep_summary_without_nan_or_warnings():
    P = np.zeros((3, 7))
    metrics = {"rms_error_second_half": np.full(3, np.nan), "diverged": np.ones(3, dtype=int)}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = summary(P, metrics, 1.0, "t.csv")
    text = json.dumps(out, allow_nan=False)
    assert out["rms_error_second_half_max"] is None and out["rms_error_second_half_max_note"] == "every run diverged"
    assert "NaN" not in text and out["diverged"] == 3
    metrics = {"rms_error_second_half": np.array([1.0, np.nan, 3.0]), "diverged": np.array([0, 1, 0])}
    out = summary(P, metrics, 1.0, "t.csv")
    assert out["rms_error_second_half_max"] == 3.0 and out["rms_error_second_half_median"] == 2.0
