"""``fjm design`` on the Panda at 1 kHz, delay 2, the ``franka_like`` sensor: wall time and compiler memory.

The issue's targets: within 10 minutes on a cold C cache and 4 minutes warm (2 cores), no compiler
process above 1.5 GB resident. The command runs twice as a user runs it (``python -m fjm_runtime.cli
design ...``, a process of its own): first with an empty ``$FJM_CACHE`` (every C build of the
search, the final check and the delay margins up to ``d + 3``), then again with that cache (warm).
Every compiler process is started through a wrapper (``$CC``) that records its peak resident set
(:mod:`bench.peak_rss`), so the compiler's memory is measured apart from the design process's own.
"""
from __future__ import annotations

import json
import os
import stat
import sys
from pathlib import Path

from .scaling import HERE, run_measured

REPO = HERE.parent
ARGS = ["panda", "--rate", "1000", "--delay-samples", "2", "--predict", "--noise", "franka_like"]
TARGETS = {"cold_seconds": 600.0, "warm_seconds": 240.0, "compiler_peak_gb": 1.5}


def _compiler_wrapper(work: Path) -> Path:
    """A ``$CC`` that runs gcc under :mod:`bench.peak_rss`, one peak file per compiler process."""
    peaks = work / "cc-peaks"
    peaks.mkdir(parents=True, exist_ok=True)
    gcc = os.environ.get("CC") or "gcc"
    script = work / "cc"
    script.write_text("#!/bin/sh\n"
                      f'exec "{sys.executable}" -S "{HERE / "peak_rss.py"}" "{peaks}/$$.peak" "{gcc}" "$@"\n')
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return script


def _compiler_peak(work: Path) -> float:
    files = list((work / "cc-peaks").glob("*.peak"))
    return max((int(f.read_text()) for f in files), default=0) / 1e9


def bench_design(work: Path, log=print) -> dict:
    """Run ``fjm design`` cold then warm; the section's results (seconds, peaks, outcome, targets)."""
    work.mkdir(parents=True, exist_ok=True)
    cc = _compiler_wrapper(work)
    env = dict(os.environ, FJM_CACHE=str(work / "cache"), CC=str(cc))
    out: dict = {"command": "fjm design " + " ".join(ARGS), "targets": dict(TARGETS)}
    for label in ("cold", "warm"):
        for f in (work / "cc-peaks").glob("*.peak"):
            f.unlink()
        gains = work / f"design-{label}.json"
        log(f"design: {label} run of fjm design {' '.join(ARGS)}")
        r = run_measured([sys.executable, "-m", "fjm_runtime.cli", "design", *ARGS, "--out", str(gains)], REPO, env)
        out[f"{label}_seconds"] = r["seconds"]
        out[f"{label}_process_peak_gb"] = (r["peak_bytes"] or 0) / 1e9
        out[f"{label}_compiler_peak_gb"] = _compiler_peak(work)
        out[f"{label}_compiler_processes"] = len(list((work / "cc-peaks").glob("*.peak")))
        out[f"{label}_returncode"] = r["returncode"]
        if gains.exists():
            spec = json.loads(gains.read_text())
            out[f"{label}_meets"] = spec.get("meets")
            out[f"{label}_misses"] = spec.get("misses")
        else:
            out[f"{label}_error"] = r["stderr"][-2000:]
    out["compiler_peak_gb"] = max(out["cold_compiler_peak_gb"], out["warm_compiler_peak_gb"])
    out["met"] = {"cold_seconds": out["cold_seconds"] <= TARGETS["cold_seconds"],
                  "warm_seconds": out["warm_seconds"] <= TARGETS["warm_seconds"],
                  "compiler_peak_gb": out["compiler_peak_gb"] <= TARGETS["compiler_peak_gb"]}
    return out
