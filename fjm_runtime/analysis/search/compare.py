"""Several laws searched on the same draws and thresholds, compared side by side, the best one kept.

:func:`design_laws` runs :func:`~fjm_runtime.analysis.search.search.design` once per law (each in its own
gain space, :mod:`fjm_runtime.analysis.search.gain_spaces`) with every other setting the same: the same
plant draws and noise seeds (the same ``seed``), the same thresholds, task, sensor, rate and delay. It
returns the record of the best law with ``law_choice`` (how the law was chosen) and ``comparison`` (one
row per law: worst RMS over joints and draws, worst jitter on the jitter joints, worst share of the time
at a torque limit and at the torque-rate limit, diverged runs, final check and re-check together).

The best law: among those that meet every threshold (final check and re-check), the smallest worst RMS;
if none meets, the smallest worst cost of the final check (the record then says ``meets: false``).

The laws are searched in the order given. Once one meets, each law after it is only compared
(``SearchSettings.compare_only``): the same grid, final check and re-check on the same draws, but one
round of the pattern search (``COMPARED_ROUNDS``) and no active-set pass (further rounds only matter to a
law that could still meet with a smaller RMS than the one that met; its final check says how far it is),
and no margins and no attribution when it misses (its record is dropped; only its row is kept, marked
``compared``). The motor interface's laws are listed
with ``impedance`` first, the law that needs no jerk: under realistic sensing it is the one that meets
(the Panda and panda_hd under franka_like sensing: ismc and fl spend 70-91 % of the time at a torque limit,
against a threshold of 2 %).
"""
from __future__ import annotations

import sys
from dataclasses import replace
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from ...control.factory import make_controller
from ...validation import FjmValueError
from .gain_spaces import gain_space

__all__ = ["LAWS_BY_INTERFACE", "comparison_lines", "comparison_row", "design_laws", "laws_for"]

#: The laws ``--law auto`` tries on each command interface (``joint_torque``: its law needs the
#: joint-torque layer in the loop).
LAWS_BY_INTERFACE = {"motor": ("impedance", "ismc", "fl"), "joint_torque": ("joint_impedance",)}


def laws_for(model, interface: str = "motor", sensing: str = "torque") -> List[str]:
    """The laws of ``interface`` that ``model`` has emitted (a complete model has no impedance law)."""
    if interface not in LAWS_BY_INTERFACE:
        raise FjmValueError(f"design: interface {interface!r}: expected one of {', '.join(LAWS_BY_INTERFACE)}")
    p = model.params_array(None)
    out = []
    for law in LAWS_BY_INTERFACE[interface]:
        space = gain_space(law)
        try:
            make_controller(law, model, p, sensing=space.sensing or sensing, **space.grid(model, p)[0])
        except (FjmValueError, ValueError, KeyError):
            continue
        out.append(law)
    return out


def _worst(values, joints=None) -> Optional[float]:
    a = np.asarray([np.nan if v is None else v for v in values], dtype=float)
    if joints is not None:
        a = a[list(joints)]
    return None if not np.any(np.isfinite(a)) else float(np.nanmax(a))


def comparison_row(law: str, rec: dict) -> dict:
    """One law's row: ``law, meets, rms (rad), jitter (N m), at_limit, at_rate_limit (fractions), diverged,
    runs, cost, seconds, compared`` (True: only compared with a law that met first): worst over the final
    check and the re-check (where it ran)."""
    cases = [rec["worst_case"]] + ([rec["recheck"]["worst_case"]] if rec["recheck"].get("worst_case") else [])
    joints = [j - 1 for j in rec["thresholds"]["jitter_joints"]]

    def worst(key, js=None):
        vals = [_worst(c.get(key, []), js) for c in cases if c.get(key)]
        vals = [v for v in vals if v is not None]
        return max(vals) if vals else None
    return {"law": law, "meets": bool(rec["meets"]), "rms": worst("rms_second_half"),
            "jitter": worst("torque_jitter", joints), "at_limit": worst("time_at_limit"),
            "at_rate_limit": worst("time_at_rate_limit"), "diverged": int(sum(c["diverged"] for c in cases)),
            "runs": int(rec["draws"] + rec["recheck"].get("draws", 0)), "cost": float(rec["worst_case"]["cost"]),
            "seconds": float(sum(rec["evaluations"]["seconds"].values())), "compared": bool(rec.get("compare_only"))}


def _best(rows: List[dict]) -> int:
    meeting = [i for i, r in enumerate(rows) if r["meets"]]
    if meeting:
        return min(meeting, key=lambda i: rows[i]["rms"])
    return min(range(len(rows)), key=lambda i: rows[i]["cost"])


def design_laws(model, settings, laws: Sequence[str], asked: str = "auto",
                progress: Optional[Callable[[str], None]] = None) -> dict:
    """Search each law of ``laws`` on the same draws and thresholds; the best law's record (module docstring).

    Parameters
    ----------
    model : Model
    settings : SearchSettings
        Every setting but ``kind`` (and, for a law that reads its own measurement, ``sensing``).
    laws : sequence of str
        Laws of :data:`~fjm_runtime.analysis.search.gain_spaces.GAIN_SPACES`.
    asked : str
        How the record names the choice (``'auto'`` or the law asked for).
    progress : callable, optional
        Receives one line per stage, prefixed with the law (default: stderr).

    Returns
    -------
    dict
        The chosen law's :func:`design` record plus ``law_choice`` (``asked``, ``laws``, ``chosen``) and
        ``comparison`` (:func:`comparison_row` per law, in ``laws`` order).
    """
    from .search import design
    if not laws:
        raise FjmValueError(f"design: no law to search for {model.name} (laws {list(laws)!r})")
    say = progress or (lambda msg: print(f"fjm design: {msg}", file=sys.stderr, flush=True))
    records: Dict[str, dict] = {}
    for law in laws:
        gain_space(law)                                  # refuses an unknown law before any run
    met = False
    for law in laws:
        records[law] = design(model, replace(settings, kind=law, compare_only=met),
                              progress=lambda msg, law=law: say(f"[{law}] {msg}"))
        met = met or bool(records[law]["meets"])
    rows = [comparison_row(law, records[law]) for law in laws]
    chosen = list(laws)[_best(rows)]
    out = dict(records[chosen])
    out["law_choice"] = {"asked": asked, "laws": list(laws), "chosen": chosen}
    out["comparison"] = rows
    return out


def _cell(v, scale: float, fmt: str, unit: str) -> str:
    return "-" if v is None else f"{fmt.format(v * scale)}{unit}"


def comparison_lines(rows: List[dict], chosen: str) -> List[str]:
    """The side-by-side table ``fjm design`` prints: one line per law, the chosen one marked."""
    head = (f"{'law':<16} {'meets':<5} {'worst RMS':>12} {'jitter':>10} {'at torque limit':>15} "
            f"{'at rate limit':>13} {'diverged':>9}")
    out = [head]
    for r in rows:
        mark = " <- shipped" if r["law"] == chosen else " (compared only)" if r.get("compared") else ""
        out.append(f"{r['law']:<16} {'yes' if r['meets'] else 'no':<5} {_cell(r['rms'], 1e3, '{:.3g}', ' mrad'):>12} "
                   f"{_cell(r['jitter'], 1.0, '{:.3g}', ' N m'):>10} {_cell(r['at_limit'], 100.0, '{:.3g}', ' %'):>15} "
                   f"{_cell(r['at_rate_limit'], 100.0, '{:.3g}', ' %'):>13} {r['diverged']:>4}/{r['runs']:<4}{mark}")
    return out
