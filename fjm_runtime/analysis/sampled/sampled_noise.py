"""Stationary noise response of a linear sampled loop: covariance, torque jitter, tracking error.

The loop linearized about an operating point (:mod:`fjm_runtime.analysis.sampled.sampled_linear`)::

    w_{k+1} = A w_k + B n_k          n_k white, E[n n'] = diag(sigma^2)   (nm channels)
    u_k     = C w_k + D n_k

has, when ``rho(A) < 1``, the stationary covariance ``P = A P A' + B S B'`` (discrete Lyapunov
equation, ``S = diag(sigma^2)``) and the torque autocovariance (``tau >= 1``)::

    R(0)   = C P C' + D S D'
    R(tau) = E[u_{k+tau} u_k'] = C A^tau P C' + C A^(tau-1) B S D'

The torque jitter of :func:`fjm_runtime.sim.metrics.torque_jitter` is the std of
``v_k = u_k - mean(u_{k-h} .. u_{k+h})`` = ``sum_i c_i u_{k+i}`` with ``c_0 = 1 - 1/W``,
``c_i = -1/W`` (``W = 2h + 1``), so ``Var(v) = sum_tau a(tau) R(tau)`` with
``a(tau) = sum_i c_i c_{i+tau}`` (the autocorrelation of ``c``). Because the channels are
independent, every variance is the sum of one term per channel (:func:`channel_variances`).
"""
from __future__ import annotations

import numpy as np

__all__ = ["jitter_weights", "stationary_covariance", "torque_jitter_variance", "channel_variances"]


def jitter_weights(h: int) -> np.ndarray:
    """``a(tau)`` for ``tau = 0..2h``: the autocorrelation of the centred-moving-mean filter, shape (2h+1,)."""
    width = 2 * h + 1
    c = np.full(width, -1.0 / width)
    c[h] += 1.0
    return np.array([np.dot(c[:width - t], c[t:]) for t in range(width)])


def stationary_covariance(A, BS, tol: float = 1e-14, max_doublings: int = 60) -> np.ndarray:
    """``P`` with ``P = A P A' + BS BS'``; ``BS`` = ``B sqrt(S)`` (nw, nm). Shape (nw, nw).

    The series ``P = sum_k A^k Q A'^k`` (``Q = BS BS'``) summed by doubling (Smith's method):
    ``P <- P + A_j P A_j'``, ``A_j <- A_j^2``, each pass doubling the number of terms, until a pass
    adds less than ``tol`` of ``P`` (numpy only: the runtime needs no SciPy). A radius of 0.9999
    takes about 18 passes.

    Raises
    ------
    ValueError
        The series does not converge (``rho(A) >= 1``): no stationary covariance.
    """
    Aj = np.asarray(A, dtype=float)
    BS = np.asarray(BS, dtype=float)
    P = BS @ BS.T
    with np.errstate(over="ignore", invalid="ignore"):     # an unstable A overflows: refused below
        for _ in range(max_doublings):
            add = Aj @ P @ Aj.T
            P = P + add
            if not np.all(np.isfinite(P)):
                break
            if np.max(np.abs(add)) <= tol * max(np.max(np.abs(P)), 1e-300):
                return 0.5 * (P + P.T)
            Aj = Aj @ Aj
    raise ValueError("stationary_covariance: the series does not converge (spectral radius of A >= 1)")


def torque_jitter_variance(A, BS, C, DS, h: int, P=None) -> np.ndarray:
    """Variance of the jitter metric's ``u_k - centred moving mean`` per joint, shape (n,).

    Parameters
    ----------
    A : ndarray (nw, nw)
    BS, DS : ndarray (nw, nm), (n, nm)
        ``B`` and ``D`` with each noise column scaled by its standard deviation.
    C : ndarray (n, nw)
    h : int
        Half-width of the 20 ms window in samples (:func:`fjm_runtime.batch.sampled.jitter_half_width`).
    P : ndarray (nw, nw), optional
        The stationary covariance (computed when not given).
    """
    P = stationary_covariance(A, BS) if P is None else P
    a = jitter_weights(h)
    var = a[0] * (np.einsum("ij,jk,ik->i", C, P, C) + np.sum(DS * DS, axis=1))
    X = P @ C.T                    # A^tau P C'
    Y = BS @ DS.T                  # A^(tau-1) B S D'
    for tau in range(1, a.size):
        X = A @ X
        var += 2.0 * a[tau] * (np.einsum("ij,ji->i", C, X) + np.einsum("ij,ji->i", C, Y))
        Y = A @ Y
    return np.maximum(var, 0.0)


def channel_variances(A, BS, C, DS, h: int, rows_q):
    """Per noise channel: the jitter variance per joint and the link-angle variance per joint.

    Returns
    -------
    jitter : ndarray (nm, n)
    q : ndarray (nm, n)
        ``Var(q_i)`` due to channel ``c`` alone (``rows_q``: the rows of ``w`` holding ``q``).
    """
    nm = BS.shape[1]
    n = C.shape[0]
    jit, q = np.zeros((nm, n)), np.zeros((nm, len(rows_q)))
    for c in range(nm):
        if not np.any(BS[:, c]) and not np.any(DS[:, c]):
            continue
        P = stationary_covariance(A, BS[:, c:c + 1])
        jit[c] = torque_jitter_variance(A, BS[:, c:c + 1], C, DS[:, c:c + 1], h, P)
        q[c] = np.diag(P)[rows_q]
    return jit, q


def modal_form(A, max_condition: float = 1e9):
    """``(vals, V, W)``: the eigenvalues, eigenvectors and ``W = V^-1`` of ``A``; None when ``V`` is
    ill-conditioned (a nearly defective ``A``: the modal sums below would lose accuracy)."""
    vals, V = np.linalg.eig(np.asarray(A, dtype=float))
    try:
        W = np.linalg.inv(V)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(W)) or np.linalg.norm(V, 1) * np.linalg.norm(W, 1) > max_condition:
        return None                       # 1-norm condition number: an SVD costs more than the rest
    return vals, V, W


def modal_channel_variances(modal, BS, outputs, h: int):
    """Per noise channel, the stationary variance of outputs and the torque jitter variance, by modes.

    With ``A = V diag(lambda) W`` the covariance a channel ``b`` adds is ``V ((W b)(W b)^H o M) V^H``,
    ``M_kl = 1 / (1 - lambda_k conj(lambda_l))``, and ``sum_tau a(tau) A^tau`` is diagonal in the modes:
    the same sums as :func:`torque_jitter_variance`, without a Lyapunov solve per channel.

    Parameters
    ----------
    modal : tuple
        :func:`modal_form` of a stable ``A`` (nw, nw).
    BS : ndarray (nw, nm)
        ``B`` with each noise column scaled by its standard deviation.
    outputs : list of (C, DS, jitter)
        Outputs ``y = C w + DS n`` (``C`` (no, nw), ``DS`` (no, nm)); ``jitter`` True: also the variance of
        ``y_k`` minus its centred ``2h + 1`` mean (the torque jitter metric).
    h : int
        Half-width of the jitter window in samples.

    Returns
    -------
    list of ndarray (nm, no)
        Per output: the stationary variance per channel, then (for a jitter output) the jitter variance.
    """
    vals, V, W = modal
    Bt = W @ np.asarray(BS, dtype=float)                        # (nw, nm) modal inputs
    M = 1.0 / (1.0 - vals[:, None] * np.conj(vals)[None, :])
    a = jitter_weights(h)
    pw = vals[None, :] ** np.arange(a.size)[:, None]             # lambda^tau, tau = 0..2h
    omega = a[1:] @ pw[1:]                                        # sum_{tau>=1} a(tau) lambda^tau
    psi = a[1:] @ pw[:-1]                                         # sum_{tau>=1} a(tau) lambda^(tau-1)
    res = []
    for C, DS, jitter in outputs:
        G = np.asarray(C, dtype=float) @ V
        X = G[None, :, :] * Bt.T[:, None, :]                      # (nm, no, nw): G_ik Bt_kc
        XM = X @ M
        var = np.real(np.sum(XM * np.conj(X), axis=2))
        DS2 = np.asarray(DS, dtype=float).T ** 2
        res.append(np.maximum(var + DS2, 0.0))
        if jitter:
            lag = np.real(np.sum((X * omega[None, None, :]) @ M * np.conj(X), axis=2))
            cross = np.real(np.sum(X * psi[None, None, :], axis=2)) * np.asarray(DS, dtype=float).T
            res.append(np.maximum(a[0] * (var + DS2) + 2.0 * (lag + cross), 0.0))
    return res


def impulse_channel_variances(A, BS, outputs, h: int, rel_tol: float = 1e-8, max_lags: int = 20000):
    """The figures of :func:`modal_channel_variances` from the impulse responses, for any stable ``A``.

    Channel ``c``'s response of ``y = C w + DS n`` is ``DS[:, c]`` at lag 0 and ``C A^(k-1) BS[:, c]`` at lag
    ``k``; its variance is the sum of squares, and the jitter's the sum of squares of the response filtered by
    ``u_k - mean(u_{k-h} .. u_{k+h})``. The lags run until ``|A^k BS|`` is below ``rel_tol`` of ``|BS|``
    (a radius of 0.956: about 400 lags); None when that takes more than ``max_lags``.
    """
    A, BS = np.asarray(A, dtype=float), np.asarray(BS, dtype=float)
    Call = np.vstack([np.asarray(C, dtype=float) for C, _d, _j in outputs])
    Dall = np.vstack([np.asarray(D, dtype=float) for _c, D, _j in outputs])
    X, stop = BS.copy(), rel_tol * max(np.max(np.abs(BS)), 1e-300)
    lags = [Dall]
    while np.max(np.abs(X)) > stop:
        if len(lags) > max_lags:
            return None
        lags.append(Call @ X)
        X = A @ X
    G = np.stack(lags)                                      # (K, no, nm): lag, output, channel
    width = 2 * h + 1
    K, zeros = G.shape[0], lambda k: np.zeros((k,) + G.shape[1:])
    csum = np.concatenate([zeros(1), np.cumsum(np.concatenate([zeros(2 * h), G, zeros(2 * h)]), axis=0)])
    mean = (csum[width:K + 4 * h + 1] - csum[:K + 2 * h]) / width    # centred means for lags -h .. K-1+h
    gz = np.concatenate([zeros(h), G, zeros(h)])
    res, row = [], 0
    for C, _d, jitter in outputs:
        sl = slice(row, row + np.asarray(C).shape[0])
        row = sl.stop
        res.append(np.sum(G[:, sl] ** 2, axis=0).T)
        if jitter:
            res.append(np.sum((gz[:, sl] - mean[:, sl]) ** 2, axis=0).T)
    return res
