"""CLI round trips and reference derivatives."""
import json

import numpy as np
import pytest

from fjm_runtime.cli.main import main
from fjm_runtime.control.references import Constant, Sinusoid, SmoothStep


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
