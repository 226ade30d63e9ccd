"""Gains found by ``fjm design`` and shipped with the package (``fjm_runtime/control/designed/*.json``).

A file is named ``<model>_<kind>[_tau]_<rate>hz_d<delay>.json`` (``_tau``: torque sensing) and holds
the design command's report (docs/design-command.md): ``gains`` is what ``fjm simulate --gains``
reads, next to the worst case and margins it was found with.
"""
from __future__ import annotations

import json
import math
from importlib import resources
from typing import List, Optional

__all__ = ["design_mismatches", "designed_file_name", "designed_gains", "find_design", "law_gains"]


def designed_file_name(model: str, kind: str, sensing: str, rate: float, delay: int) -> str:
    """The package-data file name of a design (``panda_ismc_tau_1000hz_d1.json``)."""
    return f"{model}_{kind}{'_tau' if sensing == 'torque' else ''}_{int(round(rate))}hz_d{int(delay)}.json"


def designed_gains(model: str, kind: str, sensing: str, rate: float, delay: int) -> Optional[dict]:
    """The shipped design report for these settings (``{"kind", "gains", ...}``), or ``None``."""
    name = designed_file_name(model, kind, sensing, rate, delay)
    path = resources.files(__package__).joinpath("designed", name)
    if not path.is_file():
        return None
    spec = json.loads(path.read_text(encoding="utf-8"))
    spec["file"] = f"fjm_runtime/control/designed/{name}"
    return spec


def find_design(model: str, kind: Optional[str], sensing: str, rate: float, delay: int) -> Optional[dict]:
    """The shipped design for ``model`` at this rate, delay and sensing, or ``None``.

    ``kind`` None: any controller kind (the first by name when several are shipped); else only
    that kind. The rate must round to the file's integer rate in Hz (``1000.4`` is ``1000``).
    """
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        return None
    if kind is not None:
        return designed_gains(model, kind, sensing, rate, delay)
    folder = resources.files(__package__).joinpath("designed")
    names = sorted(p.name for p in folder.iterdir() if p.name.endswith(".json"))
    for name in names:
        spec_kind = name[len(model) + 1:].split("_")[0] if name.startswith(model + "_") else None
        if spec_kind and name == designed_file_name(model, spec_kind, sensing, rate, delay):
            return designed_gains(model, spec_kind, sensing, rate, delay)
    return None


def design_mismatches(spec: dict, conditions: dict, same_sensor) -> List[str]:
    """Why a design report does NOT hold for a run: one short reason per differing condition.

    Parameters
    ----------
    spec : dict
        A design report (``model``, ``kind``, ``sensing``, ``rate``, ``delay``, ``predict``,
        ``sensor``/``noise``), as written by ``fjm design``.
    conditions : dict
        The run's ``model``, ``kind``, ``sensing``, ``rate`` (Hz), ``delay``, ``predict``, ``sensor``
        (the run's SensorModel).
    same_sensor : callable
        ``same_sensor(spec, sensor) -> (bool, design sensor name)``: whether the run's sensor is the
        design's.

    Returns
    -------
    list of str
        Empty when the design was made for exactly these conditions; a report that records none
        of them gives one reason saying so.
    """
    keys = ("model", "kind", "sensing", "rate", "delay", "predict")
    if not any(k in spec for k in keys):
        return ["the gains file records no design conditions (model, rate, delay, sensing, sensor)"]
    out = []
    for k in keys:
        want, got = spec.get(k), conditions.get(k)
        if want is None:
            out.append(f"the design records no {k}")
        elif k == "rate" and not math.isclose(float(want), float(got), rel_tol=1e-9):
            out.append(f"designed at {float(want):g} Hz, run at {float(got):g} Hz")
        elif k == "delay" and int(want) != int(got):
            out.append(f"designed for a delay of {int(want)} sample(s), run with {int(got)}")
        elif k == "predict" and bool(want) != bool(got):
            out.append(f"designed {'with' if want else 'without'} prediction, run {'with' if got else 'without'}")
        elif k in ("model", "kind", "sensing") and str(want) != str(got):
            out.append(f"designed for {k} {want!r}, run with {got!r}")
    same, name = same_sensor(spec, conditions["sensor"])
    if not same:
        out.append(f"designed with the sensor {name!r}, run with {conditions['sensor'].name!r}")
    return out


def law_gains(spec: dict) -> dict:
    """The law's gains of a design report without its ``u_max`` (a caller sets the arm's own limits)."""
    return {k: v for k, v in spec["gains"].items() if k != "u_max"}
