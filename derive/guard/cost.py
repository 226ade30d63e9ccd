"""Cost of a derivation estimated from the chain alone, before any symbolic work.

The symbolic derivation of an n-joint chain grows fast with n (``alpha``'s
time derivatives and the bracket matrix ``ad`` dominate). To refuse a runaway input (a mistyped
``tip`` link, a snake robot) before it takes the machine's memory, the cost is
estimated from ``n`` and the kind of chain (``"planar"``: the closed-form
planar chains; ``"spatial"``: URDF arms) with power laws fitted to measured
derives::

    operations(n)  = c_ops  n^e_ops                      (all generated functions)
    peak_bytes(n)  = base_bytes   + c_mem n^e_mem        (resident memory of the process)
    seconds(n)     = base_seconds + c_s   n^e_s          (wall clock of `python -m derive`)

``base_*`` is a trivial derive (interpreter, SymPy and CasADi imports); the
exponents and factors come from least squares on log-log axes of the measured
excess over it (:func:`fit_power_law`). :data:`CALIBRATION` records the
measurement they come from; ``python -m bench.derive_cost`` repeats it.

:func:`check_limits` compares an estimate with the limits (:data:`MAX_PEAK_BYTES`,
:data:`MAX_SECONDS`, or a user's ``--max-cost SECONDS``) and returns the
one-line refusal, or None. Pure functions: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, Optional, Sequence, Tuple

__all__ = ["Estimate", "estimate", "check_limits", "fit_power_law", "slowdown", "CALIBRATION", "MAX_PEAK_BYTES",
           "MAX_SECONDS", "FORMS"]

#: Default limits: an estimate above either is refused unless ``--no-cost-limit`` or ``--max-cost``. The time
#: limit applies to the estimate at the machine's current load (:func:`slowdown`): a derive either finishes
#: within about this long or is refused at once (before this limit, 300 s on the idle estimate let a
#: 60-joint chain start on a loaded 2-core machine, where it neither finished nor stopped within 150 s).
MAX_PEAK_BYTES = 2 * 1024 ** 3
MAX_SECONDS = 150.0
FORMS = ("planar", "spatial")

#: The cost model: per form, ``(factor, exponent)`` of each quantity's excess over the trivial derive
#: (``base_bytes``, ``base_seconds``: ``python -m derive --models planar1``), fitted by
#: :func:`fit_power_law` to ``runs``. ``spatial``: synthetic URDF chains (:mod:`derive.guard.synthetic`) derived
#: with ``--model-file``; ``planar``: the built-in ``planar<n>``. Peak memory is the process's maximum
#: resident set size (``ru_maxrss``, the number ``/usr/bin/time -v`` prints; ``bench/peak_rss.py``), seconds the
#: wall clock of the whole command.
#: Spatial: measured 2026-12-02 on an idle project machine (2 cores, load 0.1) by
#: ``python -m bench.derive_cost --spatial 14 21 30 45 60 --planar --keep-base``, after the Taylor
#: recursion and the closed-form brackets, at the sizes where a guard matters (the growth steepens with
#: n: fitted over 14..60 the estimate at 60 joints is 0.92-0.98 of the measurement, fitted over 3..60
#: it was 0.74 for memory). The seconds are this machine's; a machine three times slower (as measured
#: between sessions on this project) is what :func:`slowdown` scales them by. The base and the
#: planar runs are those of 2026-12-01 (the planar derivation did not change since; planar chains stay
#: within about a second of the base and are capped at 7 links, so their fit is nearly flat).
CALIBRATION: Dict[str, object] = {
    "measured": "spatial 2026-12-02 (idle machine, after the Taylor recursion and the closed-form brackets), "
                "base and planar 2026-12-01; python -m bench.derive_cost",
    "base_bytes": 95178752,
    "base_seconds": 0.93,
    "spatial": {"operations": (163.56032824947656, 2.2643676456846284),
                "peak_bytes": (25045.87856361485, 2.540545070237284),
                "seconds": (0.0043319092178612005, 2.313706438453827)},
    "planar": {"operations": (126.88805941086473, 2.1712012261231752),
               "peak_bytes": (205028.8444603613, 1.746326365259364),
               "seconds": (0.4662896071482834, 0.8207445020068006)},
    "runs": [
        {"form": "spatial", "n": 14, "operations": 67943, "peak_bytes": 116150272, "seconds": 3.01},
        {"form": "spatial", "n": 21, "operations": 155976, "peak_bytes": 149118976, "seconds": 5.71},
        {"form": "spatial", "n": 30, "operations": 342462, "peak_bytes": 245272576, "seconds": 11.44},
        {"form": "spatial", "n": 45, "operations": 892132, "peak_bytes": 473067520, "seconds": 29.18},
        {"form": "spatial", "n": 60, "operations": 1828127, "peak_bytes": 941600768, "seconds": 61.34},
        {"form": "planar", "n": 2, "operations": 583, "peak_bytes": 95842304, "seconds": 1.49},
        {"form": "planar", "n": 3, "operations": 1363, "peak_bytes": 96522240, "seconds": 3.93},
        {"form": "planar", "n": 4, "operations": 2523, "peak_bytes": 97546240, "seconds": 1.82},
        {"form": "planar", "n": 5, "operations": 4122, "peak_bytes": 99172352, "seconds": 2.4},
        {"form": "planar", "n": 6, "operations": 6220, "peak_bytes": 100184064, "seconds": 3.0},
        {"form": "planar", "n": 7, "operations": 8877, "peak_bytes": 100323328, "seconds": 3.4},
    ],
}


@dataclass(frozen=True)
class Estimate:
    """Estimated cost of deriving and emitting one model.

    Attributes
    ----------
    n : int
        Number of (revolute) joints.
    form : str
        ``"planar"`` or ``"spatial"``.
    operations : float
        Scalar operations of all generated functions.
    peak_bytes : float
        Peak resident memory of ``python -m derive`` for this model.
    seconds : float
        Wall-clock seconds of ``python -m derive`` for this model.
    """

    n: int
    form: str
    operations: float
    peak_bytes: float
    seconds: float
    slowdown: float = 1.0

    @property
    def model_seconds(self) -> float:
        """The estimated seconds of this model's own work (over a trivial derive's startup)."""
        return self.seconds - CALIBRATION["base_seconds"] * self.slowdown

    def summary(self) -> str:
        """``"~25k operations, ~0.31 GB peak memory, ~4 s"`` (``"~14 s at the current load (x3.5; ~4 s idle)"``)."""
        time = f"~{_seconds(self.seconds)}"
        if self.slowdown > 1.0:
            time += f" at the current load (x{self.slowdown:.2g}; ~{_seconds(self.seconds / self.slowdown)} idle)"
        return f"~{_si(self.operations)} operations, ~{self.peak_bytes / 1024 ** 3:.3g} GB peak memory, {time}"


def _si(x: float) -> str:
    for div, suffix in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if x >= div:
            return f"{x / div:.3g}{suffix}"
    return f"{x:.0f}"


def _seconds(s: float) -> str:
    if s >= 86400 * 365:
        return f"{s / (86400 * 365):.2g} years"
    if s >= 86400:
        return f"{s / 86400:.2g} days"
    if s >= 3600:
        return f"{s / 3600:.2g} h"
    return f"{s:.0f} s" if s >= 10 else f"{s:.2g} s"


def slowdown(load: float, cpus: int) -> float:
    """How many times longer a single-threaded derive takes than on the idle calibration machine.

    ``max(1, (load + 1) / cpus)``: ``load`` runnable processes (the 1-minute load average) and the
    derive share ``cpus`` cores. Measured: a 21-joint chain at load 7.3 on 2 cores took 19.9 s where the
    idle calibration says 5.7 s (x3.5; this gives x4.2, an over-estimate as meant).

    Parameters
    ----------
    load : float
        Load average (runnable processes), >= 0.
    cpus : int
        Cores the process may run on, >= 1.
    """
    return max(1.0, (max(float(load), 0.0) + 1.0) / max(int(cpus), 1))


def estimate(n: int, form: str, slow: float = 1.0) -> Estimate:
    """Cost of an ``n``-joint chain of kind ``form`` from :data:`CALIBRATION`.

    Parameters
    ----------
    n : int
        Number of joints (>= 1).
    form : str
        ``"planar"`` (:mod:`derive.planar.planar` chains and ``link1``) or ``"spatial"`` (URDF arms).
    slow : float
        The machine's :func:`slowdown` (>= 1; multiplies the seconds, not the memory or operations).

    Returns
    -------
    Estimate
    """
    if form not in FORMS:
        raise ValueError(f"form {form!r}; expected one of {', '.join(FORMS)}")
    if int(n) != n or n < 1:
        raise ValueError(f"n = {n!r}; expected an integer number of joints >= 1")
    fit = CALIBRATION[form]

    def power(q: str) -> float:
        c, e = fit[q]
        return c * float(n) ** e

    slow = max(1.0, float(slow))
    return Estimate(n=int(n), form=form, operations=power("operations"),
                    peak_bytes=CALIBRATION["base_bytes"] + power("peak_bytes"),
                    seconds=slow * (CALIBRATION["base_seconds"] + power("seconds")), slowdown=slow)


def check_limits(name: str, est: Estimate, max_seconds: Optional[float] = None,
                 max_peak_bytes: float = MAX_PEAK_BYTES) -> Optional[str]:
    """The one-line refusal of ``est`` beyond the limits, or None if it is within them.

    Parameters
    ----------
    name : str
        Model name, for the message.
    est : Estimate
    max_seconds : float, optional
        Limit on the estimated seconds (default :data:`MAX_SECONDS`). Given by ``--max-cost``,
        it replaces both default limits (memory is then not limited).
    max_peak_bytes : float
        Limit on the estimated peak memory (used when ``max_seconds`` is None).
    """
    if max_seconds is not None:
        if est.seconds <= max_seconds:
            return None
        over = f"over --max-cost {max_seconds:g} s"
    else:
        reasons = []
        if est.peak_bytes > max_peak_bytes:
            reasons.append(f"memory over {max_peak_bytes / 1024 ** 3:g} GB")
        if est.seconds > MAX_SECONDS:
            reasons.append(f"time over {MAX_SECONDS:g} s")
        if not reasons:
            return None
        over = " and ".join(reasons)
    return (f"{name}: refusing to derive a {est.n}-joint {est.form} chain: estimated {est.summary()} "
            f"({over}); pass --no-cost-limit, or --max-cost SECONDS, to derive it anyway")


def fit_power_law(ns: Sequence[float], values: Sequence[float], offset: float = 0.0) -> Tuple[float, float]:
    """Least squares fit of ``values - offset = c n^e`` on log-log axes.

    Parameters
    ----------
    ns : sequence of float, length m >= 2
    values : sequence of float, length m
        Measured quantities; ``values - offset`` must be positive.
    offset : float
        Subtracted before the fit (the cost of a trivial derive).

    Returns
    -------
    (float, float)
        ``(c, e)``.
    """
    if len(ns) < 2 or len(ns) != len(values) or any(v <= offset for v in values):
        raise ValueError("fit_power_law needs >= 2 points (n, value) with every value above the offset")
    pts = [(math.log(n), math.log(v - offset)) for n, v in zip(ns, values)]
    mx = sum(x for x, _ in pts) / len(pts)
    my = sum(y for _, y in pts) / len(pts)
    sxx = sum((x - mx) ** 2 for x, _ in pts)
    e = sum((x - mx) * (y - my) for x, y in pts) / sxx
    return math.exp(my - e * mx), e
