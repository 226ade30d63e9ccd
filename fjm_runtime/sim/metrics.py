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
