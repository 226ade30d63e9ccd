"""The shipped designs made under realistic sensing, one table row each, read from their files.

Each design file ``fjm design`` wrote records its final check and its re-check on fresh draws; a row is
:func:`fjm_runtime.analysis.search.compare.comparison_row` of the record (the same numbers ``fjm design``
prints side by side: worst over both checks) with the conditions the design holds for. Only the files
that record a re-check are listed (the older white-noise ``ismc`` designs do not).
"""
from __future__ import annotations

import json
from importlib import resources
from pathlib import Path
from typing import Iterable, List, Optional

from ..analysis.search.compare import comparison_row

__all__ = ["rechecked_files", "row", "table"]


def rechecked_files() -> List[Path]:
    """The package's shipped design files that record a re-check, by name."""
    folder = resources.files("fjm_runtime.control").joinpath("designed")
    out = []
    for p in sorted(folder.iterdir(), key=lambda p: p.name):
        if p.name.endswith(".json") and json.loads(p.read_text(encoding="utf-8")).get("recheck", {}).get("draws"):
            out.append(Path(str(p)))
    return out


def row(path) -> dict:
    """One design's row: ``file, model, law, interface, sensor, rate, delay, predict_substeps, margin_delay``
    and :func:`comparison_row`'s ``meets, rms, jitter, at_limit, at_rate_limit, diverged, runs``."""
    rec = json.loads(Path(path).read_text(encoding="utf-8"))
    out = {"file": Path(path).name, "model": rec["model"], "law": rec["kind"],
           "interface": (rec.get("interface") or {}).get("name", "motor"),
           "sensor": (rec.get("sensor") or {}).get("name", "?"), "rate": float(rec["rate"]), "delay": int(rec["delay"]),
           "predict_substeps": rec.get("predict_substeps"), "margin_delay": (rec.get("margins") or {}).get("delay")}
    out.update(comparison_row(rec["kind"], rec))
    return out


def _num(v: Optional[float], scale: float = 1.0) -> str:
    return "-" if v is None else f"{v * scale:.3g}"


def table(paths: Optional[Iterable] = None) -> List[str]:
    """Markdown table of :func:`row` for ``paths`` (default :func:`rechecked_files`): RMS in mrad, the
    limits in % of the samples, the runs of the final check and the re-check together."""
    lines = ["| design | model | law | interface | sensor | rate (Hz) | delay | predictor substeps | meets | "
             "worst RMS (mrad) | jitter joints 1-4 (N m) | at torque limit (%) | at rate limit (%) | "
             "diverged / runs | delay margin |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for path in (rechecked_files() if paths is None else paths):
        r = row(path)
        lines.append(f"| `{r['file']}` | {r['model']} | {r['law']} | {r['interface']} | {r['sensor']} | {r['rate']:g} | "
                     f"{r['delay']} | {r['predict_substeps']} | {'yes' if r['meets'] else 'no'} | {_num(r['rms'], 1e3)} | "
                     f"{_num(r['jitter'])} | {_num(r['at_limit'], 100.0)} | {_num(r['at_rate_limit'], 100.0)} | "
                     f"{r['diverged']} / {r['runs']} | {r['margin_delay']} |")
    return lines
