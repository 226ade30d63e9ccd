"""The regulation offset of the paper's SMC under nominal-only T_hat, and the integral surface."""
import numpy as np
import pytest

from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.laws import SlidingModeController
from fjm_runtime.control.references import Sinusoid, SmoothStep
from fjm_runtime.analysis.certificates.lemma1 import beta_hat_link1
from fjm_runtime.analysis.certificates.regulation import predict_regulation_offset
from fjm_runtime.sim.simulate import simulate

K_BOUNDS = {"K": (100.0, 200.0)}
DESIGN = {"lam": 8.0, "k_s": 1000.0, "delta": 5.0}


@pytest.mark.parametrize("K_nom, K_true, q_d, lam", [
    (150.0, 100.0, 1.0, 5.0),
    (150.0, 200.0, 1.0, 8.0),
    (120.0, 180.0, 0.6, 6.0),
    (200.0, 100.0, -0.8, 8.0),
])
def test_predicted_offset_matches_simulation(link1, K_nom, K_true, q_d, lam):
    ctrl = SlidingModeController(link1, {"K": K_nom}, lam=lam, k_s=1000.0, delta=5.0)
    pred = predict_regulation_offset(link1, ctrl, q_d, {"K": K_true})
    res = simulate(link1, ctrl, SmoothStep(q_d, rise_time=2.0), duration=20.0, true_params={"K": K_true})
    assert abs(pred.offset) > 0.02  # a real offset, not a rounding artefact
    assert res.e1[-1, 0] == pytest.approx(pred.offset, abs=1e-6)
    # the sliding-surface term -(c3/c1) e3 explains it up to the boundary-layer term and sin(q_ss) vs sin(q_d)
    assert np.sign(pred.first_order) == np.sign(pred.offset)
    assert abs(pred.s_ss) < ctrl.delta[0]  # rests inside the boundary layer


@pytest.mark.parametrize("K_true", [100.0, 150.0, 200.0])
def test_integral_smc_removes_regulation_offset(link1, K_true):
    ref = SmoothStep(1.0, rise_time=2.0)
    bh = beta_hat_link1({}, K_BOUNDS)
    ismc = make_controller("ismc", link1, {}, beta_hat=bh, **DESIGN)
    res = simulate(link1, ismc, ref, duration=10.0, true_params={"K": K_true})
    # README: |e1| < 1e-11 after 10 s (measured 2.7e-12, 4e-15, 1.5e-14 at K = 100, 150, 200)
    assert abs(res.e1[-1, 0]) < 1e-11
    smc = make_controller("smc", link1, {}, beta_hat=bh, **DESIGN)
    pred = predict_regulation_offset(link1, smc, 1.0, {"K": K_true})
    res_smc = simulate(link1, smc, ref, duration=10.0, true_params={"K": K_true})
    bound = 1e-4 + abs(pred.offset - pred.first_order)  # boundary-layer term + sin(q_ss)/sin(q_d) difference
    assert abs(res_smc.e1[-1, 0]) >= abs(pred.first_order) - bound
    if K_true != 150.0:
        assert abs(res_smc.e1[-1, 0]) > 0.05


@pytest.mark.parametrize("K_true", [100.0, 200.0])
def test_integral_smc_tracks_sine_five_to_six_times_better(link1, K_true):
    ref = Sinusoid(0.5, 1.0)
    bh = beta_hat_link1({}, K_BOUNDS)
    rms = {}
    for kind in ("smc", "ismc"):
        ctrl = make_controller(kind, link1, {}, beta_hat=bh, **DESIGN)
        rms[kind] = simulate(link1, ctrl, ref, duration=10.0,
                             true_params={"K": K_true}).metrics.rms_error_second_half
    # README: "cuts the tracking RMS error 5-6x"; measured 4.97x (K = 100) and 6.29x (K = 200).
    # Margin: 10 % below 5x, 10 % above 6.3x.
    ratio = rms["smc"] / rms["ismc"]
    assert 4.5 < ratio < 7.0, rms


@pytest.mark.parametrize("K_true", [100.0, 200.0])
def test_anti_windup_under_torque_limit(link1, K_true):
    """u_max = 10 N m (the hold needs 8.25 N m; the 1 s step would need ~20 N m): bounded overshoot, converges."""
    ref = SmoothStep(1.0, rise_time=1.0)
    out = {}
    for aw in (True, False):
        ctrl = make_controller("ismc", link1, {}, beta_hat=0.015, u_max=10.0, anti_windup=aw, **DESIGN)
        res = simulate(link1, ctrl, ref, duration=10.0, true_params={"K": K_true})
        assert res.metrics.max_abs_u <= 10.0 + 1e-12
        out[aw] = (np.max(res.e1[:, 0]), abs(res.e1[-1, 0]), np.max(np.abs(res.z)))
    overshoot, final, zmax = out[True]
    assert overshoot < 0.2  # stated bound (measured 0.075 at K=100, 0.186 at K=200)
    assert final < 1e-10  # measured 5.9e-12 (K = 100) and 0 (K = 200) at 10 s
    assert zmax < out[False][2] and overshoot <= out[False][0]


def test_offset_prediction_rejects_integral_and_sign(link1):
    with pytest.raises(ValueError, match="integral"):
        predict_regulation_offset(link1, make_controller("ismc", link1, {}, **DESIGN), 1.0, {"K": 100.0})
    with pytest.raises(ValueError, match="sign"):
        predict_regulation_offset(link1, make_controller("sign", link1, {}, lam=8.0, k_s=10.0), 1.0, {"K": 100.0})


@pytest.mark.parametrize("K_true, claimed", [(100.0, -0.169), (200.0, +0.102)])
def test_readme_offset_numbers_for_table_1(link1, K_true, claimed):
    """README: Table 1, q_d = 1 rad, K_nom = 150: offset -0.169 rad at K = 100, +0.102 rad at K = 200,
    matched by simulation; about -(3 / lambda^2)(K_nom / K - 1) M g0 L sin(q_d) / J_l."""
    lam = DESIGN["lam"]
    smc = make_controller("smc", link1, {"K": 150.0}, beta_hat=beta_hat_link1({}, K_BOUNDS), **DESIGN)
    pred = predict_regulation_offset(link1, smc, 1.0, {"K": K_true})
    assert pred.offset == pytest.approx(claimed, abs=5e-4)
    res = simulate(link1, smc, SmoothStep(1.0, rise_time=2.0), duration=10.0, true_params={"K": K_true})
    assert res.e1[-1, 0] == pytest.approx(pred.offset, abs=1e-6)
    approx = -(3.0 / lam ** 2) * (150.0 / K_true - 1.0) * 1.0 * 9.8 * 1.0 * np.sin(1.0) / 1.0
    assert pred.first_order == pytest.approx(approx, rel=1e-12)
    assert abs(pred.offset - approx) < 0.15 * abs(approx)  # "about": measured 12.5 % (K = 100), 5.8 % (K = 200)
