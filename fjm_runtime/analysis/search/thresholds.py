"""What a design must meet, the cost the search minimises, and the misses of a check.

:class:`Thresholds` holds the limits of ``fjm design`` (``--max-rms``, ``--max-jitter``,
``--max-at-limit``, ``--jitter-joints``). :func:`run_cost` is the search's cost of a run (the
worst joint's second-half RMS plus penalties for every excess over a limit); :func:`find_misses`
lists, for a set of runs, every threshold a joint misses with the worst draw, and
:func:`describe_miss` says it in one line (``jitter 4.1 N m on joint 2 > 3 N m by 1.1 N m
(draw 17, seed 17)``).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

import numpy as np

from ...validation import FjmValueError

__all__ = ["DEFAULT_JITTER_JOINTS", "DIVERGED_COST", "PENALTY", "Thresholds", "describe_miss", "find_misses",
           "parse_joints", "run_cost"]

#: Cost of a diverged run (rad): above any run that ends, penalties included. It was 10 rad; with the
#: ``franka_like`` sensor a Panda search met runs that ended with costs of 100-340 (jitter in the
#: thousands of N m), which a 10 rad divergence undercut: the search could prefer gains that diverge.
DIVERGED_COST = 1e4
#: Weight (rad) of a constraint violation of one limit's size.
PENALTY = 1e-2
#: Joints (0-based) the jitter limit applies to by default: 1-4 (the proximal joints of an arm),
#: those of them the model has.
DEFAULT_JITTER_JOINTS = (0, 1, 2, 3)


@dataclass(frozen=True)
class Thresholds:
    """The limits a design must meet on every draw and joint.

    Attributes
    ----------
    max_rms : float
        Second-half RMS tracking error of each joint, rad. Default 2e-3 rad: about 3x the worst
        joint of the shipped Panda 1 kHz / d = 1 design (6.9e-4 rad over its 200 draws) and below
        the 5.4e-3 rad of the failed d = 2 search before these thresholds; 1.6 mm at the Panda's 0.8 m reach.
    max_jitter : float
        Torque jitter (std of the commanded torque about its 20 ms moving mean), N m, on the joints
        of ``jitter_joints``.
    max_at_limit : float
        Fraction of the samples at a torque limit, per joint (0.02: 2 %).
    jitter_joints : tuple of int, optional
        0-based joints of the jitter limit; None: joints 1-4 (those the model has).
    """

    max_rms: float = 2e-3
    max_jitter: float = 3.0
    max_at_limit: float = 0.02
    jitter_joints: Optional[Tuple[int, ...]] = None

    def __post_init__(self):
        for name in ("max_rms", "max_jitter", "max_at_limit"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (np.isfinite(v) and v > 0):
                raise FjmValueError(f"{name} = {v!r}: expected a finite threshold > 0")
        if self.max_at_limit > 1:
            raise FjmValueError(f"max_at_limit = {self.max_at_limit!r}: expected a fraction in (0, 1] (0.02: 2 %)")

    def joints(self, n: int) -> List[int]:
        """The 0-based joints of the jitter limit on an ``n``-joint model."""
        if self.jitter_joints is None:
            return [j for j in DEFAULT_JITTER_JOINTS if j < n]
        bad = [j + 1 for j in self.jitter_joints if not 0 <= j < n]
        if bad:
            raise FjmValueError(f"jitter joints {bad}: the model has joints 1..{n}")
        return list(self.jitter_joints)

    def as_dict(self, n: int) -> dict:
        """JSON record (joints 1-based)."""
        return {"max_rms": self.max_rms, "max_jitter": self.max_jitter, "max_at_limit": self.max_at_limit,
                "jitter_joints": [j + 1 for j in self.joints(n)]}


def parse_joints(text: str, n: Optional[int] = None) -> Optional[Tuple[int, ...]]:
    """``'1-4'``, ``'1,2,3'``, ``'1-3,6'`` or ``'all'`` (1-based) as 0-based joints; ``'all'`` needs ``n``.

    Raises
    ------
    FjmValueError
        ``--jitter-joints TEXT: ...`` naming the bad part.
    """
    s = str(text).strip().lower()
    if s == "all":
        if n is None:
            raise FjmValueError("--jitter-joints all: the model's joint count is needed")
        return tuple(range(int(n)))
    out: List[int] = []
    for part in s.split(","):
        m = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?", part)
        if not m or int(m.group(1)) < 1 or (m.group(2) and int(m.group(2)) < int(m.group(1))):
            raise FjmValueError(f"--jitter-joints {text!r}: part {part.strip()!r}; expected joints from 1 as "
                                "'1-4', '1,2,3' or 'all'")
        lo, hi = int(m.group(1)), int(m.group(2) or m.group(1))
        out += [j - 1 for j in range(lo, hi + 1) if j - 1 not in out]
    if n is not None and max(out) >= n:
        raise FjmValueError(f"--jitter-joints {text!r}: joint {max(out) + 1}; the model has joints 1..{n}")
    return tuple(out)


def _excess(value, limit):
    return np.maximum(0.0, value - limit) / limit


def run_cost(batch, thresholds: Thresholds = Thresholds()) -> np.ndarray:
    """Per-run cost of a :class:`BatchResult` (``joint_metrics``, ``diverged``), shape (B,).

    ``max_j rms_j + PENALTY * sum_j (excess_rms_j + excess_at_limit_j + excess_jitter_j)`` with
    ``excess = max(0, value - limit) / limit`` (jitter on the jitter joints only); a diverged or
    non-finite run costs :data:`DIVERGED_COST`. The sum, not the largest excess, lets a better gain
    on one joint count while another still violates more.
    """
    jm = batch.joint_metrics
    rms_j = np.asarray(jm["rms_second_half"], dtype=float)
    n = rms_j.shape[1]
    tal = np.asarray(jm["time_at_limit"], dtype=float)
    jit = np.asarray(jm["torque_jitter"], dtype=float)[:, thresholds.joints(n)]
    jit = np.where(np.isfinite(jit), jit, 0.0)
    cost = np.max(rms_j, axis=1) + PENALTY * (
        np.sum(_excess(rms_j, thresholds.max_rms), axis=1) + np.sum(_excess(tal, thresholds.max_at_limit), axis=1)
        + np.sum(_excess(jit, thresholds.max_jitter), axis=1))
    return np.where(np.asarray(batch.diverged) | ~np.isfinite(cost), DIVERGED_COST, cost)


#: (name in the record, joint metric, threshold attribute, unit, scale of the printed value).
_CHECKS = (("rms", "rms_second_half", "max_rms", "rad", 1.0),
           ("jitter", "torque_jitter", "max_jitter", "N m", 1.0),
           ("at_limit", "time_at_limit", "max_at_limit", "%", 100.0))


def find_misses(batch, thresholds: Thresholds, draws: Sequence[int], stage: str) -> List[dict]:
    """Every (threshold, joint) that some run misses, with its worst run; diverged runs first.

    Parameters
    ----------
    batch : BatchResult
        ``joint_metrics`` (B, n), ``diverged`` (B,), ``seeds`` (B,), ``divergence_time`` (B,).
    thresholds : Thresholds
    draws : sequence of int, length B
        The draw number of each run (as the record names it).
    stage : str
        ``'final'`` or ``'recheck'``.

    Returns
    -------
    list of dict
        ``threshold, joint (1-based; None for 'diverged'), value, limit, unit, excess, draw, seed,
        stage`` (values in SI: rad, N m, fraction; ``diverged`` has ``count`` and ``time``).
    """
    out: List[dict] = []
    div = np.asarray(batch.diverged, dtype=bool)
    seeds = np.asarray(batch.seeds) if getattr(batch, "seeds", None) is not None else np.zeros(div.size)
    if div.any():
        i = int(np.flatnonzero(div)[0])
        t = float(np.asarray(batch.divergence_time)[i]) if getattr(batch, "divergence_time", None) is not None \
            else float("nan")
        out.append({"threshold": "diverged", "joint": None, "count": int(div.sum()), "of": int(div.size),
                    "draw": int(draws[i]), "seed": int(seeds[i]), "time": t if np.isfinite(t) else None,
                    "stage": stage})
    jm = batch.joint_metrics
    n = np.asarray(jm["rms_second_half"]).shape[1]
    for name, metric, attr, unit, _scale in _CHECKS:
        vals = np.where(div[:, None], np.nan, np.asarray(jm[metric], dtype=float))
        limit = float(getattr(thresholds, attr))
        joints = thresholds.joints(n) if name == "jitter" else range(n)
        for j in joints:
            col = vals[:, j]
            if not np.any(np.isfinite(col)):
                continue
            i = int(np.nanargmax(col))
            if col[i] > limit:
                out.append({"threshold": name, "joint": j + 1, "value": float(col[i]), "limit": limit,
                            "unit": "rad" if unit == "rad" else ("N m" if unit == "N m" else "fraction"),
                            "excess": float(col[i] - limit), "draw": int(draws[i]), "seed": int(seeds[i]),
                            "stage": stage})
    return out


def _fmt(v: float, unit: str, digits: int = 3) -> str:
    if unit == "fraction":
        return f"{100 * v:.{digits}g} %"
    return f"{v:.{digits}g} {unit}"


def _digits(value: float, limit: float, unit: str) -> int:
    """Significant digits that tell ``value`` from ``limit`` (3 at least, 8 at most)."""
    d = 3
    while d < 8 and _fmt(value, unit, d) == _fmt(limit, unit, d):
        d += 1
    return d


def describe_miss(miss: dict) -> str:
    """One line: ``jitter 4.1 N m on joint 2 > 3 N m by 1.1 N m (draw 17, seed 17)``."""
    if miss["threshold"] == "diverged":
        at = f", at {miss['time']:.3g} s" if miss.get("time") is not None else ""
        return (f"diverged: {miss['count']} of {miss['of']} runs (first: draw {miss['draw']}, seed {miss['seed']}"
                f"{at}; {miss['stage']})")
    label = {"rms": "RMS error", "jitter": "jitter", "at_limit": "time at a torque limit"}[miss["threshold"]]
    u = miss["unit"]
    d = _digits(miss["value"], miss["limit"], u)
    return (f"{label} {_fmt(miss['value'], u, d)} on joint {miss['joint']} > {_fmt(miss['limit'], u)} by "
            f"{_fmt(miss['excess'], u)} (draw {miss['draw']}, seed {miss['seed']}; {miss['stage']})")
