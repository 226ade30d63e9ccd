"""Gains for a sampling rate, found by running the batch engine over many sampled closed loops.

:func:`design` searches one law's gains for a model, control rate, computation delay and sensor model,
in the law's gain space (:mod:`fjm_runtime.analysis.search.gain_spaces`: its gains, ranges and starting
grid). For the integral sliding-mode law: the surface pole ``lam`` (the quadruple pole of the integral
surface, shared by the joints because the emitted law has one set of surface coefficients) and, PER
JOINT, ``k_lin``, ``k_s`` and ``delta``; for the motor-side impedance: ``K_p``, ``K_d``, ``K_T``, ``K_i``
per joint. Every candidate is simulated (:class:`~fjm_runtime.analysis.search.runs.DesignLoops`:
one compiled library for all candidates, the gains ride per run; SIMD by default; here or on a
dask cluster, bit for bit the same) on draws of the TRUE plant
(:mod:`fjm_runtime.analysis.search.draws`): by default

* ``K x U[0.7, 1.3]`` per joint, ``J_m x U[0.8, 1.2]`` per joint, payload ``U[0, 1]`` kg (models with
  ``m_load``), a sensor-noise seed per draw;
* first the corners: ``K`` all 0.7, all 1.3, alternating 0.7/1.3 (nominal ``J_m``, no payload), then
  the same three with ``J_m x 0.8`` and ``x 1.2`` and a 1 kg payload;

a parameter file (``--params``) sets the controller's nominal values and this spread.

Thresholds (:class:`~fjm_runtime.analysis.search.thresholds.Thresholds`): each joint's second-half
RMS error, the torque jitter on the jitter joints (1-4 by default), the time at a torque limit.
Cost of a run: the worst joint's RMS error (rad) plus ``PENALTY`` times the excesses over the
thresholds, each relative to its limit, summed over joints; a diverged run costs
:data:`DIVERGED_COST`. The objective of a candidate is the worst cost over the draws.

Search (deterministic by seed): the law's starting grid (ismc: a log grid on ``lam`` x ``k_s`` x the
layer's slope ``k_s / delta``, the same on every joint) on a screening set of draws and a short run, then a
pattern search: each round tries every coordinate (ismc: ``lam``, and ``k_lin_j``, ``k_s_j``, ``delta_j``
of every joint) times and divided by a factor ``f``, plus the candidate that takes every improving
move at once (the joints are weakly coupled, so their moves mostly add); the best of these replaces
the incumbent if it is better, otherwise ``f`` shrinks to ``sqrt(f)``. ``k_lin_j`` is kept at or above
:data:`~fjm_runtime.analysis.search.gain_spaces.LIN_FLOOR` ``lam`` (measured reason at the constant). Per-joint gains matter on an
arm: the proximal joints (large ``D``, stiff) turn encoder noise into torque jitter through
``beta^-1 = J_m K^-1 D`` and want a small ``k_lin``, the wrist (small ``D``) wants a large one. A
screen (:mod:`fjm_runtime.analysis.search.screen`; the linear sampled-data analysis when installed)
rejects candidates before they are simulated. Then the best gains run on all draws at the full
duration; then an active-set pass: the final check's worst draws join the screening set, the
search runs two more rounds on it with runs twice as long, and the final check is repeated.

Verdict: every (threshold, joint) that some draw of the final check misses is recorded
(``misses``); gains that meet every threshold are re-checked on FRESH plants and noise seeds
(:data:`RECHECK_SEED_OFFSET`, ``draw_params(fresh=True)``) that no stage of the search used, and
``meets`` is true only if both pass; a failed design names its binding miss and what limits it (the
screen's explanation, else :mod:`fjm_runtime.analysis.search.attribution`). Margins: the largest
tolerated delay (the best gains re-run at ``d + 1, d + 2, ...`` on the screening draws until one
fails) and the input-gain range (every stiffness scaled by one factor ``g``, widening from the box
until a draw fails).
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import replace
from typing import Callable, Optional

import numpy as np

from ..sampled.sampled_linear import scaled_stiffness
from ...sim.sensor import SensorModel
from ...validation import FjmValueError
from .draws import PlantSpread, default_spread, draw_params
from .gain_spaces import GainSpace, combine_moves, gain_space
from .runs import DesignLoops
from .screen import SCREENED_COST, screen_costs
from .settings import SearchSettings
from .thresholds import PENALTY, Thresholds, describe_miss, find_misses, run_cost

__all__ = ["RECHECK_SEED_OFFSET", "design", "evaluate_gains"]

#: Today's default thresholds (kept for importers; :class:`Thresholds` holds the limits).
MAX_TIME_AT_LIMIT = Thresholds().max_at_limit
MAX_JITTER = Thresholds().max_jitter
#: Noise seeds of the re-check: ``seed + RECHECK_SEED_OFFSET + i`` (the search uses ``seed + draw``).
RECHECK_SEED_OFFSET = 1 << 40


def default_efforts(model):
    """Torque limits of a design, N m: the model's effort limits (``model.limits.effort``: its model file's
    ``[limits]`` over the URDF's ``<limit effort>``) when every joint states a finite one > 0, else None
    (no limit)."""
    lim = model.limits.effort
    if np.all(np.isfinite(lim)) and np.all(lim > 0):
        return tuple(float(v) for v in lim)
    return None


def evaluate_gains(prob: DesignLoops, gains: dict, P, duration: float, seed, delay=None):
    """``(worst cost, BatchResult)`` of one set of gains over the rows ``P``."""
    cost, b = prob.batch([gains], P, duration, seed, delay)
    return float(np.max(cost)), b


class _Search:
    """The screened objective of the search: worst cost over rows, candidates the screen rejects skipped."""

    def __init__(self, prob: DesignLoops, screen, space: GainSpace):
        self.prob, self.screen, self.space = prob, screen, space
        self.screened = 0
        self.simulated = 0

    def objective(self, cands, P, duration, seed) -> np.ndarray:
        """Worst cost over the rows per candidate, shape (len(cands),); rejected ones :data:`SCREENED_COST`."""
        keep, _verdicts = screen_costs(self.screen, cands)
        out = np.full(len(cands), SCREENED_COST)
        self.screened += len(cands) - len(keep)
        if keep:
            self.simulated += len(keep)
            out[keep] = np.max(self.prob.batch([cands[i] for i in keep], P, duration, seed)[0], axis=1)
        return out


def _refine(search: _Search, best, best_cost, P, duration, seed, rounds, say, f: float = 2.0):
    """Pattern search over the law's scalar and per-joint gains (module docstring), first factor ``f``."""
    space = search.space
    coords = space.coords(int(search.prob.model.n))
    for rnd in range(rounds):
        moves = [(c, s) for c in coords for s in (f, 1.0 / f)]
        cands = [space.move(best, c, s) for c, s in moves]
        cost = search.objective(cands, P, duration, seed)
        better = {}
        for (c, s), v in zip(moves, cost):       # the better direction of each improving coordinate
            if v < best_cost and (c not in better or v < better[c][1]):
                better[c] = (s, v)
        if len(better) > 1:
            cands.append(combine_moves(best, [(c, s) for c, (s, _v) in better.items()], space))
            cost = np.append(cost, search.objective(cands[-1:], P, duration, seed))
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
#: Pattern-search rounds of a law only compared with one that already met (``compare_only``): its row
#: shows where the law stands, not its best; measured on the UR5e (franka_like): ismc and fl after three
#: rounds still 94-97 % of the time at a torque limit, and they took 3.5 of the design's 10.3 minutes.
COMPARED_ROUNDS = 1
#: The active set's runs last at least this factor times the latest divergence time of the draws it
#: adds (capped at the final duration): Panda designs with franka_like diverged on one corner at
#: 6.2-6.5 s in the final check, which the 4 s active-set runs never reached.
LATE_MARGIN = 1.25


def _active_set(search, best, best_cost, worst, b, P, screen_draws, duration, active_duration, seed, passes, say):
    """Refine again on the screening draws plus the final check's worst ones; ``(best, worst, batch)``.

    Each pass adds up to :data:`ACTIVE_ADD` draws of the final check that cost more than the
    screening objective, runs :data:`ACTIVE_ROUNDS` rounds of the pattern search on them at
    ``active_duration`` (from factor sqrt(2); lengthened to :data:`LATE_MARGIN` x the latest
    divergence time in the final check of its draws, screening ones included: a pass runs even when
    no draw is added if that lengthens the runs) and repeats the final check, keeping the refined gains
    only when its worst cost is not higher than before the pass.
    """
    prob = search.prob
    rows = np.arange(screen_draws)
    for k in range(passes):
        run = run_cost(b, prob.thresholds)
        add = [int(i) for i in np.argsort(run)[::-1][:ACTIVE_ADD] if run[i] > best_cost and i not in rows]
        rows = np.r_[rows, add].astype(int)
        # a run that diverged late must be run past that time, or the refinement cannot see it (also when
        # the draw is a screening one: its short screening runs ended before it failed)
        late = [float(b.divergence_time[i]) for i in rows if b.diverged[i] and np.isfinite(b.divergence_time[i])]
        longer = min(duration, max(active_duration, LATE_MARGIN * max(late))) if late else active_duration
        if not add and longer <= active_duration:
            break
        active_duration = longer
        best_cost = evaluate_gains(prob, best, P[rows], active_duration, seed + rows)[0]
        say(f"active set {k + 1}/{passes}: + draws {add} (final-check costs "
            f"{', '.join(f'{run[i]:.3g}' for i in add)}); {len(rows)} draws x {active_duration:g} s: {best_cost:.4g}")
        cand, best_cost = _refine(search, best, best_cost, P[rows], active_duration, seed + rows, ACTIVE_ROUNDS, say,
                                  f=math.sqrt(2.0))
        cand_worst, cand_b = evaluate_gains(prob, cand, P, duration, seed)
        # refined on a few draws, the gains may lose on the others (a Panda impedance design at 500 Hz: 1.4e-4 ->
        # 0.17 on the final check); the pass keeps them only when the final check does not get worse
        kept = cand_worst <= worst
        if kept:
            best, worst, b = cand, cand_worst, cand_b
        say(f"final check again: worst {cand_worst:.4g}{'' if kept else f' (worse: the gains before the pass kept, {worst:.4g})'}")
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
    p0 = np.asarray(prob.model.params_array(prob.nominal), dtype=float)
    lows, highs = [0.7, 0.6, 0.5, 0.4, 0.3, 0.2], [1.3, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0]
    rows = [scaled_stiffness(prob.model, p0, g) for g in lows + highs]  # every spring torque x g
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


def _recheck(prob, gains, spread, count, duration, seed, say):
    """The gains on ``count`` fresh plants and noise seeds: ``(record, misses)``."""
    P = draw_params(prob.model, count, seed, spread, fresh=True)
    seeds = seed + RECHECK_SEED_OFFSET + np.arange(count)
    worst, b = evaluate_gains(prob, gains, P, duration, seeds)
    misses = find_misses(b, prob.thresholds, range(count), "recheck")
    say(f"re-check on {count} fresh draws x {duration:g} s: worst cost {worst:.4g}, "
        f"{'meets every threshold' if not misses else f'{len(misses)} miss(es)'}")
    from .report import worst_case
    return {"draws": int(count), "duration": float(duration), "meets": not misses,
            "plants": f"fresh stream SeedSequence([{int(seed)}, 0x5EED]) (no corners)",
            "noise_seeds": [int(seeds[0]), int(seeds[-1])], "worst_case": worst_case(b, worst)}, misses


def _attribution(prob, gains, miss, P_all, spread, recheck, duration, seed, say):
    """``(limited_by, figures)`` of the binding miss by Monte Carlo (:mod:`.design_attribution`)."""
    from .attribution import attribute
    if miss["stage"] == "recheck":
        row = draw_params(prob.model, recheck["draws"], seed, spread, fresh=True)[miss["draw"]]
    else:
        row = P_all[miss["draw"]]
    sentence, figures = attribute(prob, gains, row, miss["seed"], duration, miss)
    if sentence:
        say(f"binding draw re-run without each noise source: {sentence}")
    return sentence, {k: (None if not np.isfinite(v) else float(v)) for k, v in figures.items()}


def _search(search, model, P_all, draws, screen_draws, screen_duration, duration, rounds, active_sets, seed, say):
    """Grid, pattern search, final check and active set: ``(best, worst, batch)``."""
    P_screen = P_all[:screen_draws]
    cands = search.space.grid(model, np.asarray(model.params_array(search.prob.nominal), dtype=float))
    cost = search.objective(cands, P_screen, screen_duration, seed)
    if np.all(cost >= SCREENED_COST) and search.screen is not None:
        say("grid: the screen rejected every candidate; simulating them all")
        screen, search.screen = search.screen, None
        cost = search.objective(cands, P_screen, screen_duration, seed)
        search.screen = screen
    j = int(np.argmin(cost))
    say(f"grid {len(cands)} candidates x {screen_draws} draws x {screen_duration:g} s: best {cost[j]:.4g} at "
        f"{cands[j]}")
    best, best_cost = _refine(search, cands[j], float(cost[j]), P_screen, screen_duration, seed, rounds, say)
    say(f"final: {draws} draws x {duration:g} s with {best}")
    worst, b = evaluate_gains(search.prob, best, P_all[:draws], duration, seed)
    return _active_set(search, best, best_cost, worst, b, P_all[:draws], screen_draws, duration,
                       min(duration, ACTIVE_DURATION * screen_duration), seed, active_sets, say)


def design(model, settings: Optional[SearchSettings] = None, *,
           progress: Optional[Callable[[str], None]] = None) -> dict:
    """Search the gains (module docstring); returns the gains-file dict (``fjm simulate --gains``).

    Parameters
    ----------
    model : Model
    settings : SearchSettings, optional
        What to search and how (default ``SearchSettings()``: ismc, torque sensing, 1 kHz, one sample
        of delay, 200 draws of 10 s, seed 0).
    progress : callable, optional
        Receives one line per stage (default: stderr).

    Returns
    -------
    dict
        ``model, kind, sensing, rate, delay, sensor, reference, predict, gains (lam, k_lin, k_s,
        delta, u_max), meets, misses, binding (the worst miss), limited_by, thresholds, recheck,
        worst_case`` (worst over all draws: cost, diverged count, per joint rms_second_half,
        time_at_limit, torque_jitter, peak_torque, time_at_rate_limit), ``margins`` (delay,
        input_gain_range), ``params, screen, scheduler, evaluations, draws, seed, duration, fjm_version``.
    """
    s = SearchSettings() if settings is None else settings
    space = gain_space(s.kind)
    if space.sensing is not None:
        s = replace(s, sensing=space.sensing)   # the law reads its own measurement
    if s.draws < 1 or s.duration <= 0 or s.rate <= 0 or s.delay < 0 or s.screen_draws < 1 or s.screen_duration <= 0:
        raise FjmValueError(f"design: draws = {s.draws}, duration = {s.duration}, rate = {s.rate}, delay = {s.delay}, "
                            f"screen_draws = {s.screen_draws}, screen_duration = {s.screen_duration}: expected "
                            "draws >= 1, durations > 0 s, rate > 0 Hz, delay >= 0, screen_draws >= 1")
    recheck_draws = s.draws if s.recheck_draws is None else int(s.recheck_draws)
    if recheck_draws < 0:
        raise FjmValueError(f"design: recheck_draws = {recheck_draws}: expected >= 0 (0: no re-check)")
    say = progress or (lambda msg: print(f"fjm design: {msg}", file=sys.stderr, flush=True))
    thresholds = s.thresholds or Thresholds()
    thresholds.joints(int(model.n))                      # validates the jitter joints for this model
    s = replace(s, recheck_draws=recheck_draws, thresholds=thresholds,
                sensor=SensorModel.panda_white(seed=s.seed) if s.sensor is None else s.sensor,
                spread=default_spread(model) if s.spread is None else s.spread,
                u_max=default_efforts(model) if s.u_max is None else s.u_max)
    if s.scheduler is None:
        return _design(model, s, say, None)
    from ...batch.distributed import client_for
    with client_for(s.scheduler) as client:
        say(f"Monte Carlo stages on the dask cluster at {client.scheduler.address}")
        return _design(model, s, say, client)


def _design(model, s: SearchSettings, say, client) -> dict:
    """The search with every default resolved (``s``), its Monte Carlo stages on ``client`` (None: here)."""
    from .report import binding_miss, report
    from .screen_linear import linear_screen
    t0 = time.perf_counter()
    spread, thresholds, screen, seed = s.spread, s.thresholds, s.screen, s.seed
    prob = DesignLoops(model, s.kind, s.sensing, s.rate, s.delay, s.sensor, s.u_max, s.threads, s.simd, s.predict,
                       s.reference, s.x0, s.task, nominal=spread.nominal, thresholds=thresholds, client=client,
                       interface=s.interface)
    if isinstance(screen, str):
        if screen != "linear":
            raise FjmValueError(f"design: screen = {screen!r}: expected None, 'linear' or a Screen object")
        screen = linear_screen(prob, spread)
        if screen is None:
            raise FjmValueError("design: screen = 'linear': fjm_runtime.analysis.sampled.sampled_linear is not installed")
    search = _Search(prob, screen, gain_space(s.kind))
    draws, duration, screen_draws, screen_duration = s.draws, s.duration, s.screen_draws, s.screen_duration
    P_all = draw_params(model, max(draws, screen_draws), seed, spread)
    rounds, active_sets = (min(s.rounds, COMPARED_ROUNDS), 0) if s.compare_only else (s.rounds, s.active_sets)
    best, worst, b = _search(search, model, P_all, draws, screen_draws, screen_duration, duration, rounds,
                             active_sets, seed, say)
    seconds = {"search": time.perf_counter() - t0}
    misses = find_misses(b, thresholds, range(draws), "final")
    recheck = {"draws": 0, "skipped": "the final check missed a threshold" if misses else "recheck_draws = 0"}
    if not misses and s.recheck_draws > 0:
        t1 = time.perf_counter()
        recheck, misses = _recheck(prob, best, spread, s.recheck_draws, duration, seed, say)
        seconds["recheck"] = time.perf_counter() - t1
    compared_only = s.compare_only and bool(misses)  # a row of the comparison, not a record anyone keeps
    margins = {"delay": None, "input_gain_range": None}
    if not compared_only:
        t1 = time.perf_counter()
        margins = {"delay": _delay_margin(prob, best, P_all[:screen_draws], screen_duration, seed,
                                          s.max_extra_delay, say),
                   "input_gain_range": _gain_range(prob, best, screen_duration, seed, say)}
        seconds["margins"] = time.perf_counter() - t1
    for m in misses:
        m["message"] = describe_miss(m)
        say(f"MISSES: {m['message']}")
    limited_by = screen.explain(best) if (misses and screen is not None and hasattr(screen, "explain")) else None
    binding, attribution = binding_miss(misses), {}
    if binding is not None and limited_by is None and not compared_only:
        limited_by, attribution = _attribution(prob, best, binding, P_all, spread, recheck, duration, seed, say)
    out = report(model, prob, best, worst, b, margins, draws, seed, duration)
    out.update({"compare_only": bool(s.compare_only), "rounds": int(rounds),
                "meets": not misses, "misses": misses, "binding": binding, "limited_by": limited_by,
                "attribution": attribution,
                "thresholds": thresholds.as_dict(int(model.n)), "recheck": recheck, "params": spread.as_dict(),
                "screen": {"name": getattr(screen, "name", None), "rejected": search.screened,
                           "simulated": search.simulated},
                "scheduler": "local" if client is None else str(client.scheduler.address),
                "evaluations": {"batches": prob.batches, "runs": prob.runs,
                                "seconds": {k: round(v, 3) for k, v in seconds.items()}}})
    return out
