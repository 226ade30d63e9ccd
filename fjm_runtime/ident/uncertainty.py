"""How sure an identification is: standard errors for coloured residuals, and a systematic term.

The residuals of a least-squares fit on filtered signals are coloured (correlated over a filter
window and more, where the model misses slow effects) and correlated WITH the regressors, so neither
the white-noise formula nor a uniform effective-sample count is honest. The Newey-West estimator
(a heteroskedasticity- and autocorrelation-consistent "sandwich") is
``cov = G^-1 S G^-1``, ``G = A^T A``, ``S = sum_(|l| <= L) (1 - |l| / (L + 1)) sum_t g_t g_(t-l)^T`` with
``g_t = a_t r_t`` (the Bartlett weights keep ``S`` positive semi-definite).

A standard error shrinks as ``1 / sqrt(T)`` with the log's length; what the method's model misses
(a real drive's friction is not exactly ``F_c sign(v)``, the filter's discretization, an encoder's
quantization) does not. :data:`SYSTEMATIC` is that part as a relative standard uncertainty per kind
of column, the largest relative bias measured on independent MuJoCo logs (docs/identification.md,
``examples/identify_validation.py``) rounded up; the stated uncertainty is ``sqrt(se^2 + sys^2)``.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["hac_covariance", "SYSTEMATIC", "INTERVAL_SIGMAS", "systematic", "combined"]

#: Standard uncertainties per half-width of a stated interval.
INTERVAL_SIGMAS = 3.0
#: Relative systematic standard uncertainty of each kind of regressor column (module docstring).
SYSTEMATIC = {"spring": 3e-4, "rotor_inertia": 3e-3, "damping": 5e-3, "friction": 5e-3, "offset": 0.0}


def hac_covariance(A: np.ndarray, r: np.ndarray, G_inv: np.ndarray, lags: int) -> np.ndarray:
    """Newey-West covariance of the coefficients of ``A theta = b`` (module docstring).

    Parameters
    ----------
    A : ndarray, shape (N, p)
        The regressor (the rows the fit used).
    r : ndarray, shape (N,)
        The fit's residuals.
    G_inv : ndarray, shape (p, p)
        The inverse of the normal matrix the estimate used (``(A^T A)^-1``, or its errors-in-variables
        corrected form).
    lags : int
        Bartlett bandwidth ``L``, samples (>= 0).

    Returns
    -------
    ndarray, shape (p, p)
    """
    g = np.asarray(A, dtype=float) * np.asarray(r, dtype=float)[:, None]
    S = g.T @ g
    for lag in range(1, min(int(lags), g.shape[0] - 1) + 1):
        c = g[lag:].T @ g[:-lag]
        S += (1.0 - lag / (lags + 1.0)) * (c + c.T)
    return G_inv @ S @ G_inv


def systematic(kind: str, value: float) -> float:
    """The systematic standard uncertainty of a parameter of column ``kind`` (:data:`SYSTEMATIC`), its unit."""
    return SYSTEMATIC[kind] * abs(float(value))


def combined(stderr: float, sys: float) -> float:
    """``sqrt(stderr^2 + sys^2)``: the standard uncertainty an interval is stated in."""
    return math.hypot(stderr, sys)
