"""Identification from logs whose truth is known (fjm_runtime.ident.identify).

The logs come from fjm's own sampled loop with TRUE parameters away from the model's defaults (the
identification never sees them), or from a small plant integrated here with Coulomb friction
(link1_hd's generated plant carries Coulomb + Stribeck friction too). MuJoCo logs: tests/scenarios/test_mujoco_identification.py.
"""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.analysis.search.draws import load_params_file
from fjm_runtime.control.factory import make_controller
from fjm_runtime.ident.excite import design_excitation
from fjm_runtime.ident.identify import identify
from fjm_runtime.ident.log import Log
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.validation import FjmValueError


def _sim_log(model, true, duration, seed=0, tau=True, noise=(1e-5, 0.05), period=None):
    """A 1 kHz log of ``model`` at ``true`` tracking a ``fjm excite`` trajectory (nominal integral SMC);
    ``period``: the excitation's length, played ``duration / period`` times (default: ``duration``)."""
    exc = design_excitation(model, duration if period is None else period, candidates=5, seed=seed)
    ctrl = make_controller("ismc", model, model.default_params, lam=10.0, k_s=20.0, delta=20.0)
    r = simulate(model, ctrl, exc.reference, duration=duration, dt=1e-3, true_params=true)
    n, rng = model.n, np.random.default_rng(seed)
    q, qm = r.x[:, :n], r.x[:, 2 * n:3 * n]
    p = model.params_array(true)
    phi = qm - q
    names = list(model.param_names)
    if "k1" in names:
        tau_J = p[names.index("k1")] * phi + p[names.index("k3")] * phi ** 3
    else:
        tau_J = p[names.index("K")] * phi
    return Log(r.t, q + noise[0] * rng.standard_normal(q.shape), qm + noise[0] * rng.standard_normal(q.shape),
               r.u, tau_J + noise[1] * rng.standard_normal(q.shape) if tau else None, "fjm simulate")


@pytest.fixture(scope="module")
def link1():
    m = fjm_runtime.load("link1")
    true = {**m.default_params, "K": 1.2 * m.default_params["K"], "J_m": 0.9 * m.default_params["J_m"], "B_m": 0.5}
    return m, true


@pytest.mark.parametrize("with_tau", [True, False])
def test_link1_within_tolerance(link1, with_tau):
    m, true = link1
    ident = identify(m, _sim_log(m, true, 6.0, tau=with_tau), friction="viscous")
    v = ident.values
    assert abs(v["K"] / true["K"] - 1) < 0.02, v
    assert abs(v["J_m"] / true["J_m"] - 1) < 0.05, v
    assert abs(v["B_m"] - true["B_m"]) < 0.1, v
    # the standard errors are honest: the truth lies within 4 of them (tolerance for the filter's bias)
    for k in ("K", "J_m"):
        assert abs(v[k] - true[k]) < 4 * ident.stderr[k] + 1e-3 * true[k], (k, v[k], true[k], ident.stderr[k])


def test_longer_log_tightens_the_errors(link1):
    m, true = link1
    short = identify(m, _sim_log(m, true, 3.0), friction="viscous")
    long = identify(m, _sim_log(m, true, 12.0, period=3.0), friction="viscous")   # the same excitation x4
    for k in ("K", "J_m", "B_m"):                                                 # sqrt(4): 0.5 expected
        assert long.stderr[k] < 0.7 * short.stderr[k], (k, short.stderr[k], long.stderr[k])


def test_mislabeled_motor_angle_fails_the_tolerance(link1):
    """A log whose q_m column holds the link angle again cannot give the stiffness: the check can fail."""
    m, true = link1
    log = _sim_log(m, true, 4.0)
    bad = Log(log.t, log.q, log.q + 0.999 * (log.q_m - log.q) + 1e-3 * np.sin(log.t)[:, None], log.u, log.tau_J)
    v = identify(m, bad, friction="viscous").values
    assert abs(v["K"] / true["K"] - 1) > 0.02


def test_cubic_spring_of_link1_hd():
    m = fjm_runtime.load("link1_hd")
    d = m.default_params
    true = {**d, "k1": 1.1 * d["k1"], "k3": 0.8 * d["k3"], "J_m": 0.9 * d["J_m"]}
    ident = identify(m, _sim_log(m, true, 6.0), friction="viscous")
    for k, tol in (("k1", 0.03), ("k3", 0.1), ("J_m", 0.05)):
        assert abs(ident.values[k] / true[k] - 1) < tol, (k, ident.values[k], true[k])
    with pytest.raises(FjmValueError, match="no cubic spring parameters"):
        identify(fjm_runtime.load("link1"), _sim_log(m, true, 2.0), spring="cubic")


def _coulomb_log(F_c=0.6, B_m=0.2, J_m=0.05, K=80.0, duration=8.0, dt=1e-3, v_c=0.01, seed=1, amplitude=1.0):
    """A motor on a spring to a fixed link (q = 0), Coulomb tanh friction, RK4 at dt/10 under held u
    (``amplitude`` scales u)."""
    rng = np.random.default_rng(seed)
    t = dt * np.arange(int(duration / dt))
    u_seq = amplitude * (1.5 * np.sin(2.1 * t) + 0.8 * np.sin(5.3 * t + 1.0) + 0.3 * np.sin(13.0 * t))

    def rhs(x, u):
        return np.array([x[1], (u - B_m * x[1] - F_c * np.tanh(x[1] / v_c) - K * x[0]) / J_m])
    x, X = np.zeros(2), np.zeros((t.size, 2))
    h = dt / 10
    for k, u in enumerate(u_seq):
        X[k] = x
        for _ in range(10):
            k1 = rhs(x, u); k2 = rhs(x + h / 2 * k1, u); k3 = rhs(x + h / 2 * k2, u); k4 = rhs(x + h * k3, u)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    qm = X[:, :1] + 1e-6 * rng.standard_normal((t.size, 1))
    tau = K * X[:, :1] + 0.01 * rng.standard_normal((t.size, 1))
    return Log(t, np.zeros_like(qm), qm, u_seq[:, None], tau, "coulomb plant")


def test_coulomb_friction_regressor():
    """A light, fast motor (spring mode 40 rad/s, stick-slip): a short 10 ms window, clean encoders."""
    m = fjm_runtime.load("link1")
    ident = identify(m, _coulomb_log(), friction="coulomb", window=0.01)
    v = ident.values
    assert abs(v["F_c1"] / 0.6 - 1) < 0.1, v
    assert abs(v["J_m"] / 0.05 - 1) < 0.05 and abs(v["K"] / 80.0 - 1) < 0.02, v
    viscous = identify(m, _coulomb_log(), friction="viscous", window=0.01)
    assert viscous.residual["motor 1"] > 3 * ident.residual["motor 1"]   # friction is in the data


def test_friction_is_filtered_like_the_other_columns_so_the_window_does_not_bias():
    """The same stick-slip motor at the default 40 ms window: friction evaluated per sample and then
    filtered (not evaluated on the filtered velocity), derivatives that are the value filter on
    differences, and the held torque averaged over each sample leave J_m, B_m and F_c as at 10 ms (measured
    at 40 ms: friction of the filtered velocity J_m +1.8 %, B_m +15 %; Savitzky-Golay derivatives J_m +6 %)."""
    m = fjm_runtime.load("link1")
    for window in (0.01, 0.04):
        v = identify(m, _coulomb_log(), friction="coulomb", window=window).values
        assert abs(v["J_m"] / 0.05 - 1) < 0.01 and abs(v["B_m"] / 0.2 - 1) < 0.03, (window, v)
        assert abs(v["F_c1"] / 0.6 - 1) < 0.01 and abs(v["K"] / 80.0 - 1) < 0.001, (window, v)


def test_parameter_file_is_what_fjm_design_reads(link1, tmp_path):
    m, true = link1
    ident = identify(m, _sim_log(m, true, 4.0), friction="viscous")
    path = ident.to_toml(tmp_path / "params.toml", m)
    spread = load_params_file(path, m)
    for k in ("K", "J_m", "B_m"):
        assert spread.overrides[k] == pytest.approx(ident.values[k], rel=0, abs=0)
        assert 0.01 <= spread.relative[k] < 1
        lo, hi = ident.interval(k)                 # the spread is the interval's half-width, at least 1 %
        assert spread.relative[k] == pytest.approx(max((hi - lo) / 2 / abs(ident.values[k]), 0.01), rel=1e-12)
        assert (hi - lo) / 2 == pytest.approx(3 * np.hypot(ident.stderr[k], ident.systematic[k]), rel=1e-12)
    assert "tau_J_offset1" in path.read_text() and "tau_J_offset1" not in spread.overrides


def test_bad_settings_and_unexcited_columns(link1):
    m, true = link1
    log = _sim_log(m, true, 2.0)
    with pytest.raises(FjmValueError, match="v_c = 0"):
        identify(m, log, v_c=0.0)
    with pytest.raises(FjmValueError, match="complete model"):
        identify(fjm_runtime.load("link1_complete"), log)
    still = Log(log.t, np.zeros_like(log.q), np.zeros_like(log.q), np.ones_like(log.u), np.zeros_like(log.q))
    with pytest.raises(FjmValueError, match="regressor column of K is zero"):
        identify(m, still)


def test_unexcited_parameter_keeps_the_models_value(link1, tmp_path):
    """A log without motor damping to see (B_m = 0 and noise): B_m is flagged and not written."""
    m, true = link1
    log = _sim_log(m, {**true, "B_m": 0.0}, 4.0)
    ident = identify(m, log, friction="coulomb")
    assert "B_m" in ident.not_excited and any(w.startswith("B_m") for w in ident.warnings)
    spread = load_params_file(ident.to_toml(tmp_path / "p.toml", m), m)
    assert "B_m" not in spread.overrides and "K" in spread.overrides


def test_link1_hd_friction_by_the_models_own_law_and_names(tmp_path):
    """link1_hd's plant carries Coulomb + Stribeck motor friction (the generated f): identified under the
    model's names within 10 %, with the model's v_c, v_s held and written to the parameter file."""
    m = fjm_runtime.load("link1_hd")
    d = m.default_params
    true = {**d, "k1": 1.1 * d["k1"], "F_c": 0.8, "F_s": 1.2}
    log = _sim_log(m, true, 6.0)
    ident = identify(m, log, friction="stribeck")
    v = ident.values
    for k in ("F_c", "F_s"):
        assert abs(v[k] / true[k] - 1) < 0.1, (k, v[k], true[k])
    assert abs(v["k1"] / true["k1"] - 1) < 0.03 and abs(v["J_m"] / true["J_m"] - 1) < 0.05, v
    assert ident.fixed == {"v_c": d["v_c"], "v_s": d["v_s"]}
    try:
        import tomllib
    except ImportError:  # Python < 3.11
        import tomli as tomllib
    written = tomllib.loads(ident.to_toml(tmp_path / "p.toml", m).read_text())["parameters"]
    assert written["F_c"] == v["F_c"] and written["F_s"] == v["F_s"] and written["v_c"] == d["v_c"]
    m.params_array({**d, **written})  # physical: the runtime accepts the file's values
    coulomb = identify(m, log, friction="coulomb")  # one level: the static level set to it (no hump)
    assert coulomb.fixed["F_s"] == coulomb.values["F_c"] and "F_s" not in coulomb.values


def test_motor_angle_not_divided_by_the_gear_ratio_is_named(link1):
    """q_m logged on the rotor side (x N = 10): one line names the joint and the factor, one the stiffness
    that lands far from the nominal value."""
    m, true = link1
    log = _sim_log(m, true, 3.0)
    ident = identify(m, Log(log.t, log.q, 10.0 * log.q_m, log.u, log.tau_J), friction="viscous")
    gear = [w for w in ident.warnings if w.startswith("joint 1: q_m_1 moves")]
    assert len(gear) == 1, ident.warnings
    assert float(gear[0].split(" moves ")[1].split(" times")[0]) == pytest.approx(10.0, rel=0.1)
    assert ident.values["K"] < 0.1 * m.default_params["K"]
    assert any(w.startswith("K = ") and "the model's nominal" in w for w in ident.warnings), ident.warnings
    assert not any("moves" in w or "nominal" in w for w in identify(m, log, friction="viscous").warnings)


def test_cli_reversal_share_keeps_every_row_at_0_and_is_refused_out_of_range(link1, tmp_path, capsys):
    """fjm identify --reversal-share 0 fits the motor equation on every sample (the viscous-only, no-friction
    link1 log: within 5 % as with the default); 1.5 is one line naming the flag and the range."""
    from fjm_runtime.cli.main import main as fjm_main
    from fjm_runtime.ident.log import write_log
    m, true = link1
    path = write_log(tmp_path / "log.csv", _sim_log(m, true, 4.0))
    out = tmp_path / "p.toml"
    assert fjm_main(["identify", "link1", str(path), "--out", str(out), "--reversal-share", "0"]) == 0
    from fjm_runtime.analysis.search.draws import load_params_file
    assert abs(load_params_file(out, m).overrides["J_m"] / true["J_m"] - 1) < 0.05
    capsys.readouterr()
    assert fjm_main(["identify", "link1", str(path), "--out", str(out), "--reversal-share", "1.5"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--reversal-share" in err and "0.9" in err and "\n" not in err


def test_damping_of_a_motor_that_barely_moves_is_reported_not_excited():
    """The stick-slip motor driven hard (0.055 rad/s RMS): B_m within 10 %; driven at 35 % of that torque
    it creeps (0.01 rad/s RMS) against its 0.6 N m friction: B_m is not excited, the warning gives the
    speed, and the interval still holds the truth."""
    m = fjm_runtime.load("link1")
    moving = identify(m, _coulomb_log(seed=2), window=0.01)
    assert "B_m" not in moving.not_excited and abs(moving.values["B_m"] / 0.2 - 1) < 0.1
    creeping = identify(m, _coulomb_log(seed=2, amplitude=0.35), window=0.01)
    assert "B_m" in creeping.not_excited
    warning = next(w for w in creeping.warnings if w.startswith("B_m = "))
    speed = float(warning.split("moves at ")[1].split(" rad/s")[0])
    assert speed == pytest.approx(0.00984, rel=0.05)
    lo, hi = creeping.interval("B_m")
    assert lo <= 0.2 <= hi
