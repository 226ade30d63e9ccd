"""fjm simulate (fjm_runtime.cli.simulate): the --json scripting keys and their types (one short run), no inf in the
JSON, the metrics and the plot, controllers and parameters, the designed gains on their task, bad input in one line."""
import json
import math

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.cli.main import main
from fjm_runtime.cli.common import finite_or_note


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


def test_simulate_json_has_no_inf(capsys):
    report = {}
    finite_or_note(report, "reaching_time", math.inf)
    finite_or_note(report, "rms", float("nan"))
    finite_or_note(report, "final", 0.5)
    assert report == {"reaching_time": None, "reaching_time_note": "not reached", "rms": None,
                      "rms_note": "not finite", "final": 0.5}
    # a run too short to reach the layer: reaching time not reached -> null plus a note
    assert main(["simulate", "link1", "--reference", "step", "--duration", "0.05", "--k-s", "1", "--delta",
                 "1e-9", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert '"inf"' not in out and "Infinity" not in out and "NaN" not in out
    metrics = json.loads(out)["metrics"]
    assert all(v is not None or f"{k}_note" in metrics for k, v in metrics.items() if not k.endswith("_note"))


def test_cli_simulate_prints_metrics_and_writes_plot(tmp_path, capsys):
    png = tmp_path / "run.png"
    rc = main(["simulate", "link1", "--K", "120", "--reference", "sine", "--duration", "2", "--plot", str(png),
               "--quiet"])
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    assert report["true_params"]["K"] == 120.0 and report["nominal_params"]["K"] == 150.0
    # The default switching gain is the Lemma 1 bound, recomputed here independently (see below).
    ks_paper, ks_tight = lemma1_link1_sine_independent(amplitude=0.5, omega=1.0, lam=8.0, K_range=(100.0, 200.0))
    assert report["k_s"] == pytest.approx(ks_paper, rel=1e-6)
    assert report["lemma1"]["k_s_tight"] == pytest.approx(ks_tight, rel=1e-6)
    assert 0 < report["metrics"]["rms_error"] < 0.1
    assert png.stat().st_size > 10_000


def lemma1_link1_sine_independent(amplitude, omega, lam, K_range, eta=10.0):
    """Lemma 1 (eq 16) for link1 with Table 1 parameters, nominal K = 150, written from the paper.

    ``k_s = W + H / beta_hat + eta`` (and ``rho W + ...``) with, for the CLI's sine region
    ``E = (0.05, A w, 0.5, 0.5)``:
    ``W = sup|y_d^(4)| + c1 E2 + c2 E3 + c3 E4``, ``beta = J_l J_m / K`` over ``K_range``,
    ``beta_hat = (beta_min + beta_max) / 2``, ``rho = (beta_max - beta_min) / (beta_max + beta_min)``,
    ``H = sup |alpha(x; K_nom) - alpha(x; K)|`` over ``|y_i| <= sup|y_d^(i-1)| + E_i`` and ``K``,
    at ``x = T^-1(y; K)``, with ``alpha = -beta a(x)`` and ``a`` the paper's closed form. ``H`` is a
    dense grid maximum (401 x 41 x 11 x 11 points in y, 41 values of K).
    """
    import fjm_runtime
    Jl, Jm, MgL, K_nom = 1.0, 2.0, 9.8, 150.0
    c1, c2, c3 = lam ** 3, 3 * lam ** 2, 3 * lam
    R = amplitude * omega ** np.arange(5)  # sup |d^k/dt^k A sin(w t)|
    E = np.array([0.05, amplitude * omega, 0.5, 0.5])
    W = R[4] + c1 * E[1] + c2 * E[2] + c3 * E[3]
    b_min, b_max = Jl * Jm / K_range[1], Jl * Jm / K_range[0]
    beta_hat, rho = (b_min + b_max) / 2, (b_max - b_min) / (b_max + b_min)

    def alpha(x1, x2, x3, x4, K):
        a = (MgL / Jl * np.sin(x1) * (x2 ** 2 + MgL / Jl * np.cos(x1) + K / Jl)
             + K / Jl * (x1 - x3) * (K / Jl + K / Jm + MgL / Jl * np.cos(x1)))
        return -(Jl * Jm / K) * a

    def T_inv(y1, y2, y3, y4, K):
        return y1, y2, y1 + Jl / K * (y3 + MgL / Jl * np.sin(y1)), y2 + Jl / K * (y4 + MgL / Jl * np.cos(y1) * y2)

    # the closed forms above are those of the generated model (checked on a few states)
    m = fjm_runtime.load("link1")
    for y in ([0.3, -0.2, 0.7, -0.9], [-0.5, 1.0, -1.0, 0.4]):
        x = np.array(T_inv(*y, 130.0))
        np.testing.assert_allclose(m.T(x, {"K": 130.0}), y, atol=1e-12)
        assert m.alpha(x, {"K": 130.0})[0] == pytest.approx(alpha(*x, 130.0), rel=1e-12)
    Y = R[:4] + E
    axes = np.ix_(np.linspace(-Y[0], Y[0], 401), np.linspace(-Y[1], Y[1], 41),
                  np.linspace(-Y[2], Y[2], 11), np.linspace(-Y[3], Y[3], 11))
    H = 0.0
    for K in np.linspace(K_range[0], K_range[1], 41):
        x = T_inv(*axes, K)
        H = max(H, float(np.max(np.abs(alpha(*x, K_nom) - alpha(*x, K)))))
    return W + H / beta_hat + eta, rho * W + H / beta_hat + eta


def test_cli_controllers_and_params(capsys):
    rc = main(["simulate", "planar2", "--controller", "ismc", "--param", "K1=160", "--param", "K2=170",
               "--duration", "1", "--quiet"])
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    assert report["true_params"]["K1"] == 160.0 and report["true_params"]["K2"] == 170.0


@pytest.mark.parametrize("argv, needle", [
    (["simulate", "link1", "--reference", "ramp"], "reference = 'ramp'"),
    (["simulate", "link1", "--param", "K"], "NAME=VALUE"),
    (["simulate", "link1", "--param", "Q=1"], "Q"),
    (["simulate", "link1", "--delta", "-1"], "delta"),
    (["simulate", "nope"], "available models"),
])
def test_cli_bad_input_exits_2_with_message(argv, needle, capsys):
    assert main(argv + ["--quiet"] if argv[0] == "simulate" else argv) == 2
    assert needle in capsys.readouterr().err
