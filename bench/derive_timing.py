"""Section ``derive``: ``python -m derive`` timed per model, gcc -O2 of planar7.c, op-count growth, and
the check that the committed ``generated/`` is byte for byte what a fresh derive writes."""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from .checks import check
from .generated_tree import differing_files
from .timing import log

__all__ = ["bench_derive", "parse_derive_log"]

REPO = Path(__file__).resolve().parent.parent


def parse_derive_log(text: str) -> dict:
    """Per-model seconds and ops from ``python -m derive``'s progress lines.

    ``[i/N] <model>: deriving ... <s> s (symbolic ..., emit ...), <ops> ops`` and
    ``derived N model(s) in <s> s``.
    """
    import re
    models = {}
    # short models: "[i/N] m: deriving ... 1.2 s (...), k ops"; long ones print stage lines first and
    # end with "[i/N] m: 12.3 s (...), k ops"
    for m in re.finditer(r"\]\s+(\S+):(?: deriving \.\.\.)?\s*([0-9.]+) s \(.*?(\d+) ops", text):
        models[m.group(1)] = {"seconds": float(m.group(2)), "operations": int(m.group(3))}
    tot = re.search(r"derived \d+ model\(s\) in ([0-9.]+) s", text)
    if not models or not tot:
        raise RuntimeError(f"cannot parse the derive log:\n{text[-2000:]}")
    return {"models": models, "total_seconds": float(tot.group(1))}


def bench_derive(work: Path, reps: int, checks: list) -> dict:
    from .ccutil import compile_object
    runs = []
    out = work / "generated"
    timings_file = work / "derive-timings.json"
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    for i in range(reps):
        log(f"derive: run {i + 1}/{reps} (python -m derive --out {out}) ...")
        t0 = time.time()
        proc = subprocess.run([sys.executable, "-m", "derive", "--out", str(out), "--timings", str(timings_file)],
                              cwd=str(REPO), env=env,
                              check=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        wall = time.time() - t0
        data = parse_derive_log(proc.stdout)
        try:  # full-precision timings written by derive --timings
            if timings_file.stat().st_mtime >= t0:
                fresh = json.loads(timings_file.read_text())
                if set(fresh["models"]) == set(data["models"]):
                    data = fresh
        except (OSError, ValueError, KeyError):
            pass
        data["wall_seconds"] = wall
        runs.append(data)
    res = {"total_seconds": statistics.median(r["total_seconds"] for r in runs),
           "wall_seconds": statistics.median(r["wall_seconds"] for r in runs), "repetitions": reps,
           "n_models": len(runs[0]["models"])}
    for name in runs[0]["models"]:
        manifest = json.loads((out / name / "manifest.json").read_text())
        fn_ops = {q: f["operations"] for q, f in manifest["functions"].items()}
        res[name] = {
            "seconds": statistics.median(r["models"][name]["seconds"] for r in runs),
            **{k: statistics.median(r["models"][name][k] for r in runs)
               for k in ("derive_seconds", "emit_seconds") if all(k in r["models"][name] for r in runs)},
            "ops": runs[0]["models"][name]["operations"],
            "ops_by_function": fn_ops,
            "c_bytes": manifest["c_sources"][f"{name}.c"],
        }
    # gcc -O2 of the planar7 C source, same flags as everything else here
    src = out / "planar7" / "planar7.c"
    if src.exists():
        ts = []
        for i in range(reps):
            log(f"gcc -O2 planar7.c: run {i + 1}/{reps} ...")
            ts.append(compile_object(src, work / "planar7_gcc.o"))
        res["planar7"]["gcc_seconds"] = statistics.median(ts)
    # op-count growth exponent over planar3..7 (least-squares slope of log ops vs log n)
    ns = [n for n in range(1, 8) if f"planar{n}" in res]
    if len(ns) >= 3:
        ops = [res[f"planar{n}"]["ops"] for n in ns]
        res["ops_growth_exponent_planar"] = float(np.polyfit(np.log(ns[2:]), np.log(ops[2:]), 1)[0])
        res["ops_growth_exponent_by_function"] = {
            q: float(np.polyfit(np.log(ns[2:]), np.log([max(1, res[f"planar{n}"]["ops_by_function"][q])
                                                         for n in ns[2:]]), 1)[0])
            for q in res[f"planar{ns[-1]}"]["ops_by_function"]}
    # the committed generated/ is what derive produces now, byte for byte (every file)
    bad = differing_files(out, REPO / "generated", runs[0]["models"])
    res["matches_committed_generated"] = not bad
    res["files_differing_from_committed"] = bad
    check(checks, "derive.generated_files",
          "files of generated/ that differ from a fresh `python -m derive`"
          + (f" ({', '.join(bad[:5])}{', ...' if len(bad) > 5 else ''})" if bad else ""),
          len(bad), 0)
    return res
