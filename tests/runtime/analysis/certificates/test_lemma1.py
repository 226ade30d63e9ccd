"""Lemma 1 (fjm_runtime.analysis.certificates.lemma1) on link1: beta_hat, the mismatch bound, the gain, and the
paper's bound in true coordinates against an independent closed form."""
import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from fjm_runtime.control.laws import coefficients_from_pole
from fjm_runtime.analysis.certificates.lemma1 import alpha_mismatch_bound, beta_bounds_link1, lemma1_gain, paper_bound
from fjm_runtime.analysis.certificates.link1 import link1_alpha, link1_T_inverse
from support.link1_case import K_BOX, K_NOM, REG, TRK, delta_alpha_closed_form


def test_beta_hat_is_midpoint_of_corrected_beta():
    beta_min, beta_max, beta_hat, rho = beta_bounds_link1({}, {"K": (100.0, 200.0)})
    assert (beta_min, beta_max) == pytest.approx((2.0 / 200, 2.0 / 100))
    assert beta_hat == pytest.approx(0.015)
    assert rho == pytest.approx(1.0 / 3.0)
    # eq (14): |beta / beta_hat - 1| < 1 over the whole interval
    K = np.linspace(100, 200, 101)
    assert np.max(np.abs(2.0 / K / beta_hat - 1)) == pytest.approx(rho)


def test_alpha_mismatch_bound_closed_form_for_stiffness_only():
    # K-only, B_m = 0: alpha_hat - alpha = J_m M g L sin y1 (y2^2 + g cos y1)(1/K - 1/K_nom)
    #                                     + (K_nom/K - 1)(J_l + J_m)(y3 + g sin y1),  g = M g0 L / J_l
    Y = np.array([1.2, 0.7, 3.0, 0.0])
    H = alpha_mismatch_bound(Y, {}, {"K": (100.0, 200.0)}, n_grid=241)
    y1 = np.linspace(-Y[0], Y[0], 2401)
    best = 0.0
    for K in (100.0, 200.0):
        for y2sq in (0.0, Y[1] ** 2):
            for y3 in (-Y[2], Y[2]):
                val = 2 * 9.8 * np.sin(y1) * (y2sq + 9.8 * np.cos(y1)) * (1 / K - 1 / 150) \
                    + (150 / K - 1) * 3.0 * (y3 + 9.8 * np.sin(y1))
                best = max(best, np.max(np.abs(val)))
    assert H == pytest.approx(best, rel=2e-3)
    assert alpha_mismatch_bound(Y, {}, None) == 0.0  # no uncertainty, no mismatch


def test_alpha_mismatch_endpoints_suffice_for_stiffness_only():
    """K-only, B_m = 0: the interval's ends carry the supremum (affine in 1/K), so the default
    shortcut equals the full parameter grid; with B_m uncertain it is not taken."""
    for Y, box in (((0.5, 1.0, 2.0, 5.0), (100.0, 200.0)), ((1.0, 2.0, 10.0, 40.0), (70.0, 130.0))):
        fast = alpha_mismatch_bound(Y, {"K": 150.0}, {"K": box}, n_grid=21)
        full = alpha_mismatch_bound(Y, {"K": 150.0}, {"K": box}, n_grid=21, n_param=9, endpoints_only=False)
        assert fast == pytest.approx(full, rel=1e-12) and fast > 0
    Y = (0.5, 1.0, 2.0, 5.0)
    both = {"K": (100.0, 200.0), "B_m": (0.0, 0.5)}
    assert alpha_mismatch_bound(Y, {"K": 150.0}, both, n_grid=11) == \
        alpha_mismatch_bound(Y, {"K": 150.0}, both, n_grid=11, endpoints_only=False)


def test_lemma1_gain_structure():
    c = coefficients_from_pole(8.0)
    R = [0.5, 0.5, 0.5, 0.5, 0.5]
    g0 = lemma1_gain(c, R, bounds={"K": (100.0, 200.0)})
    g1 = lemma1_gain(c, R, bounds={"K": (100.0, 200.0)}, error_bounds=(0.05, 0.5, 0.5, 0.5))
    assert g0.W == pytest.approx(0.5)
    assert g1.W == pytest.approx(0.5 + 512 * 0.5 + 192 * 0.5 + 24 * 0.5)
    assert g1.k_s == pytest.approx(g1.W + g1.H / g1.beta_hat + g1.eta)
    assert g1.k_s_tight < g1.k_s and g1.k_s > g0.k_s
    assert g1.reaching_time_bound(100.0, 5.0) == pytest.approx(95.0 * 0.02 / (0.015 * 10.0))


def test_lemma1_gain_and_paper_bound_are_one_evaluation(link1):
    """Both entry points give a Lemma1Gain from lemma1_on_box: k_s is eq (16), k_s_tight = k_s - (1 - rho) W.
    On the tracking box the supremum sits at vertices, so link1's fixed grid and the refined grid agree."""
    c, R, E = coefficients_from_pole(8.0), [0.5, 0.5, 0.5, 0.5, 0.5], (0.05, 0.5, 0.5, 0.5)
    g = lemma1_gain(c, R, nominal={"K": 150.0}, bounds={"K": (100.0, 200.0)}, error_bounds=E)
    p = paper_bound(link1, {"K": 150.0}, param_box={"K": (100.0, 200.0)}, reference_bounds=R, error_bounds=E,
                    lam=8.0)
    for r in (g, p):
        assert r.k_s == pytest.approx(r.W + r.H / r.beta_hat + r.eta, rel=1e-14)
        assert r.k_s - r.k_s_tight == pytest.approx((1.0 - r.rho) * r.W, rel=1e-12)
    assert (p.k_s, p.k_s_tight, p.H, p.beta_hat) == pytest.approx((g.k_s, g.k_s_tight, g.H, g.beta_hat), rel=1e-12)
    # the largest mismatch is at the ends of the stiffness interval (affine in 1/K)
    assert g.H_at["params"]["K"] in (100.0, 200.0)


# -- the paper's Lemma 1 in TRUE coordinates, independent closed form -----------------------------
def test_closed_form_matches_link1_alpha():
    rng = np.random.default_rng(3)
    y = rng.uniform(-2, 2, size=(50, 4))
    for K in (100.0, 200.0, 123.0):
        x = link1_T_inverse(y, {"K": K})
        direct = link1_alpha(x, {"K": K_NOM}) - link1_alpha(x, {"K": K})
        np.testing.assert_allclose(delta_alpha_closed_form(y[:, 0], y[:, 1], y[:, 2], K, K_NOM), direct,
                                   rtol=1e-9, atol=1e-9)


def _independent_paper_bound(ref, E, lam, eta=10.0):
    R = ref.derivative_bounds()[:, 0]
    Y = R[:4] + np.asarray(E)
    c1, c2, c3 = lam ** 3, 3 * lam ** 2, 3 * lam
    W = R[4] + c1 * E[1] + c2 * E[2] + c3 * E[3]
    H = 0.0
    # affine in 1/K, in y2^2 and in y3: vertices; y1: dense scan then bounded refinement
    for K in (100.0, 200.0):
        for y2 in (0.0, Y[1]):
            for y3 in (-Y[2], Y[2]):
                f = lambda y1: -abs(delta_alpha_closed_form(y1, y2, y3, K, K_NOM))
                grid = np.linspace(-Y[0], Y[0], 20001)
                vals = -f(grid)
                j = int(np.argmax(vals))
                best = vals[j]
                lo, hi = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
                if hi > lo:
                    r = minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": 1e-13})
                    best = max(best, -r.fun)
                H = max(H, best)
    b_min, b_max = 1.0 * 2.0 / 200.0, 1.0 * 2.0 / 100.0
    b_hat = 0.5 * (b_min + b_max)
    rho = (b_max - b_min) / (b_max + b_min)
    return rho * W + H / b_hat + eta


# the regulation box (~10 s) runs in the exhaustive pass; tracking stays in make test
@pytest.mark.parametrize("box, published", [pytest.param(REG, 1240.0, marks=pytest.mark.exhaustive), (TRK, 765.0)],
                         ids=["regulation", "tracking"])
def test_paper_bound_in_true_coordinates(link1, box, published):
    ref, E = box
    expected = _independent_paper_bound(ref, E, 8.0)
    assert abs(expected - published) < 1.0, "the independent closed form no longer gives the published bound"
    got = paper_bound(link1, {"K": K_NOM}, param_box=K_BOX, reference_bounds=ref.derivative_bounds()[:, 0],
                      error_bounds=E, lam=8.0)
    assert got.k_s_tight == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("kwargs, field", [
    ({"c": [1.0, 2.0]}, "c"),
    ({"reference_bounds": [1.0, 1.0]}, "reference_bounds"),
    ({"error_bounds": [-1.0, 0, 0, 0]}, "error_bounds"),
    ({"eta": 0.0}, "eta"),
    ({"bounds": {"K": (200.0, 100.0)}}, "bounds"),
    ({"bounds": {"stiffness": (1.0, 2.0)}}, "bounds"),
])
def test_lemma1_rejects_bad_inputs(kwargs, field):
    args = {"c": [512.0, 192.0, 24.0], "reference_bounds": [0.5] * 5, "bounds": {"K": (100.0, 200.0)}}
    args.update(kwargs)
    c, rb = args.pop("c"), args.pop("reference_bounds")
    with pytest.raises(ValueError, match=field):
        lemma1_gain(c, rb, **args)
