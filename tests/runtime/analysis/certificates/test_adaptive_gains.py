"""Gains of the adaptive law (fjm_runtime.analysis.certificates.adaptive_gains) on link1, against a closed form."""
import numpy as np
import pytest

from support.link1_case import K_NOM, REG


def test_adaptive_gamma_and_frozen_gains(link1):
    """d s / d K_hat on link1 (integral surface): (c3 (y3 + g sin y1) + y4 + g cos(y1) y2) / K_hat, largest at
    the box corner y1 = Y1 (tan y1 < c3 / Y2 there) and K_hat = K_min; the gain covers every frozen estimate."""
    from fjm_runtime.analysis.certificates.adaptive_gains import synthesize_adaptive_gains
    ref, E = REG
    R = ref.derivative_bounds()[:, 0]
    res = synthesize_adaptive_gains(link1, {"K": K_NOM}, K_bounds=(100.0, 200.0), reference_bounds=R,
                                    error_bounds=E, lam=8.0, n_estimates=2, n_grid=15, n_gamma=2000)
    Y = R[:4] + np.asarray(E)
    c3, g = 4 * 8.0, 9.8
    assert np.arctan(c3 / Y[1]) > Y[0]
    expected = (c3 * (Y[2] + g * np.sin(Y[0])) + Y[3] + g * np.cos(Y[0]) * Y[1]) / 100.0
    assert res.Gamma[0, 0] == pytest.approx(expected, rel=1e-9)
    assert res.tv_bound[0] == pytest.approx(50.0)
    for est, r in res.per_estimate:
        assert r.feasible and r.certificate[0] <= -r.eta[0] + 1e-9
        assert res.k_s[0] >= r.k_s[0]
