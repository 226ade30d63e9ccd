"""`fjm simulate --json`: the scripting keys and their types (one short run), and bad input in one line."""
import json

import pytest

import fjm_runtime

from fjm_runtime.cli.main import main


def _run(capsys, argv):
    status = main(argv)
    out = capsys.readouterr()
    return status, out.out, out.err


def test_json_keys_and_types(capsys, tmp_path):
    gains = tmp_path / "g.json"
    gains.write_text(json.dumps({"kind": "ismc", "gains": {"lam": 8.0, "k_s": 100.0, "delta": 2.0, "u_max": 40.0}}))
    status, out, _ = _run(capsys, ["simulate", "planar2", "--gains", str(gains), "--rate", "1000",
                                   "--delay-samples", "1", "--predict", "--noise", "panda", "--seed", "5",
                                   "--k-scale", "0.8,1.2", "--jm-scale", "1.1", "--duration", "0.1", "--json"])
    assert status == 0
    rep = json.loads(out)
    assert rep["diverged"] is False
    for k in ("rms_second_half", "peak_torque", "time_at_limit", "torque_jitter"):
        assert isinstance(rep[k], list) and len(rep[k]) == 2 and all(isinstance(v, float) for v in rep[k]), k
    assert all(0.0 <= v <= 1.0 for v in rep["time_at_limit"])
    assert max(rep["peak_torque"]) <= 40.0 + 1e-9
    s = rep["settings"]
    assert (s["rate"], s["delay_samples"], s["sensing"], s["seed"], s["predict"]) == (1000.0, 1, "state", 5, True)
    assert isinstance(s["substeps"], int) and s["substeps"] >= 1
    nominal = fjm_runtime.load("planar2").default_params
    assert s["true_params"]["K1"] == pytest.approx(0.8 * nominal["K1"], rel=1e-12)
    assert s["true_params"]["K2"] == pytest.approx(1.2 * nominal["K2"], rel=1e-12)
    assert s["true_params"]["Jm2"] == pytest.approx(1.1 * nominal["Jm2"], rel=1e-12)
    assert "NaN" not in out and "Infinity" not in out


@pytest.mark.parametrize("argv, text", [
    (["--delay-samples", "-1"], "delay_samples"),
    (["--substeps", "0"], "substeps"),
    (["--noise", "loud"], "--noise"),
    (["--k-scale", "1,2,3"], "--k-scale"),
    (["--payload", "1"], "--payload"),
])
def test_bad_input_is_one_line_exit_2(capsys, argv, text):
    status, _, err = _run(capsys, ["simulate", "planar2", "--duration", "0.01", "--json", *argv])
    assert status == 2
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and text in lines[0]


def test_non_finite_noise_level_in_a_file(capsys, tmp_path):
    f = tmp_path / "noise.json"
    f.write_text('{"q": 1e999}')
    status, _, err = _run(capsys, ["simulate", "link1", "--duration", "0.01", "--json", "--noise", str(f)])
    # the file's key, not the Python class's attribute (SensorModel.q)
    assert status == 2 and ": q = inf" in err and "SensorModel" not in err and len(err.strip().splitlines()) == 1


def test_designed_gains_run_on_their_task_by_default():
    """The shipped Panda design holds for the task it was searched on: `fjm simulate` uses that task
    (ready-pose sines from rest holding gravity) unless --reference says otherwise."""
    from types import SimpleNamespace

    import numpy as np

    import fjm_runtime
    from fjm_runtime.cli.simulate import _reference
    from fjm_runtime.control.design import Design
    from fjm_runtime.experiments import panda as demo
    from fjm_runtime.validation import FjmValueError
    m = fjm_runtime.load("panda")
    spec = Design.shipped("panda", "ismc", "torque", 1000, 1)
    ref, x0 = spec.reference(m), spec.start_state(m)
    assert np.allclose(ref(0.0)[0], np.subtract(demo.READY, demo.AMPLITUDE))      # from rest at READY - A
    assert np.allclose(ref(0.0)[1], 0.0) and np.allclose(ref(1.3)[0], demo.reference()(1.3)[0])
    assert np.allclose(x0[7:14], 0) and np.max(np.abs(x0[14:21] - x0[:7])) > 1e-4   # motors wound up on gravity
    assert np.array_equal(x0, demo.rest_state(m, np.subtract(demo.READY, demo.AMPLITUDE), m.default_params))
    args = SimpleNamespace(reference=None, amplitude=0.5, omega=1.0, q_d=1.0, rise_time=2.0)
    got, x0_cli = _reference(m, args, spec)
    assert args.reference == "task" and np.array_equal(x0_cli, x0)
    args = SimpleNamespace(reference="sine", amplitude=0.5, omega=1.0, q_d=1.0, rise_time=2.0)
    assert _reference(m, args, spec)[1] is None
    args = SimpleNamespace(reference="task", amplitude=0.5, omega=1.0, q_d=1.0, rise_time=2.0)
    with pytest.raises(FjmValueError, match="record no task"):
        _reference(m, args, Design(kind="ismc", gains={}))


def test_the_designs_nominal_values_are_the_controllers(capsys, tmp_path):
    """A gains file from ``fjm design --params`` records ``params.nominal``: simulate builds the law on those
    values (``--nominal`` still overrides one by one); the TRUE plant's k-scale is relative to them; a name the
    model lacks is a one-line error."""
    spec = {"kind": "ismc", "gains": {"lam": 8.0, "k_s": 100.0, "delta": 2.0},
            "params": {"source": "my.toml", "nominal": {"K1": 120.0, "Jm2": 0.7}}}
    gains = tmp_path / "g.json"
    gains.write_text(json.dumps(spec))
    status, out, _ = _run(capsys, ["simulate", "planar2", "--gains", str(gains), "--duration", "0.05", "--json",
                                   "--nominal", "Jm2=0.9", "--k-scale", "0.5"])
    assert status == 0
    s = json.loads(out)["settings"]
    assert (s["nominal_params"]["K1"], s["nominal_params"]["Jm2"]) == (120.0, 0.9)
    assert s["true_params"]["K1"] == pytest.approx(60.0, rel=1e-12)           # 0.5 x the design's nominal
    spec["params"]["nominal"] = {"K9": 1.0}
    gains.write_text(json.dumps(spec))
    status, _, err = _run(capsys, ["simulate", "planar2", "--gains", str(gains), "--duration", "0.05", "--json"])
    assert status == 2 and "params.nominal.K9" in err and len(err.strip().splitlines()) == 1
