"""Offline (non-causal) smoothing and differentiation of logged signals, numpy only.

Identification runs after the fact, so it may look ahead: every signal goes through the same
zero-phase filter, a centred window of ``2h + 1`` samples (:func:`consistent_kernels`: a Blackman
window applied to the samples and to their central first and second differences), which gives the
smoothed value and its first and second derivatives. Because the derivative kernels are the value
kernel applied to differences, a linear equation between the samples (``J_m ddq_m + B_m dq_m + tau_J
= u`` with the held torque of :func:`held_torque`) holds between the filtered signals at every
frequency; only the nonlinear columns (friction, a cubic spring) are evaluated on filtered signals.
(:func:`savgol_kernels`, a Savitzky-Golay filter, is flatter in its pass band, but its derivative
kernels are not its value kernel's: above its cut-off the equation no longer holds between them.)
The first and last ``h`` samples (the filter's edges) are dropped.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["savgol_kernels", "consistent_kernels", "smooth_derivatives", "held_torque", "sample_velocity",
           "white_noise", "moving_rows",
           "window_half"]


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


def consistent_kernels(half: int, dt: float) -> np.ndarray:
    """Kernels of value, first and second derivative, shape (3, 2 half + 1), that are ONE filter.

    The value kernel ``w`` is a Blackman window (smooth, zero at both ends), normalised to sum 1; the derivative
    kernels are ``w`` applied to the central first difference and to the second difference of the
    samples (so ``K2 @ x == w @ (Delta^2 x / dt^2)`` exactly). A linear equation between the samples
    (``J_m ddq_m + ... = u``) then holds between the filtered signals at every frequency, where a
    Savitzky-Golay filter's derivative kernels differ from its value kernel above its cut-off. The
    second difference of samples of a motion under a held torque is the triangle-weighted mean
    acceleration over two intervals: the same mean of a held torque is :func:`held_torque`'s.
    """
    if half < 2:
        raise ValueError(f"window half-width {half}: expected >= 2")
    inner = np.blackman(2 * half + 1)[1:-1]
    w = np.concatenate([[0.0], inner / inner.sum(), [0.0]])
    wp = np.concatenate([[0.0], w, [0.0]])
    k1 = (wp[:-2] - wp[2:]) / (2 * dt)       # w applied to (x[k+1] - x[k-1]) / 2dt, as a correlation
    k2 = (wp[:-2] - 2 * wp[1:-1] + wp[2:]) / dt ** 2
    return np.stack([w, k1, k2])


def smooth_derivatives(x: np.ndarray, dt: float, half: int, order: int = 3, kernels=None):
    """``(x, dx, ddx)`` of the columns of ``x`` (N, m), each (N - 2 half, m): the filter's edges dropped."""
    x = np.asarray(x, dtype=float)
    K = savgol_kernels(half, order, dt) if kernels is None else kernels
    w = 2 * half + 1
    windows = np.lib.stride_tricks.sliding_window_view(x, w, axis=0)   # (N - 2h, m, w)
    return tuple(np.einsum("kmw,w->km", windows, K[d]) for d in range(3))


def held_torque(u: np.ndarray) -> np.ndarray:
    """The commanded torque averaged over the sample interval centred on each sample, shape of ``u``.

    ``u[k]`` acts from ``t_k`` to ``t_(k+1)`` (a zero-order hold, as every sampled controller), so the
    torque around ``t_k`` is ``(u[k-1] + u[k]) / 2``: the same triangle-weighted mean over two intervals
    that the second difference of the angles takes of the acceleration. Fitting ``u[k]`` itself against
    the state at ``t_k`` puts it half a sample late (``-dt/2 du/dt``, mostly the spring's ``K dphi``).
    """
    u = np.asarray(u, dtype=float)
    return np.concatenate([u[:1], 0.5 * (u[1:] + u[:-1])], axis=0)


def sample_velocity(x: np.ndarray, dt: float, half: int = 5) -> np.ndarray:
    """A lightly smoothed velocity at EVERY sample of the columns of ``x`` (N, m), shape (N, m).

    :func:`consistent_kernels` over ``2 half + 1`` samples, the first and last ``half`` repeated. For a
    nonlinear function of the velocity (friction) evaluated per sample and THEN filtered like every other
    column: filtering ``sign(v)`` is not ``sign`` of the filtered ``v`` within a window of a reversal.
    """
    v = smooth_derivatives(x, dt, half, kernels=consistent_kernels(half, dt))[1]
    return np.concatenate([np.repeat(v[:1], half, axis=0), v, np.repeat(v[-1:], half, axis=0)], axis=0)


def white_noise(raw: np.ndarray) -> float:
    """Variance ``s^2`` of the white noise on a sampled signal (N,), from its fourth difference.

    ``Delta^4 e`` of white noise has variance ``70 s^2`` (``1 + 16 + 36 + 16 + 1``); a smooth motion's own
    fourth difference, ``(omega dt)^4`` of it, is negligible at the rates of a log. A kernel ``k`` leaves
    ``s^2 sum k^2`` of the noise in its output.
    """
    d4 = np.diff(np.asarray(raw, dtype=float), n=4, axis=0)
    return float(np.mean(d4 ** 2)) / 70.0


def moving_rows(velocity: np.ndarray, half: int, threshold: float) -> np.ndarray:
    """Samples whose window of ``2 half + 1`` samples stays where ``|velocity| > threshold``, bool (N,).

    Near a velocity reversal a drive's dry friction passes through stiction (neither a tanh nor a sign
    law describes it): those windows would bias the rotor inertia and damping, so the motor equation
    leaves them out.
    """
    slow = np.abs(np.asarray(velocity, dtype=float)) <= threshold
    c = np.concatenate([[0], np.cumsum(slow)])
    idx = np.arange(slow.size)
    lo, hi = np.clip(idx - half, 0, slow.size), np.clip(idx + half + 1, 0, slow.size)
    return (c[hi] - c[lo]) == 0


def window_half(dt: float, seconds: float) -> int:
    """The half-width ``h`` (samples) of a filter window of about ``seconds``, at least 3."""
    return max(3, int(math.ceil(0.5 * seconds / dt)))
