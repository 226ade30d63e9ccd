"""The identification's standard errors from first principles (fjm_runtime.ident.uncertainty)."""
import numpy as np

from fjm_runtime.ident.uncertainty import hac_covariance


def test_sandwich_is_the_white_noise_formula_for_white_residuals_and_grows_for_coloured_ones():
    rng = np.random.default_rng(3)
    N = 20000
    A = np.column_stack([np.sin(np.linspace(0, 30, N)), np.ones(N)])
    G_inv = np.linalg.inv(A.T @ A)
    r = rng.standard_normal(N)
    white = np.diag(G_inv) * np.mean(r ** 2)
    np.testing.assert_allclose(np.diag(hac_covariance(A, r, G_inv, 0)), white, rtol=0.05)
    coloured = np.convolve(r, np.ones(20) / np.sqrt(20), mode="same")   # same variance, correlated over 20
    ratio = np.diag(hac_covariance(A, coloured, G_inv, 80)) / (np.diag(G_inv) * np.mean(coloured ** 2))
    assert np.all(ratio > 8)                          # about the 20-sample correlation length (Bartlett-shrunk)
