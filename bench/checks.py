"""The peer checks of ``python -m bench``: tolerances, the recorded comparison, difference measures.

Every peer's output is compared with the generated code in the run itself; :func:`check` records
one comparison in the run's ``checks`` list (``results.json["checks"]``), and ``make bench`` exits 1
when one is not ``ok``.
"""
from __future__ import annotations

import numpy as np

from .timing import log

__all__ = ["TOLERANCES", "check", "metric_diff", "rel_diff"]

#: Largest accepted disagreement between a peer and the generated code, per comparison.
TOLERANCES = {
    # |a - a_ref| / max(1, max |a_ref|) over alpha and beta at 3 random states
    "alpha_beta": 1e-9,
    # |checksum - sum over the timed calls of alpha[0] + beta[0, 0] from the .casadi Functions|, relative
    "alpha_beta_checksum": 1e-9,
    # states (rad, rad/s) of the hand-written C loop vs the generated loop, max abs
    "hand_c_states": 1e-9,
    # u, s, y_hat of the hand-written C loop vs the generated loop, relative to max(1, max |.|)
    "hand_c_outputs": 1e-9,
    # the mapaccum form (casadi.external) vs the C loop form of the same step, max abs state
    "mapaccum_states": 1e-12,
    # simulate(backend="python") vs simulate(backend="compiled"): states, max abs
    "python_states": 1e-9,
    # metrics of two runs of the same loop: |a - b| / max(|b|, 1e-6), inf/nan must match
    "metrics": 1e-9,
    # scipy RK45 (law evaluated continuously, no zero-order hold) vs RK4 + ZOH, max abs state
    "solve_ivp_states": 5e-3,
    # numpy batch peer vs simulate_batch, final states max abs
    "numpy_batch_states": 1e-9,
}



def check(checks: list, key: str, what: str, measured: float, tolerance: float) -> None:
    """Record one peer comparison: ``ok`` iff ``measured <= tolerance`` (NaN fails)."""
    measured = float(measured)
    ok = bool(np.isfinite(measured) and measured <= tolerance)
    checks.append({"key": key, "what": what, "measured": measured, "tolerance": float(tolerance), "ok": ok})
    if not ok:
        log(f"PEER DISAGREES: {key}: {what}: {measured:.3g} > tolerance {tolerance:.3g}")


def metric_diff(a: dict, b: dict, keys) -> float:
    """``max |a - b| / max(|b|, 1e-6)`` over the metrics ``keys``; mismatched inf/nan count as inf."""
    worst = 0.0
    for k in keys:
        x, y = np.asarray(a[k], dtype=float), np.asarray(b[k], dtype=float)
        same = (x == y) | (np.isnan(x) & np.isnan(y))
        fin = np.isfinite(x) & np.isfinite(y)
        if np.any(~same & ~fin):
            return float("inf")
        if np.any(fin):
            worst = max(worst, float(np.max(np.abs(x[fin] - y[fin]) / np.maximum(np.abs(y[fin]), 1e-6))))
    return worst


def rel_diff(a, ref) -> float:
    """``max |a - ref| / max(1, max |ref|)``."""
    a, ref = np.asarray(a, dtype=float), np.asarray(ref, dtype=float)
    return float(np.max(np.abs(a - ref)) / max(1.0, float(np.max(np.abs(ref)))))
