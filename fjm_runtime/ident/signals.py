"""Offline (non-causal) smoothing and differentiation of logged signals, numpy only.

Identification runs after the fact, so it may look ahead: every signal goes through the same
Savitzky-Golay filter (a least-squares polynomial of degree ``order`` over a centred window of
``2h + 1`` samples), which gives the smoothed value and its first and second derivatives with zero
phase lag. Applying the SAME linear filter to every signal keeps a linear equation between them
(``J_m ddq_m + B_m dq_m + tau_J = u`` holds for the filtered signals too); only the nonlinear
columns (friction, a cubic spring) are evaluated on filtered signals, a second-order effect.
The first and last ``h`` samples (the filter's edges) are dropped.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["savgol_kernels", "smooth_derivatives", "effective_samples"]


def savgol_kernels(half: int, order: int, dt: float) -> np.ndarray:
    """Convolution kernels of value, first and second derivative, shape (3, 2 half + 1).

    ``kernels[d] @ x[k - half : k + half + 1]`` is the ``d``-th derivative at sample ``k`` of the
    least-squares polynomial of degree ``order`` through the window (``dt`` the sample interval).
    """
    if half < 1 or order < 2 or 2 * half + 1 <= order:
        raise ValueError(f"Savitzky-Golay window 2*{half}+1 with degree {order}: expected half >= 1, "
                         "2 <= order < window")
    s = np.arange(-half, half + 1, dtype=float)
    V = np.vander(s, order + 1, increasing=True)          # x(s) ~ sum_j c_j s^j
    P = np.linalg.pinv(V)                                 # c = P x
    return np.stack([P[0], P[1] / dt, 2.0 * P[2] / dt ** 2])


def smooth_derivatives(x: np.ndarray, dt: float, half: int, order: int = 3):
    """``(x, dx, ddx)`` of the columns of ``x`` (N, m), each (N - 2 half, m): the filter's edges dropped."""
    x = np.asarray(x, dtype=float)
    K = savgol_kernels(half, order, dt)
    w = 2 * half + 1
    windows = np.lib.stride_tricks.sliding_window_view(x, w, axis=0)   # (N - 2h, m, w)
    return tuple(np.einsum("kmw,w->km", windows, K[d]) for d in range(3))


def effective_samples(residual: np.ndarray, max_lag: int) -> float:
    """Samples of independent information in a residual series: ``N / tau``, ``tau = 1 + 2 sum rho_k``.

    The residuals of a fit on filtered signals are correlated over about a filter window; treating
    them as independent would understate the standard errors by ``sqrt(tau)``. The sum runs over
    lags ``1..max_lag`` and stops at the first negative autocorrelation.
    """
    r = np.asarray(residual, dtype=float) - np.mean(residual)
    N = r.size
    var = float(r @ r) / N
    if var == 0.0 or N < 4:
        return float(N)
    tau = 1.0
    for k in range(1, min(max_lag, N // 4) + 1):
        rho = float(r[:-k] @ r[k:]) / (N * var)
        if rho <= 0.0:
            break
        tau += 2.0 * rho
    return max(N / tau, 1.0)


def window_half(dt: float, seconds: float) -> int:
    """The half-width ``h`` (samples) of a filter window of about ``seconds``, at least 3."""
    return max(3, int(math.ceil(0.5 * seconds / dt)))
