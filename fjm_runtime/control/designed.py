"""Gains found by ``fjm design`` and shipped with the package (``fjm_runtime/control/designed/*.json``).

A file is named ``<model>_<kind>[_tau]_<rate>hz_d<delay>.json`` (``_tau``: torque sensing) and holds
the design command's report (docs/design-command.md): ``gains`` is what ``fjm simulate --gains``
reads, next to the worst case and margins it was found with.
"""
from __future__ import annotations

import json
from importlib import resources
from typing import Optional

__all__ = ["designed_file_name", "designed_gains", "law_gains"]


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


def law_gains(spec: dict) -> dict:
    """The law's gains of a design report without its ``u_max`` (a caller sets the arm's own limits)."""
    return {k: v for k, v in spec["gains"].items() if k != "u_max"}
