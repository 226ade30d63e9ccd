"""Reaching certificate of the torque-sensed law (fjm_runtime.analysis.certificates.certify_tau, ``fjm tune --sensing torque``).

Controller on NOMINAL parameters (the emitted ``control_ismc_tau``), plant on TRUE ones. The
checks are independent of the analysis: the true state is rebuilt from ``y_hat`` by solving
``T_tau`` here, ``s'`` is a central difference of the emitted law's ``s`` along the true vector
field with the torque held, and the input gain of ``s_i'`` is measured by changing ``k_s``.
"""
import json

import numpy as np
import pytest

from fjm_runtime.analysis.certificates.certify import certificate
from fjm_runtime.analysis.certificates.certify_tau import (TorqueEvaluator, gamma_tolerance, synthesize_torque_gains,
                                              torque_param_box)
from fjm_runtime.cli.main import main
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import Sinusoid
from fjm_runtime.control.sensing import torque_measurement

E_BOX = (0.05, 0.5, 0.5, 0.5)
LAM = 8.0


@pytest.fixture(scope="module")
def certified(planar2):
    """The certificate on the feasible box (stiffness +-3 %, J_m +-1 %, payload 0.1 kg): (result, R, box)."""
    R, box = _setup(planar2, 0.03)
    res = synthesize_torque_gains(planar2, reference_bounds=R, error_bounds=E_BOX, lam=LAM, param_box=box,
                                  budget=1500)
    return res, R, box


def _K(model, p):
    names = list(model.param_names)
    return np.array([p[names.index(f"K{i + 1}")] for i in range(model.n)])


def _state(model, y_hat, p_true, p_nom):
    """True x from nominal torque coordinates: solve T_tau(m; p_nom)[2n:] = y_hat[2n:] for (tau_J, dtau_J)."""
    n = model.n
    T = model.torque_functions["T_tau"]
    v = np.zeros(2 * n)

    def res(v):
        m = np.concatenate([y_hat[:2 * n], v, y_hat[n:2 * n]])
        return np.asarray(T(m, p_nom)).ravel()[2 * n:] - y_hat[2 * n:]

    for _ in range(3):                     # T_tau is affine in (tau_J, dtau_J): the first step is exact
        r0 = res(v)
        J = np.column_stack([(res(v + 1e-3 * e) - res(v - 1e-3 * e)) / 2e-3 for e in np.eye(2 * n)])
        v = v - np.linalg.solve(J, r0)
    K = _K(model, p_true)
    return np.concatenate([y_hat[:n], y_hat[n:2 * n], y_hat[:n] + v[:n] / K, y_hat[n:2 * n] + v[n:] / K])


def _sdot(model, ctrl, x, z, r, p_true, h=1e-6):
    """(s, s') of the emitted law along the TRUE plant, torque held, z' = e1, reference Taylor-shifted."""
    K = _K(model, p_true)
    smp = ctrl.evaluate(0.0, torque_measurement(x, K), z, r)
    xd = np.asarray(model.f(x, p_true)).ravel() + np.asarray(model.g(x, p_true)) @ smp.u
    e1 = smp.e[0]
    shift = np.vstack([r[1:], np.zeros((1, r.shape[1]))])
    s = [ctrl.evaluate(0.0, torque_measurement(x + sg * h * xd, K), z + sg * h * e1, r + sg * h * shift).s
         for sg in (1.0, -1.0)]
    return smp.s, (s[0] - s[1]) / (2 * h)


def _realize(model, ctrl, y_hat, e, y4d, signs, S):
    """Reference r (5, n) and z with e = y_hat - y_d, y_d'''' = y4d and s_j = signs_j S_j (outside the layer)."""
    n = model.n
    Y = y_hat.reshape(4, n)
    r = np.vstack([Y - e, y4d[None, :]])
    c = ctrl.c
    rest = c[1] * e[0] + c[2] * e[1] + c[3] * e[2] + e[3]
    return r, (signs * S - rest) / c[0]


def _controller(model, p_nom, k_s):
    return make_controller("ismc", model, p_nom, lam=LAM, k_s=k_s, delta=np.maximum(k_s, 1.0) / 200.0,
                           sensing="torque")


def _setup(model, gamma):
    R = Sinusoid(0.5, 1.0, n=model.n).derivative_bounds()
    box = torque_param_box(model, None, (1 - gamma, 1 + gamma), (0.99, 1.01), 0.1)
    return R, box


@pytest.mark.slow
def test_certified_gain_reaches_at_sampled_points(planar2, certified):
    """Feasible box: sgn(s) s' <= -eta at random box points, with the certificate's k_s."""
    m = planar2
    res, R, box = certified
    assert res.feasible, res.reason
    p_nom = m.params_array()
    ctrl = _controller(m, p_nom, res.k_s)
    rng = np.random.default_rng(7)
    names = list(m.param_names)
    Ybox = (R[:4] + np.asarray(E_BOX)[:, None]).ravel()
    worst = -np.inf * np.ones(m.n)
    for _ in range(12):
        p = p_nom.copy()
        for nm, (lo, hi) in box.items():
            p[names.index(nm)] = rng.uniform(lo, hi)
        y_hat = rng.uniform(-Ybox, Ybox)
        e = rng.uniform(-1, 1, (4, m.n)) * np.asarray(E_BOX)[:, None]
        y4d = rng.uniform(-R[4], R[4])
        signs = rng.choice([-1.0, 1.0], m.n)
        x = _state(m, y_hat, p, p_nom)
        r, z = _realize(m, ctrl, y_hat, e, y4d, signs, 3.0 * ctrl.delta)
        s, sd = _sdot(m, ctrl, x, z, r, p)
        np.testing.assert_allclose(np.sign(s), signs)
        worst = np.maximum(worst, np.sign(s) * sd)
    assert np.all(worst <= -res.eta + 1e-6 * res.k_s), (worst, res.certificate)
    assert np.all(worst <= res.certificate + 1e-6 * res.k_s)


@pytest.mark.slow
def test_too_small_gain_fails_at_its_witness(planar2, certified):
    """Half the certified gain: the certificate exceeds -eta, and the emitted law on the true plant
    at the witness point really has sgn(s_i) s_i' > -eta_i (equal to the certificate's value there)."""
    m = planar2
    res, R, box = certified
    k_small = 0.5 * res.k_s
    cert = certificate(m, k_small, param_box=box, reference_bounds=R, error_bounds=E_BOX, lam=LAM, integral=True,
                       budget=1500, evaluator=TorqueEvaluator)
    i = int(np.argmax(cert["certificate"] + res.eta))
    assert cert["certificate"][i] > -res.eta[i]
    wit = cert["witness"][i]
    p_nom = m.params_array()
    p = p_nom.copy()
    for nm, v in wit["params"].items():
        p[list(m.param_names).index(nm)] = v
    ctrl = _controller(m, p_nom, k_small)
    y_hat = np.asarray(wit["y_hat"]).ravel()
    G_row = np.asarray(wit["G_row"])
    signs = -wit["sign_s"] * np.sign(G_row)
    signs[i] = wit["sign_s"]
    e = np.zeros((4, m.n))
    r, z = _realize(m, ctrl, y_hat, e, np.asarray(wit["w"]), signs, 3.0 * ctrl.delta)
    x = _state(m, y_hat, p, p_nom)
    s, sd = _sdot(m, ctrl, x, z, r, p)
    val = np.sign(s[i]) * sd[i]
    assert val > -res.eta[i]
    np.testing.assert_allclose(val, cert["certificate"][i], rtol=1e-5, atol=1e-5 * (1 + k_small[i]))


def test_gamma_tolerance_is_the_sign_change_of_the_measured_input_gain(planar2):
    """At the worst link angles, a stiffness-ratio spread just inside r_1 leaves the measured input gain
    of s_1' positive, just outside it negative (measured by changing k_s,1 in the emitted law)."""
    m = planar2
    p_nom = m.params_array()
    tol = gamma_tolerance(m, 0.55, samples=800)
    r1, q = tol["r_max"][0], np.asarray(tol["q_worst"][0])
    x0 = np.concatenate([q, np.zeros(m.n), q, np.zeros(m.n)])
    D = np.asarray(m.inertia(x0)).reshape(m.n, m.n)
    sgn_a = np.sign(np.linalg.inv(D)[0] * D[:, 0])
    names = list(m.param_names)
    gains = []
    for scale in (0.98, 1.02):
        p = p_nom.copy()
        for k in range(m.n):
            p[names.index(f"K{k + 1}")] *= 1.0 - scale * r1 * sgn_a[k]
        y_hat = np.concatenate([q, np.zeros(3 * m.n)])
        x = _state(m, y_hat, p, p_nom)
        out = []
        for k1 in (100.0, 200.0):
            ctrl = _controller(m, p_nom, np.array([k1, 100.0]))
            r, z = _realize(m, ctrl, y_hat, np.zeros((4, m.n)), np.zeros(m.n), np.ones(m.n), 3.0)
            out.append(_sdot(m, ctrl, x, z, r, p)[1][0])
        gains.append(-(out[1] - out[0]) / 100.0)
    assert gains[0] > 0 > gains[1], gains


def test_cli_states_the_obstacle_for_planar2(capsys):
    code = main(["tune", "planar2", "--sensing", "torque", "--budget", "2000"])
    out = json.loads(capsys.readouterr().out)
    assert code == 1 and not out["feasible"] and out["sensing"] == "torque"
    ig = out["settings"]["input_gain"]
    assert min(ig["G_diag_min"]) <= 0
    assert "r_i = 1 / sup_q" in out["settings"]["obstacle"]


def test_cli_certifies_link1_with_textbook_gain(capsys):
    """One joint: G = Gamma in [0.7/1.2, 1.3/0.8]; the gain meets k_s >= (sup |F| + eta) / Gamma_min."""
    code = main(["tune", "link1", "--sensing", "torque", "--budget", "3000"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["feasible"] and out["settings"]["law"] == "ismc_tau"
    ig = out["settings"]["input_gain"]
    np.testing.assert_allclose(ig["G_diag_min"][0], 0.7 / 1.2, rtol=1e-9)
    np.testing.assert_allclose(ig["G_diag_max"][0], 1.3 / 0.8, rtol=1e-9)
    assert out["k_s"][0] * 0.7 / 1.2 >= ig["drift_F0"][0] + out["eta"][0] - 1e-9


def test_bad_torque_arguments_are_one_line_errors(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["tune", "link1", "--sensing", "torque", "--gamma-range", "1.3"])
    assert exc.value.code == 2
    assert main(["tune", "link1", "--sensing", "torque", "--gamma-range", "1.3", "0.7"]) == 2
    assert "--gamma-range" in capsys.readouterr().err
