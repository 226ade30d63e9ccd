"""The linear sampled-data analysis as the screen of ``fjm design`` (:mod:`fjm_runtime.analysis.search.screen`).

:class:`LinearScreen` analyses each candidate with
:class:`~fjm_runtime.analysis.sampled.sampled_analysis.LinearAnalyzer` on the nominal plant and the nine
corners of the design's parameter box, at rest and at task points, without margins (cheap: the
jacobian Functions are built once, the gains ride as inputs). A candidate passes when

* every plant at every point is stable with a margin: spectral radius ``rho <= exp(-MIN_DECAY T)``
  (the slowest mode decays at least at ``MIN_DECAY`` 1/s; a radius itself close to 1 is normal at
  1 kHz: a 20 1/s pole is ``exp(-0.02) = 0.980``);
* the predicted torque jitter of every jitter joint is at most ``JITTER_SLACK x`` the limit (the
  linear prediction is trusted to 25 % against Monte Carlo, so a candidate within that band is left
  to the Monte Carlo stages rather than rejected).

:meth:`LinearScreen.explain` names what limits a set of gains: an instability (plant, point, the
joint of the unstable mode) or the joint whose predicted jitter is worst relative to the limit and
the noise channel that dominates it.
"""
from __future__ import annotations

import math
from typing import List, Optional

import numpy as np

from .screen import Screen, Verdict

__all__ = ["JITTER_SLACK", "MIN_DECAY", "LinearScreen", "linear_screen"]

#: Slowest decay rate allowed of the sampled loop's modes, 1/s.
MIN_DECAY = 1.0
#: Predicted jitter up to this factor of the limit passes the screen (Monte Carlo decides).
JITTER_SLACK = 1.25
#: Task points of the screen, s (besides rest): fewer than ``fjm analyze``'s, for speed.
TASK_TIMES = (1.0,)


class LinearScreen:
    """A :class:`~fjm_runtime.analysis.search.screen.Screen` from the linear analysis.

    Parameters
    ----------
    loops : DesignLoops
    spread : PlantSpread
    margin : float, optional
        Overrides :data:`MIN_DECAY` as ``rho <= 1 - margin`` when given as a radius margin > 0.
    """

    name = "linear sampled-data analysis"

    def __init__(self, loops, spread, margin: Optional[float] = None):
        from ..sampled.sampled_analysis import LinearAnalyzer, default_plants
        from ..sampled.sampled_linear import Conditions
        self.loops = loops
        self.analyzer = LinearAnalyzer(Conditions.from_loops(loops), plants=default_plants(loops.model, spread),
                                       task_times=TASK_TIMES)
        self.rho_max = math.exp(-MIN_DECAY * float(loops.dt)) if not margin else 1.0 - float(margin)
        self.jitter_joints = loops.thresholds.joints(int(loops.model.n))
        self.max_jitter = float(loops.thresholds.max_jitter)
        self.seconds = 0.0
        self.checked = 0

    def _analyze(self, gains: dict, attribution: bool = False) -> dict:
        import time
        t0 = time.perf_counter()
        g = {k: v for k, v in gains.items() if k != "u_max"}
        try:
            return self.analyzer.analyze(g, margins=False, attribution=attribution)
        finally:
            self.seconds += time.perf_counter() - t0
            self.checked += 1

    def verdict(self, gains: dict) -> Verdict:
        """One candidate's verdict (``predicted``: rho, the jitter per joint)."""
        res = self._analyze(gains)
        s = res["summary"]
        rho = s["rho"]
        jit = s["torque_jitter"]
        predicted = {"rho": rho, "torque_jitter": jit}
        if not s["stable_everywhere"] or rho is None or rho > self.rho_max:
            return Verdict(False, f"spectral radius {rho if rho is not None else 'inf'} > {self.rho_max:.6g}",
                           predicted)
        worst = [(jit[j] / self.max_jitter, j) for j in self.jitter_joints if jit[j] is not None]
        if worst and max(worst)[0] > JITTER_SLACK:
            r, j = max(worst)
            return Verdict(False, f"predicted jitter {jit[j]:.3g} N m on joint {j + 1} > {JITTER_SLACK:g} x "
                                  f"{self.max_jitter:g} N m", predicted)
        return Verdict(True, "", predicted)

    def check(self, cands: List[dict]) -> List[Verdict]:
        """A verdict per candidate (module docstring)."""
        return [self.verdict(g) for g in cands]

    def explain(self, gains: dict) -> Optional[str]:
        """What the analysis says limits ``gains``: an unstable mode, or the worst predicted jitter's noise."""
        res = self._analyze(gains, attribution=True)
        for row in res["plants"]:
            for point, fig in row["points"].items():
                if not fig.get("stable", False) or fig["rho"] > self.rho_max:
                    j = fig.get("dominant_joint")
                    return (f"linear analysis: spectral radius {fig['rho']:.4g} on the {row['plant']} plant at "
                            f"{point}" + (f", mode on joint {j}" if j else "") + f" (allowed {self.rho_max:.6g})")
        best = None
        for row in res["plants"]:
            for point, fig in row["points"].items():
                for j in self.jitter_joints:
                    v = fig["torque_jitter"][j]
                    if best is None or v > best[0]:
                        best = (v, j, row["plant"], point, fig.get("dominant_noise", [None] * (j + 1))[j],
                                fig.get("noise_share", {}).get(str(j + 1), {}))
        if best is None:
            return None
        v, j, plant, point, channel, share = best
        frac = share.get(channel) if channel else None
        return (f"linear analysis: predicted jitter {v:.3g} N m on joint {j + 1} (limit {self.max_jitter:g}; "
                f"{plant} plant, {point}), limited by {channel} noise"
                + (f" ({100 * frac:.0f} % of its variance)" if frac is not None else ""))


def linear_screen(loops, spread, margin: Optional[float] = None) -> Screen:
    """The linear analysis (:mod:`fjm_runtime.analysis.sampled.sampled_linear`) as a screen.

    Parameters
    ----------
    loops : DesignLoops
        Model, law, rate, delay, sensor, prediction, reference and thresholds of the design.
    spread : PlantSpread
        The corners of its box are analysed.
    margin : float, optional
        Required distance of the spectral radius below 1 (default: the decay-rate margin of
        :data:`MIN_DECAY`).
    """
    return LinearScreen(loops, spread, margin)
