"""Gains for a sampling rate, found by running the batch engine over many sampled closed loops.

:func:`design` searches the integral sliding-mode law's gains (surface pole ``lam``, the quadruple
pole of the integral surface; ``k_lin``; ``k_s``; ``delta``) for a model, control rate, computation
delay and sensor model. Every candidate is simulated (:func:`fjm_runtime.batch.runner.simulate_batch`,
one compiled library for all candidates: the gains ride per run) on draws of the TRUE plant:

* ``K x U[0.7, 1.3]`` per joint, ``J_m x U[0.8, 1.2]`` per joint, payload ``U[0, 1]`` kg (models with
  ``m_load``), a sensor-noise seed per draw;
* first the corners: ``K`` all 0.7, all 1.3, alternating 0.7/1.3 (nominal ``J_m``, no payload), then
  the same three with ``J_m x 0.8`` and ``x 1.2`` and a 1 kg payload.

Cost of a run: the worst joint's second-half RMS error (rad) plus penalties,
``PENALTY * (max(0, time_at_limit - 2 %) / 2 % + max(0, jitter_{joints 1-4} - 3 N m) / 3 N m)``
(the largest over joints), a diverged run costs :data:`DIVERGED_COST`. The objective of a candidate
is the worst cost over the draws. Search (deterministic by seed): a log grid on ``lam`` x ``k_s``
(``k_lin = LIN_RATIO lam``, ``delta = k_s / 200``) on a screening set of draws and a short run,
then coordinate refinement (each gain x / divided by a factor, halving the factor each round), then
the best gains on all draws at the full duration. Margins: the largest tolerated delay (the best
gains re-run at ``d + 1, d + 2, ...`` on the screening draws until one fails) and the input-gain
range (every stiffness scaled by one factor ``g``, widening from the box until a draw fails).
"""
from __future__ import annotations

import math
import sys
from typing import Callable, Optional

import numpy as np

from ..control.factory import make_controller
from ..control.references import make_reference
from ..sim.sample_step import stiffness_indices
from ..sim.sensor import SensorModel
from ..validation import FjmValueError

__all__ = ["DIVERGED_COST", "PENALTY", "design", "draw_params", "evaluate_gains", "run_cost"]

#: Cost of a diverged run (rad): far above any tracking error.
DIVERGED_COST = 10.0
#: Weight (rad) of a constraint violation of one limit's size.
PENALTY = 1e-2
#: ``k_lin / lam`` of the grid stage.
LIN_RATIO = 5.0
#: Constraints: time at a torque limit, jitter on the first four joints.
MAX_TIME_AT_LIMIT = 0.02
MAX_JITTER = 3.0
#: Torque limits by model (N m; the Panda's URDF efforts).
EFFORTS = {"panda": (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)}


def draw_params(model, count: int, seed: int) -> np.ndarray:
    """TRUE parameter rows: the corners of the module docstring, then random draws; shape (count, n_params)."""
    n = int(model.n)
    iK, iJ = stiffness_indices(model)
    p0 = np.asarray(model.params_array({}), dtype=float)
    iL = list(model.param_names).index("m_load") if "m_load" in model.param_names else None
    alt = np.where(np.arange(n) % 2 == 0, 0.7, 1.3)
    corners = [(np.full(n, 0.7), 1.0, 0.0), (np.full(n, 1.3), 1.0, 0.0), (alt, 1.0, 0.0)]
    corners += [(k, jm, 1.0) for jm in (0.8, 1.2) for k in (np.full(n, 0.7), np.full(n, 1.3), alt)]
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(count):
        if i < len(corners):
            ks, js, load = corners[i][0], np.full(n, corners[i][1]), corners[i][2]
        else:
            ks, js, load = rng.uniform(0.7, 1.3, n), rng.uniform(0.8, 1.2, n), rng.uniform(0.0, 1.0)
        p = p0.copy()
        p[iK] *= ks
        p[iJ] *= js
        if iL is not None:
            p[iL] = load
        rows.append(p)
    return np.vstack(rows)


def run_cost(batch, n_jitter: int = 4) -> np.ndarray:
    """Per-run cost (module docstring) of a :class:`BatchResult`, shape (B,)."""
    jm = batch.joint_metrics
    rms = np.max(jm["rms_second_half"], axis=1)
    tal = np.max(jm["time_at_limit"], axis=1)
    jit = np.max(jm["torque_jitter"][:, :n_jitter], axis=1)
    jit = np.where(np.isfinite(jit), jit, 0.0)
    cost = rms + PENALTY * (np.maximum(0.0, tal - MAX_TIME_AT_LIMIT) / MAX_TIME_AT_LIMIT
                            + np.maximum(0.0, jit - MAX_JITTER) / MAX_JITTER)
    return np.where(batch.diverged | ~np.isfinite(cost), DIVERGED_COST, cost)


class _Problem:
    """Model, law, reference, sensor and the batch settings shared by every evaluation."""

    def __init__(self, model, kind, sensing, rate, delay, sensor, u_max, threads, simd, predict=False,
                 reference=None, x0=None, task=None):
        self.model, self.kind, self.sensing, self.delay = model, kind, sensing, int(delay)
        self.dt, self.sensor, self.u_max, self.threads, self.simd = 1.0 / rate, sensor, u_max, threads, simd
        self.predict, self.x0 = bool(predict), x0
        self.reference = make_reference("sine", int(model.n), amplitude=0.5, omega=1.0) if reference is None \
            else reference
        self.task = task or {"kind": "sine", "amplitude": 0.5, "omega": 1.0}

    def controller(self, g: dict):
        return make_controller(self.kind, self.model, {}, sensing=self.sensing, u_max=self.u_max, **g)

    def batch(self, cands, P, duration, seed, delay=None):
        """Every candidate on every row of ``P`` (seeds ``seed + row``): cost array (n_cand, n_rows)."""
        from ..batch.runner import simulate_batch
        ctrls = [self.controller(g) for g in cands]
        G = np.vstack([np.tile(c.gains, (P.shape[0], 1)) for c in ctrls])
        seeds = np.tile(seed + np.arange(P.shape[0]), len(cands))
        b = simulate_batch(self.model, ctrls[0], self.reference, np.tile(P, (len(cands), 1)), duration=duration,
                           dt=self.dt, sensor=self.sensor, delay_samples=self.delay if delay is None else delay,
                           seeds=seeds, gains=G, threads=self.threads, simd=self.simd, predict=self.predict,
                           x0=self.x0)
        return run_cost(b).reshape(len(cands), P.shape[0]), b


def evaluate_gains(prob: _Problem, gains: dict, P, duration: float, seed: int, delay=None):
    """``(worst cost, BatchResult)`` of one set of gains over the rows ``P``."""
    cost, b = prob.batch([gains], P, duration, seed, delay)
    return float(np.max(cost)), b


def _grid(lams, kss):
    return [{"lam": float(lam), "k_lin": LIN_RATIO * float(lam), "k_s": float(ks), "delta": float(ks) / 200.0}
            for lam in lams for ks in kss]


def _refine(prob, best, best_cost, P, duration, seed, rounds, say):
    """Coordinate refinement: each gain x / divided by ``f``; ``f`` shrinks each round."""
    f = 2.0
    for rnd in range(rounds):
        cands = []
        for key in ("lam", "k_lin", "k_s", "delta"):
            for s in (f, 1.0 / f):
                c = dict(best)
                c[key] = best[key] * s
                cands.append(c)
        cost = np.max(prob.batch(cands, P, duration, seed)[0], axis=1)
        j = int(np.argmin(cost))
        say(f"refine round {rnd + 1}/{rounds} (factor {f:.3g}): best {cost[j]:.4g} vs {best_cost:.4g}")
        if cost[j] < best_cost:
            best, best_cost = cands[j], float(cost[j])
        f = math.sqrt(f)
    return best, best_cost


def _delay_margin(prob, gains, P, duration, seed, max_extra, say) -> int:
    """Largest delay (samples) at which no screening draw fails (cost below the divergence/penalty level)."""
    d_ok = prob.delay
    for d in range(prob.delay + 1, prob.delay + 1 + max_extra):
        worst, b = evaluate_gains(prob, gains, P, duration, seed, delay=d)
        fails = bool(np.any(b.diverged)) or worst >= PENALTY
        say(f"delay margin: d = {d}: worst cost {worst:.4g}{' (fails)' if fails else ''}")
        if fails:
            break
        d_ok = d
    return d_ok


def _gain_range(prob, gains, duration, seed, say):
    """``[g_low, g_high]``: all stiffnesses x ``g``, widening from the box [0.7, 1.3] until a run fails."""
    iK = stiffness_indices(prob.model)[0]
    p0 = np.asarray(prob.model.params_array({}), dtype=float)
    lows, highs = [0.7, 0.6, 0.5, 0.4, 0.3, 0.2], [1.3, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0]
    rows = []
    for g in lows + highs:
        p = p0.copy()
        p[iK] *= g
        rows.append(p)
    cost, b = prob.batch([gains], np.vstack(rows), duration, seed)
    ok = (cost[0] < PENALTY) & ~b.diverged

    def widest(vals, flags):
        last = None
        for v, good in zip(vals, flags):
            if not good:
                break
            last = v
        return last
    rng = [widest(lows, ok[:len(lows)]), widest(highs, ok[len(lows):])]
    say(f"input-gain range: K x [{rng[0]}, {rng[1]}] (None: fails at the box edge)")
    return rng


def design(model, *, kind: str = "ismc", sensing: str = "torque", rate: float = 1000.0, delay: int = 1,
           sensor: Optional[SensorModel] = None, draws: int = 200, duration: float = 10.0, seed: int = 0,
           u_max=None, screen_draws: int = 12, screen_duration: float = 2.0, rounds: int = 3,
           max_extra_delay: int = 3, threads: Optional[int] = None, simd: bool = False,
           progress: Optional[Callable[[str], None]] = None, predict: bool = False, reference=None,
           x0=None, task: Optional[dict] = None) -> dict:
    """Search the gains (module docstring); returns the gains-file dict (``fjm simulate --gains``).

    ``predict`` runs every loop with the delay compensation of the sample step; ``reference`` and
    ``x0`` (shared by all runs) replace the default task (a 0.5 rad sine about q = 0 from rest),
    ``task`` describes them in the file.

    Returns
    -------
    dict
        ``model, kind, sensing, rate, delay, sensor, gains (lam, k_lin, k_s, delta, u_max),
        worst_case`` (worst over all draws: cost, rms_second_half, time_at_limit, torque_jitter on
        joints 1-4, diverged count), ``margins`` (delay, input_gain_range), ``draws, seed, duration``.
    """
    if kind != "ismc":
        raise FjmValueError(f"design: controller {kind!r}: the search covers the integral law 'ismc'")
    if draws < 1 or duration <= 0 or rate <= 0 or delay < 0:
        raise FjmValueError(f"design: draws = {draws}, duration = {duration}, rate = {rate}, delay = {delay}: "
                            "expected draws >= 1, duration > 0 s, rate > 0 Hz, delay >= 0")
    say = progress or (lambda msg: print(f"fjm design: {msg}", file=sys.stderr, flush=True))
    sensor = SensorModel.panda(seed=seed) if sensor is None else sensor
    u_max = EFFORTS.get(model.name) if u_max is None else u_max
    prob = _Problem(model, kind, sensing, rate, delay, sensor, u_max, threads, simd, predict, reference, x0, task)
    P_all = draw_params(model, max(draws, screen_draws), seed)
    P_screen = P_all[:screen_draws]
    cands = _grid(np.geomspace(20.0, 160.0, 4), np.geomspace(200.0, 20000.0, 5))
    cost = np.max(prob.batch(cands, P_screen, screen_duration, seed)[0], axis=1)
    j = int(np.argmin(cost))
    say(f"grid {len(cands)} candidates x {screen_draws} draws x {screen_duration:g} s: best {cost[j]:.4g} at "
        f"{cands[j]}")
    best, best_cost = _refine(prob, cands[j], float(cost[j]), P_screen, screen_duration, seed, rounds, say)
    say(f"final: {draws} draws x {duration:g} s with {best}")
    worst, b = evaluate_gains(prob, best, P_all[:draws], duration, seed)
    margins = {"delay": _delay_margin(prob, best, P_screen, screen_duration, seed, max_extra_delay, say),
               "input_gain_range": _gain_range(prob, best, screen_duration, seed, say)}
    return _report(model, prob, best, worst, b, margins, draws, seed, duration)


def _report(model, prob, best, worst, b, margins, draws, seed, duration) -> dict:
    from .. import __version__
    jm = b.joint_metrics
    finite = lambda a: [None if not np.isfinite(v) else float(v) for v in a]  # noqa: E731
    gains = dict(best)
    if prob.u_max is not None:
        gains["u_max"] = [float(v) for v in np.broadcast_to(prob.u_max, (int(model.n),))]
    return {"model": model.name, "kind": prob.kind, "sensing": prob.sensing, "rate": 1.0 / prob.dt,
            "delay": prob.delay, "sensor": {k: v for k, v in prob.sensor.__dict__.items()},
            "reference": prob.task, "predict": prob.predict, "gains": gains,
            "worst_case": {"cost": worst, "diverged": int(np.sum(b.diverged)),
                           "rms_second_half": finite(np.nanmax(jm["rms_second_half"], axis=0)),
                           "time_at_limit": finite(np.nanmax(jm["time_at_limit"], axis=0)),
                           "torque_jitter": finite(np.nanmax(jm["torque_jitter"], axis=0)),
                           "peak_torque": finite(np.nanmax(jm["peak_torque"], axis=0))},
            "margins": margins, "draws": int(draws), "seed": int(seed), "duration": float(duration),
            "fjm_version": __version__}
