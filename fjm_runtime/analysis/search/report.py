"""The gains file a design writes (``fjm simulate --gains`` reads ``kind`` and ``gains``), and its summary."""
from __future__ import annotations

from typing import List

import numpy as np

from ...sim.predictor import loop_predict_substeps

__all__ = ["binding_miss", "report", "summary_lines", "worst_case"]


def _finite(a) -> list:
    return [None if not np.isfinite(v) else float(v) for v in a]


def _nanmax(a) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    out = np.full(a.shape[1], np.nan)
    ok = np.any(np.isfinite(a), axis=0)
    out[ok] = np.nanmax(a[:, ok], axis=0)
    return out


def worst_case(b, cost: float) -> dict:
    """Worst over the runs of a BatchResult, per joint: ``cost, diverged, rms_second_half, time_at_limit,
    torque_jitter, peak_torque, time_at_rate_limit`` (None where every run diverged)."""
    jm = b.joint_metrics
    out = {"cost": float(cost), "diverged": int(np.sum(b.diverged))}
    for k in ("rms_second_half", "time_at_limit", "torque_jitter", "peak_torque", "time_at_rate_limit"):
        if k in jm:
            out[k] = _finite(_nanmax(jm[k]))
    return out


def report(model, prob, best, worst, b, margins, draws, seed, duration) -> dict:
    """The record's common part: settings, gains, the final check's worst case, margins."""
    from ... import __version__
    gains = dict(best)
    if prob.u_max is not None:
        gains["u_max"] = [float(v) for v in np.broadcast_to(prob.u_max, (int(model.n),))]
    rec = {"model": model.name, "kind": prob.kind, "sensing": prob.sensing, "rate": 1.0 / prob.dt,
           "delay": prob.delay, "sensor": prob.sensor.as_dict(), "interface": prob.interface.as_dict(),
           "reference": prob.task, "predict": prob.predict}
    if prob.predict and prob.delay > 0:  # the predictor's substeps by accuracy, for the exported controller
        rec["predict_substeps"] = loop_predict_substeps(model, prob.controller(best), prob.sensor, prob.dt,
                                                        prob.delay, prob.reference, prob.x0)
    return {**rec, "gains": gains, "worst_case": worst_case(b, worst), "margins": margins, "draws": int(draws),
            "seed": int(seed), "duration": float(duration), "fjm_version": __version__}


def summary_lines(rec: dict) -> List[str]:
    """What ``fjm design`` prints on stderr at the end: the verdict, each miss, what limits it."""
    thr = rec["thresholds"]
    if rec["meets"]:
        rc = rec.get("recheck", {})
        again = (f"; re-checked on {rc['draws']} fresh draws" if rc.get("draws") else
                 f"; no re-check ({rc.get('skipped', '')})")
        return [f"meets every threshold (RMS <= {thr['max_rms']:g} rad, jitter <= {thr['max_jitter']:g} N m on "
                f"joints {thr['jitter_joints']}, at a limit <= {100 * thr['max_at_limit']:g} %) on "
                f"{rec['draws']} draws{again}"]
    cond = f"{rec['rate']:g} Hz, delay {rec['delay']}, sensor {rec['sensor'].get('name', '?')}"
    b = rec.get("binding") or {}
    out = [f"{cond}: does NOT meet the thresholds ({len(rec['misses'])} miss(es); the file records "
           f"\"meets\": false); binding: {b.get('message', '?')}"]
    if rec.get("limited_by"):
        out.append(f"  limited by: {rec['limited_by']}")
    out += [f"  {m['message']}" for m in rec["misses"]]
    return out


def binding_miss(misses: list):
    """The miss that binds most: a divergence, else the largest excess relative to its limit (None if none)."""
    if not misses:
        return None
    div = [m for m in misses if m["threshold"] == "diverged"]
    return div[0] if div else max(misses, key=lambda m: m["excess"] / m["limit"])
