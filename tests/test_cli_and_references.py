"""CLI round trips and reference derivatives."""
import json

import numpy as np
import pytest

from fjm_runtime.cli import main
from fjm_runtime.references import Constant, Sinusoid, SmoothStep


def test_cli_simulate_prints_metrics_and_writes_plot(tmp_path, capsys):
    png = tmp_path / "run.png"
    rc = main(["simulate", "link1", "--K", "120", "--reference", "sine", "--duration", "2", "--plot", str(png),
               "--quiet"])
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    assert report["true_params"]["K"] == 120.0 and report["nominal_params"]["K"] == 150.0
    assert report["lemma1"]["k_s"] == pytest.approx(report["k_s"])
    assert 0 < report["metrics"]["rms_error"] < 0.1
    assert png.stat().st_size > 10_000


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


def test_cli_help(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    assert "simulate" in capsys.readouterr().out


@pytest.mark.parametrize("ref", [SmoothStep([1.0, -0.5], n=2, rise_time=1.5, t0=0.2),
                                 Sinusoid([0.5, 0.2], [1.0, 3.0], n=2, phase=[0.0, 1.0]), Constant(0.7)])
def test_reference_derivatives_are_consistent(ref):
    t = np.linspace(0.0013, 2.9987, 300)  # off the step's junctions, where the 5th derivative jumps
    h = 1e-5
    r = ref.sample(t)
    fd = (ref.sample(t + h) - ref.sample(t - h)) / (2 * h)
    scale = np.max(np.abs(r[:, 1:]), axis=0) + 1.0
    assert np.max(np.abs(fd[:, :4] - r[:, 1:]) / scale) < 1e-5
    assert np.allclose(r, np.stack([ref(tk) for tk in t]))
    bounds = ref.derivative_bounds()
    assert np.all(np.max(np.abs(r), axis=0) <= bounds + 1e-9)
