"""The linear analysis of one law over plants, operating points, delays and stiffness scales.

:class:`LinearAnalyzer` holds the conditions (:class:`~fjm_runtime.analysis.sampled.sampled_linear.Conditions`)
and the plants (nominal plus the corners of the parameter box, :func:`default_plants`); its
:meth:`~LinearAnalyzer.analyze` takes a gains dict and returns a plain dict (JSON-able). The CasADi
jacobian Functions are cached per layout (:func:`~fjm_runtime.analysis.sampled.sampled_linear.linear_step`),
with the gains as an input, so screening many candidates builds nothing after the first.
"""
from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from typing import Optional, Sequence

import numpy as np

from ...sim.rest import rest_state
from ...sim.substeps import resolve_substeps
from .sampled_linear import (Conditions, assess, channel_names, finite, linear_step, noise_levels, respring,
                             scaled_stiffness, spectral)

__all__ = ["LinearAnalyzer", "default_plants", "MAX_EXTRA_DELAY"]

#: Delays tried by the delay margin: ``d + 1 .. d + MAX_EXTRA_DELAY``.
MAX_EXTRA_DELAY = 4
#: Stiffness factors bracketing the scale range, and the bisection steps (ratio 2 -> 2^(1/64)).
SCALE_BRACKET, SCALE_BISECTIONS = (2.0, 4.0, 8.0, 16.0), 6


def default_plants(model, spread=None):
    """``[(name, p)]``: the nominal plant, then the nine corners of ``draw_params`` (the design's box)."""
    from ..search.draws import default_spread, draw_params
    spread = default_spread(model) if spread is None else spread
    p0 = np.asarray(model.params_array(spread.nominal), dtype=float)
    rows = draw_params(model, 9, 0, spread)
    labels = ("K low", "K high", "K alternating")
    ends = ("", ", other spreads low", ", other spreads high")
    return [("nominal", p0)] + [(f"corner {i + 1}: {labels[i % 3]}{ends[i // 3]}", rows[i]) for i in range(9)]


class LinearAnalyzer:
    """The linear analysis of laws of one kind under :class:`Conditions`.

    Parameters
    ----------
    cond : Conditions
    plants : list of (str, ndarray), optional
        TRUE plants (default :func:`default_plants`); the first is the nominal one.
    task_times : sequence of float
        Frozen-time points along the task, s (besides ``rest``).
    catch_up : float
        Seconds of noise-free loop that settle a task point on another plant or delay.
    substeps : int, optional
        RK4 substeps (default: the largest of the rule over the plants).
    """

    def __init__(self, cond: Conditions, plants=None, task_times: Sequence[float] = (0.5, 1.0, 2.0),
                 catch_up: float = 0.05, substeps: Optional[int] = None):
        from ...batch.sampled import jitter_half_width
        self.cond, m = cond, cond.model
        self.model, self.n, self.T = m, int(m.n), float(cond.dt)
        self.plants = default_plants(m) if plants is None else [(str(a), np.asarray(b, dtype=float))
                                                                 for a, b in plants]
        self.p_nom = np.asarray(m.params_array(cond.nominal), dtype=float)
        self.substeps = int(substeps) if substeps else max(
            resolve_substeps(None, m, cond.x0, p, self.T) for _, p in self.plants)
        self.sensor = cond.linear_sensor()
        self.levels = noise_levels(cond.sensor, cond.sensing, self.n)
        self.names = channel_names(cond.sensor, cond.sensing, self.n)
        self.h = jitter_half_width(self.T)
        self.task_k = sorted({int(round(t / self.T)) for t in task_times if t > 0})
        self.catch = max(1, int(round(catch_up / self.T)))
        q0 = np.asarray(cond.reference(0.0), dtype=float)[0]
        self.q0, self.r_rest = q0, np.concatenate([q0, np.zeros(4 * self.n)])
        self._R = None
        self._chords: dict = {}      # delay -> the nominal plant's rest linearization (this candidate's)
        self._sigma0 = None          # the std of s at the nominal plant's rest (this candidate's)

    # -- operating points --------------------------------------------------------------------------
    def points(self):
        """Names of the operating points: ``rest`` and ``t=<s>`` per task point."""
        return ["rest"] + [f"t={k * self.T:g}s" for k in self.task_k]

    def _step(self, ctrl, delay):
        c = self.cond
        return linear_step(self.model, ctrl, self.T, self.substeps, self.sensor, delay, c.predict, c.interface)

    def _rows(self):
        if self._R is None and self.task_k:
            t = self.T * np.arange(self.task_k[-1] + 1)
            self._R = np.asarray(self.cond.reference.sample(t), dtype=float).reshape(t.size, 5 * self.n)
        return self._R

    def _nominal_run(self, ctrl, g):
        """``{k: w_k}`` of the noise-free run on the nominal plant at the design's delay (each task
        point and the start of its catch-up)."""
        if not self.task_k:
            return {}
        S = self._step(ctrl, self.cond.delay)
        w0 = S.core_state(self.cond.x0, np.zeros(S.n_law), self.p_nom, self.sensor)
        R = self._rows()
        W = np.vstack([w0[None], S.run(w0, R[:-1], self.p_nom, g)])
        return {k: W[k] for j in self.task_k for k in (j, max(0, j - self.catch))}

    def operating_point(self, ctrl, g, point: int, p, delay, run):
        """``(S, w, r)``: the step and the point (``point`` 0: rest, else the task point's index + 1)."""
        S = self._step(ctrl, delay)
        if point == 0:
            x = rest_state(self.model, self.q0, p)
            chord = self._chords.get(delay)
            w, _ok = S.equilibrium(S.core_state(x, np.zeros(S.n_law), p, self.sensor), self.r_rest, p, g, chord)
            return S, w, self.r_rest
        k = self.task_k[point - 1]
        R = self._rows()
        if delay == self.cond.delay and np.array_equal(p, self.p_nom):
            return S, run[k], R[k]
        k0 = max(0, k - self.catch)
        S0 = self._step(ctrl, self.cond.delay)
        w_from = run[k0] if k0 in run else self._nominal_w(ctrl, g, k0)
        x = respring(self.model, w_from[:self.model.nx], self.p_nom, p)
        w = S.core_state(x, S0.z_law(w_from), p, self.sensor)
        W = S.run(w, R[k0:k], p, g)
        return S, (W[-1] if W.shape[0] else w), R[k]

    def _nominal_w(self, ctrl, g, k):
        S = self._step(ctrl, self.cond.delay)
        w0 = S.core_state(self.cond.x0, np.zeros(S.n_law), self.p_nom, self.sensor)
        return w0 if k == 0 else S.run(w0, self._rows()[:k], self.p_nom, g)[-1]

    def rho(self, ctrl, g, point, p, delay, run) -> float:
        S, w, r = self.operating_point(ctrl, g, point, p, delay, run)
        if not np.all(np.isfinite(w)):
            return float("inf")
        lin = S.linearize(w, r, p, g)
        if point == 0:
            self._chords.setdefault(delay, lin)
        return float(np.max(np.abs(np.linalg.eigvals(lin.A))))     # the radius only: no eigenvectors

    # -- margins -----------------------------------------------------------------------------------
    def delay_margin(self, ctrl, g, point, p, run):
        """First delay ``d' > d`` (up to ``d + MAX_EXTRA_DELAY``) with spectral radius >= 1, or None
        (:meth:`analyze` records ``d`` itself when the loop is unstable at ``d``)."""
        d = self.cond.delay
        for dd in range(d + 1, d + 1 + MAX_EXTRA_DELAY):
            if self.rho(ctrl, g, point, p, dd, run) >= 1.0:
                return dd
        return None

    def scale_range(self, ctrl, g, point, run, hint=None):
        """``[g_lo, g_hi]``: the stiffness factors (all K x g, TRUE plant) at which the radius reaches 1.

        Bisection in log g to a ratio ``2^(1/64)``; None on a side that stays stable over the bracket
        (``1/16 .. 16``). ``[None, None]`` with ``unstable`` when g = 1 itself is unstable. ``hint``: another
        point's range; a side whose boundary lies within that same ratio of it is taken in two evaluations.
        """
        d = self.cond.delay
        stable = lambda s: self.rho(ctrl, g, point, scaled_stiffness(self.model, self.p_nom, s), d, run) < 1.0
        if not stable(1.0):
            return {"range": [None, None], "unstable": True}
        half = 2.0 ** (0.5 / 2 ** SCALE_BISECTIONS)          # half the final bracket, as a ratio

        def side(k: int, sign: float):
            v = None if hint is None else hint[k]
            if v is not None and stable(v * half ** -sign) and not stable(v * half ** sign):
                return float(v)
            return self._scale_side(stable, sign)
        # the two sides are independent searches: one thread each (CasADi releases the GIL while it evaluates;
        # the Panda's default analysis spent 21 of 33 s here, one side after the other)
        with ThreadPoolExecutor(max_workers=2) as pool:
            out = list(pool.map(side, (0, 1), (-1.0, 1.0)))
        return {"range": out, "unstable": False}

    @staticmethod
    def _scale_side(stable, sign: float):
        """One side of :meth:`scale_range` from scratch: bracket, then bisection."""
        ok, bad = 1.0, None
        for b in SCALE_BRACKET:
            s = b ** sign
            if stable(s):
                ok = s
            else:
                bad = s
                break
        if bad is None:
            return None
        for _ in range(SCALE_BISECTIONS):
            mid = float(np.sqrt(ok * bad))
            ok, bad = (mid, bad) if stable(mid) else (ok, mid)
        return float(np.sqrt(ok * bad))

    # -- the whole analysis ------------------------------------------------------------------------
    def _layer(self, ctrl, g, lin):
        """``(k_s, delta, slope)`` of the law's boundary layer at ``lin`` (gains ``g``), or None (no layer)."""
        blocks = self.model.manifest["controls"][ctrl.law_kind]["gains"]
        off = {b["name"]: (int(b["offset"]), int(b["size"])) for b in blocks}
        if "k_s" not in off or "delta" not in off:
            return None
        take = lambda name: np.broadcast_to(g[off[name][0]:off[name][0] + off[name][1]], (self.n,)).astype(float)
        k_s, delta = take("k_s"), take("delta")
        law_delta = np.broadcast_to(np.asarray(ctrl.delta, dtype=float), (self.n,))
        slope = np.where(np.abs(lin.s) < delta, k_s / delta, 0.0)
        return k_s, law_delta, slope

    def equivalent_gains(self, ctrl, g, fig) -> np.ndarray:
        """``g`` with each boundary layer widened to ``delta / P(|s| < delta)`` of ``fig`` (a point's
        :func:`assess`): inside it the law's slope is the equivalent gain (the loop the trajectories and
        margins are computed on). ``g`` itself when the point has no layer fraction."""
        frac = fig.get("layer_fraction")
        if frac is None or fig.get("method") != "equivalent gain":
            return g
        blocks = {b["name"]: b for b in self.model.manifest["controls"][ctrl.law_kind]["gains"]}
        b = blocks["delta"]
        out = np.asarray(g, dtype=float).copy()
        delta = np.broadcast_to(np.asarray(ctrl.delta, dtype=float), (self.n,))
        wide = delta / np.maximum(np.asarray(frac, dtype=float), 1e-9)
        out[int(b["offset"]):int(b["offset"]) + int(b["size"])] = wide[:int(b["size"])]
        return out

    def figures(self, ctrl, g, point: int, p, run, attribution: bool) -> dict:
        """:func:`assess` of one plant and point (gains ``g``), with ``|s| / delta`` at the point."""
        S, w, r = self.operating_point(ctrl, g, point, p, self.cond.delay, run)
        if not np.all(np.isfinite(w)):
            return {"rho": float("inf"), "stable": False, "dominant_joint": None}
        lin = S.linearize(w, r, p, g)
        if point == 0:
            self._chords.setdefault(self.cond.delay, lin)
        fig = assess(lin, self.levels, self.h, self.names, attribution, self._layer(ctrl, g, lin), self._sigma0)
        if getattr(ctrl, "delta", None) is not None:  # a law with a boundary layer (ismc, smc, adaptive)
            fig["s_over_delta"] = (np.abs(lin.s) / np.asarray(ctrl.delta, dtype=float)).tolist()
        return fig

    def analyze(self, gains: dict, margins: bool = True, attribution: bool = True,
                points: Optional[Sequence[int]] = None) -> dict:
        """The analysis of ``gains`` (a law gains dict, or a controller) as a JSON-able dict.

        ``points``: indices into :meth:`points` (default all). The nominal plant at rest is analysed
        first: its equivalent gains (:meth:`equivalent_gains`) are the law the task run, the task points and
        the margins use. Margins: the delay margin for every plant at rest and for the nominal plant (the
        first) at every point; the stiffness-scale range for the nominal plant at every point.
        """
        t0 = time.perf_counter()
        ctrl = gains if hasattr(gains, "law_kind") else self.cond.controller(gains)
        g = np.asarray(ctrl.gains, dtype=float)
        self._chords = {}
        pts = list(range(len(self.task_k) + 1)) if points is None else list(points)
        self._sigma0 = None
        rest0 = self.figures(ctrl, g, 0, self.plants[0][1], {}, attribution)
        g_eq = self.equivalent_gains(ctrl, g, rest0)
        if "s_std_over_delta" in rest0:          # every other point's fixed point starts from this one's
            self._sigma0 = np.asarray(rest0["s_std_over_delta"]) * np.asarray(ctrl.delta, dtype=float)
        run = self._nominal_run(ctrl, g_eq) if any(i > 0 for i in pts) else {}
        names = self.points()
        table, margin_jobs = [], []
        for k, (name, p) in enumerate(self.plants):
            row = {"plant": name, "params": {k: float(v) for k, v in zip(self.model.param_names, p)}, "points": {}}
            for i in pts:
                fig = rest0 if (i == 0 and k == 0) else self.figures(ctrl, g if i == 0 else g_eq, i, p, run,
                                                                     attribution)
                if margins and (i == 0 or k == 0):
                    if fig["stable"] is False:
                        fig["first_unstable_delay"] = self.cond.delay
                    else:
                        margin_jobs.append((fig, i, p))
                row["points"][names[i]] = fig
            table.append(row)
        # each point's delay margin is its own search: two at a time (CasADi releases the GIL while it evaluates)
        with ThreadPoolExecutor(max_workers=2) as pool:
            found = list(pool.map(lambda job: self.delay_margin(ctrl, g_eq, job[1], job[2], run), margin_jobs))
        for (fig, _, _), d in zip(margin_jobs, found):
            fig["first_unstable_delay"] = d
        out = {"points": [names[i] for i in pts], "plants": table, "summary": _summary(table, self.n)}
        if margins:
            out["stiffness_scale"], hint = {}, None
            for i in pts:
                sc = out["stiffness_scale"][names[i]] = self.scale_range(ctrl, g_eq, i, run, hint)
                hint = None if sc["unstable"] else sc["range"]
        out["settings"] = {"rate": 1.0 / self.T, "delay": self.cond.delay, "predict": self.cond.predict,
                           "sensing": self.cond.sensing, "sensor": self.cond.sensor.name,
                           "interface": None if self.cond.interface is None else self.cond.interface.name,
                           "substeps": self.substeps,
                           "jitter_window_samples": 2 * self.h + 1, "catch_up_samples": self.catch,
                           "noise_levels": dict(zip(self.names, self.levels.tolist()))}
        out["seconds"] = time.perf_counter() - t0
        return out


def _summary(table, n):
    """Worst over plants and points: radius, jitter and error std per joint, first unstable delay; the
    verdict (``stable_everywhere`` True / False, or None when no point is unstable but some has none)."""
    figs = [f for row in table for f in row["points"].values()]
    rho = max(f["rho"] for f in figs)
    stable = [f for f in figs if f["stable"]]
    worst = lambda key: [finite(max(f[key][j] for f in stable)) for j in range(n)] if len(stable) == len(figs) \
        else [None] * n
    delays = [f.get("first_unstable_delay") for f in figs if "first_unstable_delay" in f]
    verdict = True if len(stable) == len(figs) else (False if any(f["stable"] is False for f in figs) else None)
    return {"rho": finite(rho), "stable_everywhere": verdict,
            "no_verdict": sorted({f["reason"] for f in figs if f["stable"] is None and "reason" in f}),
            "torque_jitter": worst("torque_jitter"), "q_error_std": worst("q_error_std"),
            "first_unstable_delay": (min((d for d in delays if d is not None), default=None) if delays else None)}
