"""The NumPy peer of ``simulate_batch``: the bench's link1 case vectorized over runs, the same figures.

One RK4 step per sample of the closed forms of link1 (plant ``K`` per run; ideal sensor, no delay,
the stateless SMC law, no torque limit), computing everything ``simulate_batch(..., substeps=1)``
returns for that case, so the timing compares the same work:

* the whole-run metrics (:func:`fjm_runtime.sim.metrics.metrics_from_sums`) and the final states;
* the divergence check of every sample (a state beyond ``max_state`` or not finite: the run is
  frozen at its last good state, its figures become NaN, its divergence time is recorded);
* the per-joint figures: ``rms_second_half``, ``peak_torque`` over the applied torques,
  ``time_at_limit`` (zero: no limit) and ``torque_jitter``, the std of the centred deviation
  ``u_{k-h} - mean(u_{k-2h} .. u_k)`` over the full 20 ms windows (a ring buffer of the last
  ``2h + 1`` torques and their running sum).
"""
from __future__ import annotations

from typing import Dict

import numpy as np

from fjm_runtime.batch.sampled import jitter_half_width
from fjm_runtime.sim.metrics import metrics_from_sums

__all__ = ["JOINT_PEER_FIGURES", "numpy_batch"]

#: The per-joint figures of ``BatchResult.joint_metrics`` the peer computes (the bench compares them).
JOINT_PEER_FIGURES = ("rms_second_half", "peak_torque", "time_at_limit", "torque_jitter")


class _RunFigures:
    """The per-run figures beyond the metrics: peak torque, jitter and the divergence check, for ``B`` runs."""

    def __init__(self, B: int, dt: float, max_state: float):
        self.h = jitter_half_width(dt)
        self.width = 2 * self.h + 1
        self.ring = np.zeros((self.width, B))   # the last `width` applied torques, slot k % width
        self.window_sum = np.zeros(B)
        self.jit_sum, self.jit_sq, self.peak = np.zeros(B), np.zeros(B), np.zeros(B)
        self.first_bad = np.full(B, -1.0)
        self.max_state = max_state

    def applied(self, k: int, u: np.ndarray) -> None:
        """Sample ``k``'s torque ``u`` is applied (every sample but the last)."""
        np.maximum(self.peak, np.abs(u), out=self.peak)
        slot = k % self.width
        self.window_sum += u - self.ring[slot]
        self.ring[slot] = u
        if k >= 2 * self.h:
            dev = self.ring[(k - self.h) % self.width] - self.window_sum / self.width
            self.jit_sum += dev
            self.jit_sq += dev * dev

    def checked(self, k: int, old, new):
        """``new`` states, with each run that is (or just became) diverged frozen at ``old``."""
        M = self.max_state
        ok = (np.abs(new[0]) <= M) & (np.abs(new[1]) <= M) & (np.abs(new[2]) <= M) & (np.abs(new[3]) <= M)
        frozen = self.first_bad >= 0
        if ok.all() and not frozen.any():   # NaN compares false: a non-finite state is not ok
            return new
        self.first_bad[~ok & ~frozen] = k + 1
        keep = ~ok | frozen
        return tuple(np.where(keep, o, nw) for o, nw in zip(old, new))

    def joint(self, N: int, n_half: int, sum_half: np.ndarray) -> Dict[str, np.ndarray]:
        """The per-joint figures (columns of one joint), NaN rows for diverged runs."""
        cnt = N - 2 * self.h
        mean = self.jit_sum / cnt
        out = {"rms_second_half": np.sqrt(sum_half / n_half), "peak_torque": self.peak.copy(),
               "time_at_limit": np.zeros_like(self.peak),
               "torque_jitter": np.sqrt(np.maximum(self.jit_sq / cnt - mean * mean, 0.0))}
        diverged = self.first_bad >= 0
        for v in out.values():
            v[diverged] = np.nan
        return {k: v[:, None] for k, v in out.items()}


def numpy_batch(case, K_values: np.ndarray, max_state: float = 1e6) -> dict:
    """Every figure of ``simulate_batch(case..., substeps=1)`` for plants with ``K_values``, NumPy over runs.

    Returns
    -------
    dict
        The metrics (arrays (B,)), ``x_final`` (B, 4), ``joint_metrics`` (name -> (B, 1)),
        ``diverged`` (B,) and ``divergence_time`` (B,; NaN if never).
    """
    if getattr(case.controller, "u_max", None) is not None:
        raise ValueError("the NumPy peer models no torque limit; the case's controller has u_max")
    B = K_values.size
    dt, N = case.dt, case.n_steps
    pt = case.p_true
    Jl, Jm, MgL, Bm = pt[0], pt[1], pt[3] * pt[4] * pt[5], pt[6]
    K = np.asarray(K_values, dtype=float)
    pn = case.p_nom
    nJl, nJm, nK, nMgL, nBm = pn[0], pn[1], pn[2], pn[3] * pn[4] * pn[5], pn[6]
    c1, c2, c3 = case.controller.c
    k_s, delta = float(case.controller.k_s[0]), float(case.controller.delta[0])
    bh = case.controller.beta_hat
    beta_hat = float(bh[0, 0]) if bh is not None else None
    R = case.reference.sample(dt * np.arange(N + 1)).reshape(N + 1, 5)
    x = tuple(np.full(B, v) for v in case.x0())
    t = dt * np.arange(N + 1)
    half = t >= 0.5 * t[-1]
    sum_e2 = np.zeros(B); sum_half = np.zeros(B); max_u = np.zeros(B); tv = np.zeros(B)
    last_out = np.full(B, -1.0); u_prev = np.zeros(B)
    figures = _RunFigures(B, dt, max_state)
    h = 0.5 * dt

    def f(q, dq, qm, dqm, u):
        spring = K * (q - qm)
        return dq, -(MgL * np.sin(q) + spring) / Jl, dqm, (spring - Bm * dqm + u) / Jm

    for k in range(N + 1):
        r = R[k]
        q, dq, qm, dqm = x
        sq, cq = np.sin(q), np.cos(q)
        spring = nK * (q - qm)
        y3 = -(nMgL * sq + spring) / nJl
        y4 = -(nMgL * cq * dq + nK * (dq - dqm)) / nJl
        a = -(-nMgL * sq * dq * dq + nMgL * cq * y3 + nK * (y3 - (spring - nBm * dqm) / nJm)) / nJl
        beta = nJl * nJm / nK
        e1, e2, e3, e4 = q - r[0], dq - r[1], y3 - r[2], y4 - r[3]
        s = c1 * e1 + c2 * e2 + c3 * e3 + e4
        nu = r[4] - (c1 * e2 + c2 * e3 + c3 * e4) - k_s * np.clip(s / delta, -1.0, 1.0)
        u = -beta * a + (beta_hat if beta_hat is not None else beta) * nu
        e2sq = e1 * e1
        sum_e2 += e2sq
        if half[k]:
            sum_half += e2sq
        np.maximum(max_u, np.abs(u), out=max_u)
        if k:
            tv += np.abs(u - u_prev)
        u_prev = u
        last_out = np.where(np.abs(s) > delta, float(k), last_out)
        if k == N:
            break
        figures.applied(k, u)
        a1 = f(q, dq, qm, dqm, u)
        a2 = f(q + h * a1[0], dq + h * a1[1], qm + h * a1[2], dqm + h * a1[3], u)
        a3 = f(q + h * a2[0], dq + h * a2[1], qm + h * a2[2], dqm + h * a2[3], u)
        a4 = f(q + dt * a3[0], dq + dt * a3[1], qm + dt * a3[2], dqm + dt * a3[3], u)
        x = figures.checked(k, x, tuple(xi + dt / 6 * (b1 + 2 * b2 + 2 * b3 + b4)
                                        for xi, b1, b2, b3, b4 in zip(x, a1, a2, a3, a4)))
    q = x[0]
    metrics = metrics_from_sums(t, np.abs(q - R[N, 0]), sum_e2, sum_half, max_u, last_out, tv, 1)
    diverged = figures.first_bad >= 0
    metrics = {k: np.where(diverged, np.nan, np.asarray(v, dtype=float)) for k, v in metrics.items()}
    return {**metrics, "x_final": np.stack(x, axis=1),
            "joint_metrics": figures.joint(N, int(np.count_nonzero(half)), sum_half),
            "diverged": diverged, "divergence_time": np.where(diverged, figures.first_bad * dt, np.nan)}
