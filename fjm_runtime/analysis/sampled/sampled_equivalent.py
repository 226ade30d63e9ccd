"""The law's boundary layer under sensor noise: the equivalent-gain (statistical) linearization.

The law's switching term ``k_s sat(s / delta)`` has the slope ``k_s / delta`` inside its layer and 0
outside. A small-signal linearization sees the slope; in a loop whose noise moves ``s`` across the
layer many times its width (the shipped Panda design: ``|s| / delta`` about 200 on joint 7) the term is
closer to ``k_s sign(s)``, and the slope is not the gain the loop feels. For ``s`` Gaussian with mean
``mu`` (its value at the operating point) and std ``sigma``, the term is replaced by its best linear fit
(Booton's equivalent gain; Gelb and Vander Velde, *Multiple-input describing functions*, 1968)::

    k_s sat(s / delta) ~ k_s E[sat] + N (s - mu) + e,     N = (k_s / delta) P(|s| < delta)

with ``e`` uncorrelated with ``s``, of variance ``k_s^2 Var(sat) - N^2 sigma^2``, entering ``nu`` as
white noise (the residual of a hard limiter on a correlated Gaussian input is nearly white: its
autocorrelation is ``(2/pi)(arcsin rho - rho)``, about ``rho^3 / 3``). ``sigma`` itself is the loop's:
the fixed point ``sigma = sigma_s(N(sigma))`` is found by a damped iteration on ``log sigma``
(:func:`equivalent_loop`). Inside the layer (``sigma << delta``) ``N`` is the slope and ``e`` vanishes: the
small-signal linearization is the special case.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .sampled_noise import (impulse_channel_variances, modal_channel_variances, modal_form, stationary_covariance,
                            torque_jitter_variance)

__all__ = ["sat_moments", "with_slope", "EquivalentLoop", "equivalent_loop", "loop_figures", "noise_columns"]

#: Iterations of the fixed point, its tolerance on ``log sigma`` and its damping.
ITERATIONS, TOLERANCE, DAMPING = 120, 1e-3, 0.5


def _normal_cdf(z) -> np.ndarray:
    return 0.5 * (1.0 + np.array([math.erf(v / math.sqrt(2.0)) for v in np.ravel(z)]).reshape(np.shape(z)))


def sat_moments(mu, sigma, delta):
    """``(p_in, mean, var)`` of ``y = sat(x / delta)`` for ``x ~ N(mu, sigma^2)``, each shape (n,).

    ``p_in = P(|x| < delta)``; closed forms with the normal pdf/cdf (``sigma = 0``: ``x = mu``).
    """
    mu, delta = np.asarray(mu, dtype=float), np.asarray(delta, dtype=float)
    sig = np.maximum(np.asarray(sigma, dtype=float), 1e-300)
    a, b = (-delta - mu) / sig, (delta - mu) / sig
    pa, pb = np.exp(-0.5 * a * a) / math.sqrt(2 * math.pi), np.exp(-0.5 * b * b) / math.sqrt(2 * math.pi)
    Fa, Fb = _normal_cdf(a), _normal_cdf(b)
    p_in = np.maximum(Fb - Fa, 0.0)
    ex = mu * p_in + sig * (pa - pb)                                   # E[x 1_in]
    ex2 = mu * mu * p_in + 2 * mu * sig * (pa - pb) + sig * sig * (p_in + a * pa - b * pb)
    mean = ex / delta + (1.0 - Fb) - Fa
    var = np.maximum(ex2 / delta ** 2 + (1.0 - p_in) - mean ** 2, 0.0)
    return p_in, mean, var


def with_slope(lin, d_slope):
    """``(A, B, C, D)`` of ``lin`` with the layer's slope changed by ``d_slope`` (n,) per joint.

    ``nu_j`` gains ``-d_slope_j s_j``: ``A - Bv diag(d) Cs``, ``B - Bv diag(d) Ds``, and the same on ``C, D``.
    """
    d = np.asarray(d_slope, dtype=float)
    BvD, DvD = lin.Bv * d[None, :], lin.Dv * d[None, :]
    return lin.A - BvD @ lin.Cs, lin.B - BvD @ lin.Ds, lin.C - DvD @ lin.Cs, lin.D - DvD @ lin.Ds


def loop_figures(A, BS, C, DS, CsS, DsS, qrows, h: int, channels: bool = False, modal=None):
    """Per noise channel (``channels``) or summed: torque jitter, link-angle and ``s`` variances per joint.

    Returns ``(jitter, q, s)``, each (n,) or, with ``channels``, (nm, n). Modal sums when ``A`` is
    diagonalizable with a well-conditioned basis (``modal``: its :func:`modal_form`, computed when not
    given); else per channel the impulse-response sums, and for the totals the Lyapunov doubling sum.
    """
    modal = modal_form(A) if modal is None else modal
    Cq = np.zeros((len(qrows), A.shape[0]))
    Cq[np.arange(len(qrows)), qrows] = 1.0
    outs = [(C, DS, True), (Cq, np.zeros((len(qrows), BS.shape[1])), False), (CsS, DsS, False)]
    figs = modal_channel_variances(modal, BS, outs, h) if modal else \
        (impulse_channel_variances(A, BS, outs, h) if channels else None)
    if figs is not None:
        _u, jit, q_var, s_var = figs
        return (jit, q_var, s_var) if channels else (jit.sum(0), q_var.sum(0), s_var.sum(0))
    if channels:                         # a radius too close to 1 for the impulse sums
        cols = [loop_figures(A, BS[:, c:c + 1], C, DS[:, c:c + 1], CsS, DsS[:, c:c + 1], qrows, h, modal=False)
                for c in range(BS.shape[1])]
        return tuple(np.array([col[k] for col in cols]) for k in range(3))
    P = stationary_covariance(A, BS)
    jit = torque_jitter_variance(A, BS, C, DS, h, P)
    s_var = np.einsum("ij,jk,ik->i", CsS, P, CsS) + np.sum(DsS * DsS, axis=1)
    return jit, np.diag(P)[qrows], s_var


def _radius(A):
    """``(rho, modal)``: the spectral radius and :func:`modal_form` (False when ill-conditioned)."""
    modal = modal_form(A)
    vals = modal[0] if modal else np.linalg.eigvals(A)
    return float(np.max(np.abs(vals))), (modal if modal else False)


@dataclass
class EquivalentLoop:
    """The equivalent-gain loop at its fixed point (or where the iteration stopped).

    ``gain`` (n,) the equivalent slope ``N``; ``p_in`` (n,) the fraction of time inside the layer;
    ``sigma_s`` (n,) the std of ``s``; ``residual`` (n,) the std of ``e``; ``A, B, C, D`` the loop with
    ``N``; ``rho`` its spectral radius; ``converged``; ``reason`` why not.
    """

    gain: np.ndarray
    p_in: np.ndarray
    sigma_s: np.ndarray
    residual: np.ndarray
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    rho: float
    converged: bool
    reason: str = ""
    iterations: int = 0


def noise_columns(lin, ABCD, levels, residual):
    """``(BS, DS, DsS)``: the noise columns of ``x, u, s`` scaled by their std, the sensor channels (``levels``)
    then one residual channel per joint on ``nu`` (``residual`` (n,), std)."""
    A, B, C, D = ABCD
    BS = np.hstack([B * levels[None, :], lin.Bv * residual[None, :]])
    DS = np.hstack([D * levels[None, :], lin.Dv * residual[None, :]])
    DsS = np.hstack([lin.Ds * levels[None, :], np.zeros_like(lin.Dv)])
    return BS, DS, DsS


def equivalent_loop(lin, levels, k_s, delta, slope, h: int, qrows, sigma0=None) -> Optional[EquivalentLoop]:
    """The fixed point ``sigma = sigma_s(N(sigma))`` of the equivalent-gain loop at ``lin``'s point.

    Parameters
    ----------
    lin : Linearization
        With ``Cs, Ds, Bv, Dv, s``.
    levels : ndarray (nm,)
        Sensor noise std per channel.
    k_s, delta : ndarray (n,)
        The law's switching gain and boundary layer.
    slope : ndarray (n,)
        The slope ``lin`` carries (``k_s / delta`` of the law linearized where ``|s|`` is inside its
        layer, else 0).
    h : int
        Jitter half-window, samples.
    qrows : list of int
        Rows of the link angles in ``A``.
    sigma0 : ndarray (n,), optional
        A start for ``sigma`` (another point's fixed point); default: the saturated loop's (``N = 0``).
    """
    levels, k_s, delta = (np.asarray(v, dtype=float) for v in (levels, k_s, delta))
    active = k_s > 0
    mu = np.asarray(lin.s, dtype=float)
    sigma = np.maximum(np.abs(mu), delta)                 # a start outside nothing: refined below
    zero = np.zeros_like(k_s)
    ABCD = with_slope(lin, -np.asarray(slope, dtype=float))  # the saturated loop: sensor noise only
    BS, DS, DsS = noise_columns(lin, ABCD, levels, zero)
    rho, modal = (2.0, False) if sigma0 is not None else _radius(ABCD[0])
    if sigma0 is not None:
        sigma = np.maximum(np.asarray(sigma0, dtype=float), 1e-9 * delta)
    elif rho < 1.0:
        sigma = np.maximum(np.sqrt(loop_figures(ABCD[0], BS, ABCD[2], DS, lin.Cs, DsS, qrows, h, modal=modal)[2]),
                           1e-9 * delta)
    last = None
    for it in range(ITERATIONS):
        p_in, mean, var = sat_moments(mu, sigma, delta)
        N = np.where(active, k_s / delta * p_in, 0.0)
        residual = np.where(active, np.sqrt(np.maximum(k_s ** 2 * var - N ** 2 * sigma ** 2, 0.0)), 0.0)
        ABCD = with_slope(lin, N - slope)
        rho, modal = _radius(ABCD[0])
        last = (N, p_in, residual, ABCD)
        if rho >= 1.0:                                    # sigma too small for this gain: widen
            if np.all(sigma[active] > 1e8 * delta[active]):
                break
            sigma = np.where(active, 4.0 * sigma, sigma)
            continue
        BS, DS, DsS = noise_columns(lin, ABCD, levels, residual)
        s_new = np.maximum(np.sqrt(loop_figures(ABCD[0], BS, ABCD[2], DS, lin.Cs, DsS, qrows, h, modal=modal)[2]),
                           1e-9 * delta)
        step = np.log(s_new) - np.log(sigma)
        if np.max(np.abs(step[active]), initial=0.0) < TOLERANCE:
            return EquivalentLoop(N, p_in, s_new, residual, *ABCD, rho, True, iterations=it + 1)
        sigma = np.exp(np.log(sigma) + DAMPING * step)
    N, p_in, residual, ABCD = last
    reason = "unstable at every equivalent gain tried" if rho >= 1.0 else \
        f"the equivalent-gain iteration did not settle in {ITERATIONS} steps"
    return EquivalentLoop(N, p_in, sigma, residual, *ABCD, rho, False, reason, ITERATIONS)
