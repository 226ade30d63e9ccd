"""Figures of merit of a closed-loop run: from sampled trajectories or from running sums.

:func:`compute_metrics` serves one stored run (:func:`fjm_runtime.sim.simulate.simulate`);
:func:`metrics_from_sums` turns the running sums of a compiled loop (one run or a batch)
into the same fields, so both give the same numbers.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Metrics:
    """Per-run figures of merit (link-position error ``e1 = q_l - q_d``, worst joint).

    Attributes
    ----------
    final_error : float
        ``max_i |e1_i(t_end)|`` in rad.
    rms_error : float
        RMS of ``e1`` over the whole run (all joints), rad.
    rms_error_second_half : float
        RMS of ``e1`` over ``t >= t_end / 2``, rad.
    max_abs_u : float
        ``max |u|`` in N m.
    reaching_time : float
        First time after which ``|s_i| <= delta_i`` for all joints until the end
        (s); ``inf`` if the boundary layer is not reached and kept.
    total_variation_u : float
        ``sum_k |u_{k+1} - u_k|`` (summed over joints), N m: the chattering measure.
    """

    final_error: float
    rms_error: float
    rms_error_second_half: float
    max_abs_u: float
    reaching_time: float
    total_variation_u: float

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def metrics_from_sums(t, final_error, sum_e2, sum_e2_half, max_abs_u, last_outside, total_variation_u,
                      n: int) -> dict:
    """The :class:`Metrics` fields from running sums (one run, or arrays of runs: the batch).

    Parameters
    ----------
    t : ndarray, shape (N+1,)
        Sample times.
    final_error, sum_e2, sum_e2_half, max_abs_u, total_variation_u : float or ndarray, shape (B,)
        ``max_i |e1_i(t_end)|``, ``sum e1^2`` over all samples and joints, the same over
        ``t >= t_end / 2``, ``max |u|``, ``sum_k |u_{k+1} - u_k|``.
    last_outside : float or ndarray, shape (B,)
        Last sample index with some ``|s_i| > delta_i`` (-1: never).
    n : int
        Number of joints.

    Returns
    -------
    dict str -> float or ndarray
    """
    N = t.size - 1
    n_half = int(np.count_nonzero(t >= 0.5 * t[-1]))
    last = np.asarray(last_outside, dtype=float)
    reaching = np.where(last >= N, np.inf, np.where(last < 0, t[0], t[np.minimum(last + 1, N).astype(int)]))
    return {"final_error": final_error,
            "rms_error": np.sqrt(np.asarray(sum_e2) / ((N + 1) * n)),
            "rms_error_second_half": np.sqrt(np.asarray(sum_e2_half) / (n_half * n)),
            "max_abs_u": max_abs_u,
            "reaching_time": reaching,
            "total_variation_u": total_variation_u}


def compute_metrics(t, e1, u, s, delta) -> Metrics:
    """Compute :class:`Metrics` from sampled trajectories.

    Parameters
    ----------
    t : ndarray, shape (N+1,)
    e1, u, s : ndarray, shape (N+1, n)
    delta : ndarray, shape (n,)
    """
    half = t >= 0.5 * t[-1]
    outside = np.flatnonzero(np.any(np.abs(s) > delta, axis=1))
    m = metrics_from_sums(t, np.max(np.abs(e1[-1])), np.sum(e1 ** 2), np.sum(e1[half] ** 2),
                          np.max(np.abs(u)), outside[-1] if outside.size else -1,
                          np.sum(np.abs(np.diff(u, axis=0))), e1.shape[1])
    return Metrics(**{k: float(v) for k, v in m.items()})


# -- per-joint figures of a stored run (the ``fjm simulate --json`` report) ---------------------
#
# ``result`` is a :class:`fjm_runtime.sim.simulate.SimulationResult`; the torques are the ones
# applied, ``u_0 .. u_{N-1}`` (each held over a sample; the last row ``u_N`` is never applied).

def rms_second_half(result) -> np.ndarray:
    """RMS of ``e1 = q - q_d`` per joint over the samples with ``t >= t_end / 2``, rad, shape (n,)."""
    half = result.t >= 0.5 * result.t[-1]
    return np.sqrt(np.mean(result.e1[half] ** 2, axis=0))


def peak_torque(result) -> np.ndarray:
    """``max_k |u_k|`` per joint over the applied torques, N m, shape (n,)."""
    return np.max(np.abs(result.u[:-1]), axis=0)


def time_at_limit(result, u_max=None) -> np.ndarray:
    """Fraction of the applied samples with ``|u_k| >= u_max (1 - 1e-9)`` per joint, shape (n,).

    ``u_max`` defaults to ``result.u_max`` (the controller's limit); without a limit: zeros.
    """
    limit = result.u_max if u_max is None else np.asarray(u_max, dtype=float)
    u = np.abs(result.u[:-1])
    if limit is None:
        return np.zeros(u.shape[1])
    return np.mean(u >= np.broadcast_to(limit, (u.shape[1],)) * (1.0 - 1e-9), axis=0)


def time_at_rate_limit(result) -> np.ndarray:
    """Fraction of the applied samples whose torque moved by the whole allowed step, per joint, shape (n,).

    Counts ``k = 1..N-1`` with ``|u_k - u_{k-1}| >= R T (1 - 1e-9)`` over ``N`` applied samples
    (the batch engine counts the same), ``R`` from ``result.settings['torque_rate_limit']``;
    zeros without a rate limit.
    """
    u = result.u[:-1]
    rate = (getattr(result, "settings", None) or {}).get("torque_rate_limit")
    if rate is None or u.shape[0] < 2:
        return np.zeros(u.shape[1])
    T = float(result.t[1] - result.t[0])
    r = np.array([np.inf if v is None else v for v in np.atleast_1d(np.asarray(rate, dtype=object))], dtype=float)
    step = np.broadcast_to(r * T, (u.shape[1],))
    return np.sum(np.abs(np.diff(u, axis=0)) >= step * (1.0 - 1e-9), axis=0) / u.shape[0]


def torque_jitter(result, window: float = 0.02) -> np.ndarray:
    """Standard deviation of ``u`` minus its centred moving mean, per joint, N m, shape (n,).

    The mean is over ``2h + 1`` samples with ``h = round(window / (2 T))`` (20 ms by default),
    taken where the whole window lies inside the run (``N - 2h`` samples); ``nan`` if the run is
    shorter than the window.
    """
    u = result.u[:-1]
    T = float(result.t[1] - result.t[0])
    h = max(1, int(round(0.5 * window / T)))
    width = 2 * h + 1
    if u.shape[0] < width:
        return np.full(u.shape[1], np.nan)
    c = np.vstack([np.zeros((1, u.shape[1])), np.cumsum(u, axis=0)])
    mean = (c[width:] - c[:-width]) / width
    return np.std(u[h:u.shape[0] - h] - mean, axis=0)

