"""H = sup |alpha_hat - alpha| on a box (fjm_runtime.analysis.certificates.mismatch) against link1's closed form."""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.analysis.certificates.mismatch import mismatch_supremum
from support.link1_case import delta_alpha_closed_form


def _closed_form_supremum(Y, K_box, K_nom=150.0, n=200001):
    # K-only, B_m = 0 (link1 defaults): affine in 1/K, y2^2 and y3 (vertices carry the supremum); y1 scanned densely
    y1 = np.linspace(-Y[0], Y[0], n)
    best = 0.0
    for K in K_box:
        for y2 in (0.0, Y[1]):
            for y3 in (-Y[2], Y[2]):
                best = max(best, float(np.max(np.abs(delta_alpha_closed_form(y1, y2, y3, K, K_nom)))))
    return best


def test_refinement_finds_the_peak_between_grid_points():
    link1 = fjm_runtime.load("link1")
    Y = np.array([2.0, 0.7, 0.5, 0.0])
    p_nom = np.asarray(link1.params_array({"K": 150.0}), dtype=float)
    box = {"K": (100.0, 200.0)}
    best = _closed_form_supremum(Y, box["K"])
    coarse = mismatch_supremum(link1, p_nom, box, Y[:, None], lambda dim: 11)
    fine = mismatch_supremum(link1, p_nom, box, Y[:, None], lambda dim: 11, refine=True)
    assert coarse.H < best * (1 - 1e-4)  # the 11-point grid misses the interior peak in y1
    assert fine.H == pytest.approx(best, rel=1e-8)
    assert coarse.H <= fine.H
    assert fine.H_at["params"]["K"] in box["K"]
    # beta = J_l J_m / K, state-independent: its range comes from the ends of the stiffness interval
    assert (fine.beta_min, fine.beta_max) == pytest.approx((2.0 / 200.0, 2.0 / 100.0), rel=1e-12)


def test_no_uncertainty_no_mismatch():
    link1 = fjm_runtime.load("link1")
    p_nom = np.asarray(link1.params_array({}), dtype=float)
    r = mismatch_supremum(link1, p_nom, {}, np.array([[1.0], [1.0], [1.0], [1.0]]), lambda dim: 5, refine=True)
    assert r.H == 0.0
    assert r.beta_min == pytest.approx(float(link1.beta(np.zeros(4), {})[0, 0]), rel=1e-12)
    assert r.beta_max == r.beta_min
