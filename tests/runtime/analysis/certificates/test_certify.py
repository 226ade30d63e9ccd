"""Reaching-gain synthesis (fjm_runtime.analysis.certificates.certify, ``fjm tune``): certificates, trajectories, CLI.

Robustness claims: controller on NOMINAL parameters, plant on TRUE ones. The
checks of the certificate use independent evaluations (closed forms written
here, finite differences of T along the true vector field, simulated
trajectories), never values copied from the code under test.
"""
import json

import numpy as np
import pytest

from fjm_runtime.cli.main import main
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import Sinusoid
from fjm_runtime.analysis.certificates.lemma1 import beta_hat_link1, lemma1_gain
from fjm_runtime.analysis.certificates.link1 import link1_T_inverse
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.analysis.certificates.certify import InfeasibleGainError, certificate, synthesize_gains
from support.link1_case import K_BOX, K_NOM, REG
from support.reaching import state_at, trajectory_check


_SYNTH = {}


def _link1_gain(link1, lam, **extra):
    """``synthesize_gains(link1, K_NOM, REG box, lam, **extra)``, computed once per module: it is deterministic
    and several tests check different properties of the same synthesized gain (~2 s each)."""
    key = (lam, tuple(sorted(extra.items())))
    if key not in _SYNTH:
        _SYNTH[key] = synthesize_gains(link1, {"K": K_NOM}, **extra, **_link1_kwargs(REG, lam))
    return _SYNTH[key]


def _link1_kwargs(box=REG, lam=8.0):
    ref, E = box
    return dict(param_box=K_BOX, reference_bounds=ref.derivative_bounds()[:, 0], error_bounds=E, lam=lam,
                beta_hat=beta_hat_link1({"K": K_NOM}, K_BOX))


# -- certificates: negative for the synthesized gain, positive 20 % below ---------------------------
# ~10 s each: lam = 20 in make test, the two others in the exhaustive pass
@pytest.mark.parametrize("lam", [pytest.param(8.0, marks=pytest.mark.exhaustive), 20.0,
                                 pytest.param(30.0, marks=pytest.mark.exhaustive)])
def test_link1_certificate_sign(link1, lam):
    kw = _link1_kwargs(REG, lam)
    res = _link1_gain(link1, lam)
    assert res.feasible, res.reason
    assert res.certificate[0] <= -res.eta[0] + 1e-9
    assert res.certificate[0] < 0
    low = certificate(link1, 0.8 * res.k_s, {"K": K_NOM}, **kw)
    assert low["certificate"][0] > 0


def test_lemma1_gain_is_not_certified_for_the_implemented_law_at_large_lambda(link1):
    """The Lemma 1 gain (true coordinates) does not give reaching for s built from T(x; K_nom) at lambda = 30."""
    ref, E = REG
    kw = _link1_kwargs(REG, 30.0)
    g = lemma1_gain([30.0 ** 3, 3 * 30.0 ** 2, 3 * 30.0], ref.derivative_bounds()[:, 0], nominal={"K": K_NOM},
                    bounds=K_BOX, error_bounds=E)
    assert certificate(link1, g.k_s, {"K": K_NOM}, **kw)["certificate"][0] > 0


def _direct_sdot(model, nominal, true_params, x, r, k_s, lam, beta_hat=None):
    """s' of the paper-surface sign law by central differences of T(x; p_nom) along the TRUE vector field."""
    ctrl = make_controller("sign", model, nominal, lam=lam, k_s=k_s, beta_hat=beta_hat)
    smp = ctrl.evaluate(0.0, x, np.zeros(0), r)
    xdot = model.f(x, true_params) + model.g(x, true_params) @ smp.u
    n, h = model.n, 1e-6
    dy = ((model.T(x + h * xdot, model.params_array(nominal)) - model.T(x - h * xdot, model.params_array(nominal)))
          / (2 * h)).reshape(4, n)
    c = ctrl.c
    sdot = c[0] * (dy[0] - r[1]) + c[1] * (dy[1] - r[2]) + c[2] * (dy[2] - r[3]) + dy[3] - r[4]
    return smp.s, sdot


def _check_witness(model, nominal, kw, k_low):
    """At the witness of the gain 20 % below, the direct s' has sgn(s) s' > 0 and equals the certificate."""
    low = certificate(model, k_low, nominal, **kw)
    n = model.n
    lam = kw["lam"]
    c3 = 3 * lam
    for i in range(n):
        wit = low["witness"][i]
        y_hat = np.asarray(wit["y_hat"], dtype=float).reshape(-1)
        x = state_at(model, nominal, y_hat)
        eps = 1e-9
        sign = np.full(n, 1.0); sign[i] = wit["sign_s"]
        e = np.zeros((4, n)); e[3] = eps * sign
        r = np.zeros((5, n))
        r[:4] = y_hat.reshape(4, n) - e
        r[4] = np.asarray(wit["w"]) + c3 * e[3]          # w = y4d' - c3 e4
        true = dict(nominal); true.update(wit["params"])
        s, sdot = _direct_sdot(model, nominal, true, x, r, k_low, lam, kw.get("beta_hat"))
        val = np.sign(s[i]) * sdot[i]
        assert val > 0
        assert val == pytest.approx(low["certificate"][i], rel=1e-4, abs=1e-3 * np.max(k_low))


def test_link1_witness_direct_evaluation(link1):
    kw = _link1_kwargs(REG, 20.0)
    res = _link1_gain(link1, 20.0)
    _check_witness(link1, {"K": K_NOM}, kw, 0.8 * res.k_s)


# -- planar2 ---------------------------------------------------------------------------------------
P2_NOM = {"K1": 100.0, "K2": 100.0}
P2_REF = Sinusoid([0.5, 0.3], [1.0, 1.5], n=2, phase=[0.0, 0.5])
P2_KW = dict(param_box={"K1": (100.0, 200.0), "K2": (100.0, 200.0)}, reference_bounds=P2_REF.derivative_bounds(),
             error_bounds=(0.02, 0.1, 0.2, 30.0), lam=8.0, n_grid=3)
# a wide jerk-error bound: during reaching s falls mostly through e4 (s' ~ -k_s), so e4 must stay in the box


@pytest.fixture(scope="module")
def planar2_gain(planar2):
    return synthesize_gains(planar2, P2_NOM, **P2_KW)


def test_planar2_certificate_sign(planar2, planar2_gain):
    res = planar2_gain
    assert res.feasible, res.reason
    assert np.all(res.certificate <= -res.eta + 1e-9)
    _check_witness(planar2, P2_NOM, P2_KW, 0.8 * res.k_s)


# -- simulated trajectories: sgn(s) s' <= -eta wherever the state is in the box and |s| > delta ----------
@pytest.mark.parametrize("K_true", [100.0, 200.0])
def test_link1_trajectory_reaching(link1, K_true):
    ref, E = REG
    kw = _link1_kwargs(REG, 8.0)
    gain = _link1_gain(link1, 8.0)
    ctrl = make_controller("smc", link1, {"K": K_NOM}, lam=8.0, k_s=gain.k_s, delta=gain.delta,
                           beta_hat=kw["beta_hat"])
    e0 = 0.8 * np.asarray(E)
    x0 = link1_T_inverse(ref(0.0)[:4, 0] + e0, {"K": K_NOM})
    res = simulate(link1, ctrl, ref, duration=1.5, dt=1e-4, true_params={"K": K_true}, x0=x0)
    trajectory_check(res, E, gain.eta[0], ctrl.c)


def test_planar2_trajectory_reaching(planar2, planar2_gain):
    """With the default layer k_s / 200 the whole error box lies inside the layer (vacuous); a thin layer and a
    short step expose the reaching phase (layer slope 1 / (5 dt), stable under the zero-order hold)."""
    E = P2_KW["error_bounds"]
    dt = 1e-5
    delta = 5 * dt * planar2_gain.k_s
    ctrl = make_controller("smc", planar2, P2_NOM, lam=8.0, k_s=planar2_gain.k_s, delta=delta)
    y0 = P2_REF(0.0)[:4] + 0.8 * np.asarray(E)[:, None] * np.array([1.0, -1.0])[None, :]
    x0 = state_at(planar2, P2_NOM, y0.reshape(-1))
    res = simulate(planar2, ctrl, P2_REF, duration=0.02, dt=dt, true_params={"K1": 200.0, "K2": 100.0}, x0=x0)
    trajectory_check(res, E, planar2_gain.eta[0], ctrl.c)


# -- infeasible boxes and errors -------------------------------------------------------------------
@pytest.mark.exhaustive  # ~11 s: .ci/run runs it after make test (make test stays under 5 minutes)
def test_infeasible_actuator_limit(link1):
    kw = _link1_kwargs(REG, 30.0)
    res = synthesize_gains(link1, {"K": K_NOM}, u_max=5.0, **kw)
    assert not res.feasible
    assert "u_max" in res.reason and "5" in res.reason
    with pytest.raises(InfeasibleGainError, match="u_max"):
        synthesize_gains(link1, {"K": K_NOM}, u_max=5.0, raise_infeasible=True, **kw)


def test_unknown_box_parameter(link1):
    kw = _link1_kwargs(REG, 8.0)
    kw["param_box"] = {"K_x": (1.0, 2.0)}
    with pytest.raises(ValueError, match="K_x.*expected one of"):
        synthesize_gains(link1, {"K": K_NOM}, **kw)


# -- CLI -------------------------------------------------------------------------------------------
def test_cli_tune_link1_lam30(capsys):
    assert main(["tune", "link1", "--lam", "30"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["feasible"] is True
    assert out["k_s"][0] > 0
    assert out["certificate"][0] < 0
    assert out["certificate"][0] <= -out["eta"][0] + 1e-9
    assert out["reaching_time_bound"][0] > 0


def test_cli_tune_infeasible_exit_status(capsys):
    assert main(["tune", "link1", "--lam", "30", "--u-max", "5"]) == 1
    cap = capsys.readouterr()
    assert json.loads(cap.out)["feasible"] is False
    assert "u_max" in cap.err


def _cli(argv, capsys):
    try:
        rc = main(argv)
    except SystemExit as exc:       # argparse errors leave through sys.exit
        rc = exc.code
    return rc, capsys.readouterr()


@pytest.mark.parametrize("argv, needle", [
    (["tune", "nope"], "unknown model 'nope'"),
    (["tune", "link1", "--lam", "abc"], "--lam: 'abc' is not a number"),
    (["tune", "link1", "--budget", "1.5"], "--budget: '1.5' is not an integer"),
    (["tune", "link1", "--controller", "pid"], "--controller: invalid choice: 'pid'"),
    (["tune", "link1", "--reference-bounds", "1,2"], "--reference-bounds '1,2': expected 5 numbers"),
    (["tune", "link1", "--error-box", "a,b,c,d"], "--error-box 'a,b,c,d': expected 4 numbers"),
    (["tune", "link1", "--k-range", "5", "1"], "--k-range 5.0 1.0: expected 0 < LO <= HI"),
    (["tune", "link1", "--param-box", "K=1"], "expected NAME=LO:HI"),
    (["tune", "link1", "--nominal", "K=x"], "VALUE 'x' is not a number"),
])
def test_cli_tune_bad_input_is_one_line_exit_2(argv, needle, capsys):
    rc, cap = _cli(argv, capsys)
    assert rc == 2
    assert cap.out == ""
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], cap.err
    assert "Traceback" not in cap.err


def test_cli_tune_infeasible_is_one_stderr_line(capsys):
    rc, cap = _cli(["tune", "link1", "--lam", "30", "--u-max", "5"], capsys)
    assert rc == 1
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fjm tune: no admissible gain: ") and "u_max" in lines[0]


# -- matched disturbances --------------------------------------------------------------------------
@pytest.mark.exhaustive  # ~9 s: .ci/run runs it after make test (make test stays under 5 minutes)
def test_disturbance_raises_gain_by_bound_over_beta_hat(link1):
    """link1: C J g = K_nom / (J_l J_m) and G = (C J g) beta_hat, so the gain grows by exactly D / beta_hat."""
    kw = _link1_kwargs(REG, 8.0)
    r0 = _link1_gain(link1, 8.0)
    r1 = _link1_gain(link1, 8.0, disturbance_bound=2.0)
    assert (r1.k_s[0] - r0.k_s[0]) == pytest.approx(2.0 / kw["beta_hat"], rel=1e-6)
    assert certificate(link1, r0.k_s, {"K": K_NOM}, disturbance_bound=2.0, **kw)["certificate"][0] > 0
    assert r1.certificate[0] <= -r1.eta[0] + 1e-9


def test_disturbed_model_drift(link1):
    from fjm_runtime.control.disturbance import with_motor_disturbance
    plant = with_motor_disturbance(link1, coulomb=2.0, bias=0.5)
    rng = np.random.default_rng(0)
    for _ in range(5):
        x = rng.uniform(-1, 1, 4)
        expected = link1.f(x, {"K": 120.0}) + link1.g(x, {"K": 120.0}) @ np.array([-2.0 * np.sign(x[3]) + 0.5])
        np.testing.assert_allclose(plant.f(x, {"K": 120.0}), expected, rtol=1e-12, atol=1e-12)
    assert plant.bound[0] == pytest.approx(2.5)


def test_link1_trajectory_reaching_with_coulomb_friction(link1):
    """Plant with Coulomb friction 2 N m (sign) on the motor: the gain synthesized with D = 2 still reaches."""
    from fjm_runtime.control.disturbance import with_motor_disturbance
    ref, E = REG
    kw = _link1_kwargs(REG, 8.0)
    gain = _link1_gain(link1, 8.0, disturbance_bound=2.0)
    ctrl = make_controller("smc", link1, {"K": K_NOM}, lam=8.0, k_s=gain.k_s, delta=gain.delta,
                           beta_hat=kw["beta_hat"])
    x0 = link1_T_inverse(ref(0.0)[:4, 0] + 0.8 * np.asarray(E), {"K": K_NOM})
    plant = with_motor_disturbance(link1, coulomb=2.0)
    res = simulate(plant, ctrl, ref, duration=1.0, dt=1e-4, true_params={"K": 100.0}, x0=x0)
    trajectory_check(res, E, gain.eta[0], ctrl.c)


def test_torque_disturbance_bound_is_enforced(link1):
    from fjm_runtime.control.disturbance import TorqueDisturbance
    ctrl = make_controller("smc", link1, {"K": K_NOM}, lam=8.0, k_s=100.0, delta=1.0)
    wrapped = TorqueDisturbance(ctrl, lambda t: np.array([3.0 * np.sin(t)]), bound=1.0)
    with pytest.raises(ValueError, match="exceeds the stated bound"):
        simulate(link1, wrapped, Sinusoid(0.5, 1.0), duration=2.0, dt=1e-2)


def test_torque_disturbance_reaches_the_plant(link1):
    """The plant receives the commanded torque plus d(t); the wrapped law itself is unchanged."""
    from fjm_runtime.control.disturbance import TorqueDisturbance
    ctrl = make_controller("smc", link1, {"K": K_NOM}, lam=8.0, k_s=100.0, delta=1.0)
    d = lambda t: np.array([0.5 * np.cos(3.0 * t)])
    res = simulate(link1, TorqueDisturbance(ctrl, d, bound=0.5), Sinusoid(0.5, 1.0), duration=0.05, dt=1e-3)
    for k in (0, 10, 49):
        commanded = ctrl.evaluate(res.t[k], res.x[k], res.z[k], res.ref[k]).u
        np.testing.assert_allclose(res.u[k], commanded + d(res.t[k]), rtol=1e-12, atol=1e-12)
