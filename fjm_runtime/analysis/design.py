"""Gains for a sampling rate, found by running the batch engine over many sampled closed loops.

:func:`design` searches the integral sliding-mode law's gains for a model, control rate, computation
delay and sensor model: the surface pole ``lam`` (the quadruple pole of the integral surface, shared
by the joints because the emitted law has one set of surface coefficients) and, PER JOINT, ``k_lin``,
``k_s`` and ``delta``. Every candidate is simulated (:func:`fjm_runtime.batch.runner.simulate_batch`,
one compiled library for all candidates: the gains ride per run; SIMD by default) on draws of the
TRUE plant:

* ``K x U[0.7, 1.3]`` per joint, ``J_m x U[0.8, 1.2]`` per joint, payload ``U[0, 1]`` kg (models with
  ``m_load``), a sensor-noise seed per draw;
* first the corners: ``K`` all 0.7, all 1.3, alternating 0.7/1.3 (nominal ``J_m``, no payload), then
  the same three with ``J_m x 0.8`` and ``x 1.2`` and a 1 kg payload.

Cost of a run: the worst joint's second-half RMS error (rad) plus penalties summed over the joints,
``PENALTY * sum_j (max(0, time_at_limit_j - 2 %) / 2 % + max(0, jitter_j - 3 N m) / 3 N m)`` (jitter on
joints 1-4 only), a diverged run costs :data:`DIVERGED_COST`. The sum (not the largest) lets a move
of one joint's gain count even when another joint violates more. The objective of a candidate is
the worst cost over the draws.

Search (deterministic by seed): a log grid on ``lam`` x ``k_s`` (``k_lin = LIN_RATIO lam``,
``delta = k_s / 200``, the same on every joint) on a screening set of draws and a short run, then a
pattern search: each round tries every coordinate (``lam``, and ``k_lin_j``, ``k_s_j``, ``delta_j``
of every joint) times and divided by a factor ``f``, plus the candidate that takes every improving
move at once (the joints are weakly coupled, so their moves mostly add); the best of these replaces
the incumbent if it is better, otherwise ``f`` shrinks to ``sqrt(f)``. ``k_lin_j`` is kept at or above
:data:`LIN_FLOOR` ``lam`` (measured reason at the constant). Per-joint gains matter on an
arm: the proximal joints (large ``D``, stiff) turn encoder noise into torque jitter through
``beta^-1 = J_m K^-1 D`` and want a small ``k_lin``, the wrist (small ``D``) wants a large one. Then
the best gains run on all draws at the full duration; then an active-set pass: the final check's worst
draws join the screening set, the search runs two more rounds on it with runs twice as long, and the
final check is repeated. Margins: the largest tolerated delay (the
best gains re-run at ``d + 1, d + 2, ...`` on the screening draws until one fails) and the
input-gain range (every stiffness scaled by one factor ``g``, widening from the box until a draw
fails).
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

__all__ = ["DIVERGED_COST", "LIN_FLOOR", "PENALTY", "combine_moves", "design", "draw_params", "evaluate_gains",
           "move_gain", "run_cost"]

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
EFFORTS = {"panda": (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0),
           # head_pan, then each arm's s0, s1, e0, e1 (50 N m) and w0, w1, w2 (15 N m): the URDF's <limit effort>
           # (the head's URDF value, 50000, is a placeholder: 50 N m)
           "baxter": (50.0,) + (50.0, 50.0, 50.0, 50.0, 15.0, 15.0, 15.0) * 2}


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
    tal = np.asarray(jm["time_at_limit"], dtype=float)
    jit = np.asarray(jm["torque_jitter"], dtype=float)[:, :n_jitter]
    jit = np.where(np.isfinite(jit), jit, 0.0)
    cost = rms + PENALTY * (np.sum(np.maximum(0.0, tal - MAX_TIME_AT_LIMIT), axis=1) / MAX_TIME_AT_LIMIT
                            + np.sum(np.maximum(0.0, jit - MAX_JITTER), axis=1) / MAX_JITTER)
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
        """Every candidate on every row of ``P``: cost array (n_cand, n_rows).

        ``seed``: an int (row ``i`` gets noise seed ``seed + i``) or one seed per row.
        """
        from ..batch.runner import simulate_batch
        ctrls = [self.controller(g) for g in cands]
        G = np.vstack([np.tile(c.gains, (P.shape[0], 1)) for c in ctrls])
        row_seeds = seed + np.arange(P.shape[0]) if np.ndim(seed) == 0 else np.asarray(seed)
        seeds = np.tile(row_seeds, len(cands))
        b = simulate_batch(self.model, ctrls[0], self.reference, np.tile(P, (len(cands), 1)), duration=duration,
                           dt=self.dt, sensor=self.sensor, delay_samples=self.delay if delay is None else delay,
                           seeds=seeds, gains=G, threads=self.threads, simd=self.simd, predict=self.predict,
                           x0=self.x0)
        return run_cost(b).reshape(len(cands), P.shape[0]), b


def evaluate_gains(prob: _Problem, gains: dict, P, duration: float, seed: int, delay=None):
    """``(worst cost, BatchResult)`` of one set of gains over the rows ``P``."""
    cost, b = prob.batch([gains], P, duration, seed, delay)
    return float(np.max(cost)), b


#: The per-joint gains of the pattern search.
PER_JOINT = ("k_lin", "k_s", "delta")
#: Floor of ``k_lin_j / lam``: the sliding variable's own pole no slower than 1.25 x the surface's.
#: Without it the search (2 s screening runs) drove one Panda joint's k_lin to 6 (1/s), and 7 of 200
#: final 10 s runs diverged after 2 s (slow limit cycles through the delay and the boundary layer);
#: on those draws plus the screening ones (22 runs, 10 s), floors of 25 / 50 / 100 left 8 / 1 / 0 diverged.
LIN_FLOOR = 1.25


def _grid(lams, kss, n: int):
    """The grid stage's candidates: the same gains on every joint (per-joint lists of length ``n``)."""
    return [{"lam": float(lam), "k_lin": [LIN_RATIO * float(lam)] * n, "k_s": [float(ks)] * n,
             "delta": [float(ks) / 200.0] * n} for lam in lams for ks in kss]


def move_gain(gains: dict, coord, factor: float) -> dict:
    """``gains`` with one coordinate (``"lam"`` or ``(name, joint)``) multiplied by ``factor``."""
    out = {k: (list(v) if isinstance(v, list) else v) for k, v in gains.items()}
    if coord == "lam":
        out["lam"] = gains["lam"] * factor
    else:
        out[coord[0]][coord[1]] = gains[coord[0]][coord[1]] * factor
    out["k_lin"] = [max(v, LIN_FLOOR * out["lam"]) for v in out["k_lin"]]
    return out


def combine_moves(gains: dict, moves) -> dict:
    """``gains`` with every ``(coord, factor)`` of ``moves`` applied (distinct coordinates)."""
    for coord, factor in moves:
        gains = move_gain(gains, coord, factor)
    return gains


def _refine(prob, best, best_cost, P, duration, seed, rounds, say, f: float = 2.0):
    """Pattern search over ``lam`` and the per-joint gains (module docstring), first factor ``f``."""
    n = len(best["k_lin"])
    coords = ["lam"] + [(key, j) for key in PER_JOINT for j in range(n)]
    for rnd in range(rounds):
        moves = [(c, s) for c in coords for s in (f, 1.0 / f)]
        cands = [move_gain(best, c, s) for c, s in moves]
        cost = np.max(prob.batch(cands, P, duration, seed)[0], axis=1)
        better = {}
        for (c, s), v in zip(moves, cost):       # the better direction of each improving coordinate
            if v < best_cost and (c not in better or v < better[c][1]):
                better[c] = (s, v)
        if len(better) > 1:
            cands.append(combine_moves(best, [(c, s) for c, (s, _v) in better.items()]))
            cost = np.append(cost, np.max(prob.batch(cands[-1:], P, duration, seed)[0], axis=1))
        j = int(np.argmin(cost))
        say(f"refine round {rnd + 1}/{rounds} (factor {f:.3g}, {len(cands)} candidates, {len(better)} "
            f"improving moves): best {cost[j]:.4g} vs {best_cost:.4g}")
        if cost[j] < best_cost:
            best, best_cost = cands[j], float(cost[j])
        else:
            f = math.sqrt(f)
    return best, best_cost


#: Draws of the final check added to the screening set per active-set pass, and the screening
#: duration of that pass (x ``screen_duration``): a draw that fails only after 2 s (measured on the
#: Panda: K1, K2 soft with K3 stiff, torque jitter and the limit from 3 s on) needs a longer run.
ACTIVE_ADD, ACTIVE_DURATION, ACTIVE_ROUNDS = 4, 2.0, 2


def _active_set(prob, best, best_cost, worst, b, P, screen_draws, duration, active_duration, seed, passes, say):
    """Refine again on the screening draws plus the final check's worst ones; ``(best, worst, batch)``.

    Each pass adds up to :data:`ACTIVE_ADD` draws of the final check that cost more than the
    screening objective, runs :data:`ACTIVE_ROUNDS` rounds of the pattern search on them at
    ``active_duration`` (from factor sqrt(2)) and repeats the final check.
    """
    rows = np.arange(screen_draws)
    for k in range(passes):
        run = run_cost(b)
        add = [int(i) for i in np.argsort(run)[::-1][:ACTIVE_ADD] if run[i] > best_cost and i not in rows]
        if not add:
            break
        rows = np.r_[rows, add]
        best_cost = evaluate_gains(prob, best, P[rows], active_duration, seed + rows)[0]
        say(f"active set {k + 1}/{passes}: + draws {add} (final-check costs "
            f"{', '.join(f'{run[i]:.3g}' for i in add)}); {len(rows)} draws x {active_duration:g} s: {best_cost:.4g}")
        best, best_cost = _refine(prob, best, best_cost, P[rows], active_duration, seed + rows, ACTIVE_ROUNDS, say,
                                  f=math.sqrt(2.0))
        worst, b = evaluate_gains(prob, best, P, duration, seed)
        say(f"final check again: worst {worst:.4g}")
    return best, worst, b


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
           u_max=None, screen_draws: int = 12, screen_duration: float = 2.0, rounds: int = 6,
           max_extra_delay: int = 3, threads: Optional[int] = None, simd: bool = True,
           progress: Optional[Callable[[str], None]] = None, predict: bool = False, reference=None,
           x0=None, task: Optional[dict] = None, active_sets: int = 1) -> dict:
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
    cands = _grid(np.geomspace(20.0, 160.0, 4), np.geomspace(200.0, 20000.0, 5), int(model.n))
    cost = np.max(prob.batch(cands, P_screen, screen_duration, seed)[0], axis=1)
    j = int(np.argmin(cost))
    say(f"grid {len(cands)} candidates x {screen_draws} draws x {screen_duration:g} s: best {cost[j]:.4g} at "
        f"{cands[j]}")
    best, best_cost = _refine(prob, cands[j], float(cost[j]), P_screen, screen_duration, seed, rounds, say)
    say(f"final: {draws} draws x {duration:g} s with {best}")
    worst, b = evaluate_gains(prob, best, P_all[:draws], duration, seed)
    best, worst, b = _active_set(prob, best, best_cost, worst, b, P_all[:draws], screen_draws, duration,
                                 min(duration, ACTIVE_DURATION * screen_duration), seed, active_sets, say)
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
