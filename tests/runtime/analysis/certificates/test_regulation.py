"""Closed-loop eigenvalues at rest and the regulation offset of the paper's SMC under nominal-only T_hat
(fjm_runtime.analysis.certificates.regulation)."""
import numpy as np
import pytest

from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.laws import SlidingModeController
from fjm_runtime.control.references import SmoothStep
from fjm_runtime.analysis.certificates.lemma1 import beta_hat_link1
from fjm_runtime.analysis.certificates.regulation import predict_regulation_offset
from fjm_runtime.sim.simulate import simulate

K_BOUNDS = {"K": (100.0, 200.0)}
DESIGN = {"lam": 8.0, "k_s": 1000.0, "delta": 5.0}


def test_closed_loop_eigenvalues_exact_parameters_give_designed_poles(link1):
    from fjm_runtime.control.factory import make_controller
    from fjm_runtime.analysis.certificates.regulation import closed_loop_eigenvalues
    fl = make_controller("fl", link1, {}, lam=8.0)
    ev = closed_loop_eigenvalues(link1, fl, {})
    # quadruple pole at -8: a repeated root is ill-conditioned, so compare the characteristic polynomial
    assert np.real(np.poly(ev)) == pytest.approx([1, 32, 384, 2048, 4096], rel=1e-5)
    smc = make_controller("smc", link1, {}, lam=8.0, k_s=1000.0, delta=5.0)
    ev = closed_loop_eigenvalues(link1, smc, {})
    # inside the layer: triple pole at -8 and the s-pole at -k_s/delta = -200
    assert np.real(np.poly(ev)) == pytest.approx(np.poly([-8, -8, -8, -200]), rel=1e-5)
    # wrong stiffness moves the poles (and the chains can go unstable, see the demo)
    assert closed_loop_eigenvalues(link1, fl, {"K": 100.0})[0].real > -8.0 + 0.5


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
