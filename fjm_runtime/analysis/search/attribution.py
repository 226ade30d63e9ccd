"""What limits a failed design, found by Monte Carlo: the binding draw re-run with each sensor effect removed.

When no screen explains a failure (:mod:`fjm_runtime.analysis.search.screen`), :func:`attribute`
re-runs the draw of the binding miss with the same gains, plant and noise seed: once per noise
source with its levels at zero (encoder angles ``q, q_m``; measured velocities ``dq, dq_m``; the
torque sensor ``tau_J, dtau_J``), once with every noise level at zero, and, when the command
interface limits the command's rate, once without that limit. Noise LEVELS are run-time inputs of the
compiled step, so those re-runs reuse the design's library; the rate limit is part of the step (its
re-run builds one more step). Quantization, filters and the tau_J offset stay in every re-run. The
effect whose removal brings the missed figure furthest down limits the design; if the figure still
misses without any one of them, they do not limit it alone (the gains, plant box, rate, delay or
torque limits do).
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Dict, Optional, Tuple

import numpy as np

__all__ = ["SOURCES", "attribute"]

#: Noise sources by name: the SensorModel level fields each one zeroes.
SOURCES = {"encoder noise (q, q_m)": ("q", "q_m"),
           "velocity noise (dq, dq_m)": ("dq", "dq_m"),
           "torque-sensor noise (tau_J, dtau_J)": ("tau_J", "dtau_J")}
ALL_NOISE = "every noise level at zero"
NO_RATE_LIMIT = "no torque-rate limit"
_METRIC = {"rms": "rms_second_half", "jitter": "torque_jitter", "at_limit": "time_at_limit"}


def _silent(sensor, fields) -> bool:
    return all(np.all(np.asarray(getattr(sensor, f)) == 0) for f in fields)


def _figure(b, miss) -> float:
    """The missed figure in a one-run batch (a metric: +inf when the run diverged; 'diverged': 0 or 1)."""
    if miss["threshold"] == "diverged":
        return float(bool(b.diverged[0]))
    if b.diverged[0]:
        return float("inf")
    return float(np.asarray(b.joint_metrics[_METRIC[miss["threshold"]]])[0, miss["joint"] - 1])


def variants(sensor, interface=None) -> Dict[str, dict]:
    """The re-runs of :func:`attribute`: name -> SensorModel fields to replace (the rate limit's: the
    CommandInterface field ``torque_rate_limit``)."""
    out = {name: {f: 0.0 for f in fields} for name, fields in SOURCES.items() if not _silent(sensor, fields)}
    if len(out) > 1:
        out[ALL_NOISE] = {f: 0.0 for fields in SOURCES.values() for f in fields}
    if interface is not None and interface.has_rate_limit():
        out[NO_RATE_LIMIT] = {"torque_rate_limit": math.inf}
    return out


def attribute(loops, gains: dict, row: np.ndarray, noise_seed: int, duration: float,
              miss: dict) -> Tuple[Optional[str], Dict[str, float]]:
    """``(sentence, figures)``: the miss's figure with each sensor effect removed (module docstring).

    Parameters
    ----------
    loops : DesignLoops
    gains : dict
    row : ndarray (n_params,)
        The TRUE parameters of the binding draw.
    noise_seed : int
    duration : float
        Seconds (the stage's run length).
    miss : dict
        A record of :func:`~fjm_runtime.analysis.search.thresholds.find_misses`.

    Returns
    -------
    sentence : str or None
        E.g. ``"limited by encoder noise (q, q_m): jitter on joint 2 4.1 -> 1.2 N m without it (limit
        3 N m)"``; None when the sensor has nothing to remove.
    figures : dict str -> float
        The figure per re-run (``"as designed"`` and each of :func:`variants`).
    """
    sensor, interface = loops.sensor, getattr(loops, "interface", None)
    runs = variants(sensor, interface)
    if not runs:
        return None, {}
    figures: Dict[str, float] = {}
    try:
        for name, change in [("as designed", {})] + list(runs.items()):
            if name == NO_RATE_LIMIT:
                loops.interface = replace(interface, **change)
            else:
                loops.sensor = replace(sensor, **change)
            b = loops.run([gains], np.atleast_2d(row), duration, np.array([int(noise_seed)]))
            figures[name] = _figure(b, miss)
    finally:
        loops.sensor = sensor
        if interface is not None:
            loops.interface = interface
    return _sentence(miss, figures), figures


def _without(name: str) -> str:
    return {ALL_NOISE: "any sensor noise", NO_RATE_LIMIT: "the torque-rate limit"}.get(name, name)


def _main_effect(removed: Dict[str, float], base: float) -> str:
    """The removal that lowers the figure most; a single noise source over all of them when it gets
    95 % of their drop (it names the source)."""
    name = min(removed, key=removed.get)
    if name == ALL_NOISE:
        drop = base - removed[name]
        singles = {k: v for k, v in removed.items() if k in SOURCES}
        if singles and drop > 0:
            k = min(singles, key=singles.get)
            if base - singles[k] >= 0.95 * drop:
                return k
    return name


def _sentence(miss: dict, figures: Dict[str, float]) -> str:
    removed = {k: v for k, v in figures.items() if k != "as designed"}
    if miss["threshold"] == "diverged":
        calm = [k for k, v in removed.items() if v == 0.0]
        if not calm:
            return (f"diverges also without {', '.join(_without(k) for k in removed)}: limited by the loop (gains, "
                    "plant box, rate, delay, torque limits)")
        single = [k for k in calm if k != ALL_NOISE]
        return f"limited by {_without(single[0] if single else ALL_NOISE)}: no divergence without it"
    limit, base = miss["limit"], figures["as designed"]
    scale, unit = (100.0, "%") if miss["threshold"] == "at_limit" else (1.0, miss["unit"])
    what = {"rms": "RMS error", "jitter": "jitter", "at_limit": "time at a limit"}[miss["threshold"]]
    name = _main_effect(removed, base)
    got = removed[name]
    if min(removed.values()) > limit:
        return (f"{what} on joint {miss['joint']}: {scale * base:.3g} {unit} as designed, {scale * got:.3g} {unit} "
                f"without {_without(name)} (the largest drop), still > {scale * limit:.3g} {unit}: {_without(name)} "
                "costs most, the rest is the loop (gains, plant box, rate, delay, torque limits)")
    return (f"limited by {_without(name)}: {what} on joint {miss['joint']} {scale * base:.3g} -> {scale * got:.3g} "
            f"{unit} without it (limit {scale * limit:.3g} {unit})")
