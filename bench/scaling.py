"""The scaling section of ``make bench``: derive synthetic chains of growing length, fit the growth.

For each n in :data:`SIZES` the bench writes a synthetic spatial chain
(:mod:`derive.guard.synthetic`), runs ``python -m derive --model-file ... --no-cost-limit``
in a fresh process and records

* ``derive_seconds``: the wall clock of the whole command;
* ``peak_bytes``: the largest resident set of that process and its children
  (``os.wait4`` in :mod:`bench.peak_rss`, the same number ``/usr/bin/time -v`` prints);
* ``alpha_beta_ops``: operations after CSE of alpha and beta in one call, ``control_core``
  (``T``, ``alpha``, ``beta``, what every law calls; manifest);
* ``alpha_plus_beta_ops``: operations of ``alpha`` plus those of ``beta``, two Functions;
* ``all_ops``: operations of every model quantity (``f, g, ad, T, alpha, beta, energy, inertia``);
* ``ad_ops``: operations of the bracket matrix;
* ``c_bytes``: size of the shipped ``<model>.c`` (every function, the control laws included);
* ``gcc_seconds``: ``gcc -O2 -c`` of that file (:data:`bench.ccutil.CFLAGS`), within
  :data:`GCC_TIMEOUT` (None and ``gcc_timed_out`` if it did not finish: the target counts as missed).

Each quantity gets a fitted power law ``c n^e`` (least squares on log-log axes) and
the run is compared with the :data:`TARGETS`.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional, Sequence

HERE = Path(__file__).resolve().parent
REPO = HERE.parent

#: Chain lengths measured.
SIZES = (7, 14, 21, 30)
#: Seconds allowed for one gcc -O2 of a generated C file before it is recorded as not finished.
GCC_TIMEOUT = 300.0
QUANTITIES = ("derive_seconds", "peak_bytes", "alpha_beta_ops", "alpha_plus_beta_ops", "ad_ops", "all_ops", "c_bytes",
              "gcc_seconds")

#: ``(n, quantity, limit)``: the run meets a target when the measured value is at most the limit.
TARGETS = (
    (21, "derive_seconds", 10.0),
    (21, "peak_bytes", 500e6),
    (21, "alpha_beta_ops", 30e3),
    (21, "c_bytes", 2e6),
    (21, "gcc_seconds", 60.0),
    (30, "derive_seconds", 60.0),
    (30, "peak_bytes", 1e9),
)


def run_measured(cmd: Sequence[str], cwd: Path, env: Dict[str, str]) -> Dict[str, object]:
    """Run ``cmd``; returns ``{"seconds", "peak_bytes", "returncode", "stdout", "stderr"}``.

    The peak is ``ru_maxrss`` of ``os.wait4`` on the process: the largest resident set of
    the process and of every descendant it waited for (the derivation's forked child). It is
    taken by :mod:`bench.peak_rss`, a small process that forks ``cmd``: forked from the bench
    itself, ``cmd`` would start from the bench's high-water mark (Linux keeps ``ru_maxrss``
    across ``exec``), and the small chains would all read the bench's own resident set.
    """
    import tempfile
    with tempfile.TemporaryFile("w+") as fo, tempfile.TemporaryFile("w+") as fe, \
            tempfile.TemporaryDirectory(prefix="fjm-peak-") as tmp:
        peak_file = Path(tmp) / "peak"
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-S", str(HERE / "peak_rss.py"), str(peak_file), *cmd],
                              cwd=str(cwd), env=env, stdout=fo, stderr=fe, text=True)
        seconds = time.perf_counter() - t0
        fo.seek(0)
        fe.seek(0)
        out, err = fo.read(), fe.read()
        peak = int(peak_file.read_text()) if peak_file.exists() else None
    return {"seconds": seconds, "peak_bytes": peak, "returncode": proc.returncode, "stdout": out, "stderr": err}


def measure_chain(n: int, work: Path, compile_c: bool = True) -> Dict[str, Optional[float]]:
    """Derive the synthetic ``n``-joint chain into ``work`` and measure it (see the module docstring)."""
    from derive.guard.synthetic import write_synthetic_chain

    toml, _ = write_synthetic_chain(n, work / f"model{n}")
    out = work / f"out{n}"
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    run = run_measured([sys.executable, "-m", "derive", "--model-file", str(toml), "--out", str(out),
                        "--no-cost-limit"], REPO, env)
    if run["returncode"] != 0:
        raise RuntimeError(f"derive of the {n}-joint chain failed:\n{run['stdout'][-2000:]}\n{run['stderr'][-2000:]}")
    name = f"chain{n}"
    manifest = json.loads((out / name / "manifest.json").read_text())
    ops = {q: f["operations"] for q, f in manifest["functions"].items()}
    src = out / name / f"{name}.c"
    gcc, timed_out = None, False
    if compile_c:
        try:
            gcc = _timed_compile(src, work / f"{name}.o")
        except subprocess.TimeoutExpired:
            timed_out = True
    return {"n": n, "derive_seconds": run["seconds"], "peak_bytes": run["peak_bytes"],
            "alpha_beta_ops": manifest["control_core"]["operations"], "alpha_plus_beta_ops": ops["alpha"] + ops["beta"],
            "ad_ops": ops["ad"], "all_ops": sum(ops.values()),
            "ops_by_function": ops, "c_bytes": src.stat().st_size, "gcc_seconds": gcc,
            "gcc_timed_out": timed_out}


def _timed_compile(src: Path, obj: Path) -> float:
    """gcc -O2 of ``src`` within :data:`GCC_TIMEOUT` (raises ``subprocess.TimeoutExpired``)."""
    from .ccutil import CFLAGS, cc
    t0 = time.perf_counter()
    subprocess.run([cc(), *CFLAGS, "-c", str(src), "-o", str(obj)], check=True, timeout=GCC_TIMEOUT,
                   stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    return time.perf_counter() - t0


def fit_exponents(runs: List[Dict[str, object]]) -> Dict[str, Dict[str, float]]:
    """Per quantity, ``{"c", "e"}`` of ``value = c n^e`` over the runs that have a value."""
    from derive.guard.cost import fit_power_law
    fits = {}
    for q in QUANTITIES:
        pts = [(r["n"], r[q]) for r in runs if r.get(q)]
        if len(pts) >= 2:
            c, e = fit_power_law([p[0] for p in pts], [p[1] for p in pts])
            fits[q] = {"c": c, "e": e}
    return fits


def target_rows(runs: List[Dict[str, object]], panda: Optional[Dict[str, float]] = None) -> List[Dict[str, object]]:
    """Every target with the measured value and ``ok`` (None when not measured)."""
    by_n = {r["n"]: r for r in runs}
    rows = []
    for n, q, limit in TARGETS:
        v = by_n.get(n, {}).get(q)
        if v is None and q == "gcc_seconds" and by_n.get(n, {}).get("gcc_timed_out"):
            rows.append({"what": f"n = {n} {q}", "limit": limit, "measured": f"> {GCC_TIMEOUT:g} (stopped)",
                         "ok": False})
            continue
        rows.append({"what": f"n = {n} {q}", "limit": limit, "measured": v,
                     "ok": None if v is None else bool(v <= limit)})
    for key, limit in (("alpha_beta_ops", 5000.0), ("alpha_beta_us", 1.0)):
        v = (panda or {}).get(key)
        rows.append({"what": f"panda {key}", "limit": limit, "measured": v,
                     "ok": None if v is None else bool(v <= limit)})
    return rows


def panda_numbers(spatial: Optional[dict]) -> Dict[str, Optional[float]]:
    """The Panda's alpha + beta operations in one call (``control_core``, generated/ manifest) and us per call
    (the spatial section's one-call figure)."""
    manifest = json.loads((REPO / "generated" / "panda" / "manifest.json").read_text())
    ops = manifest["control_core"]["operations"]
    spatial = spatial or {}
    return {"alpha_beta_ops": ops, "alpha_beta_us": spatial.get("generated_us"),
            "adam_peer_us": spatial.get("peer_us")}


def bench_scaling(work: Path, sizes: Sequence[int] = SIZES, spatial: Optional[dict] = None,
                  log=print) -> dict:
    """The scaling section: one derive per size, fitted exponents, targets.

    Returns
    -------
    dict
        ``runs`` (one dict per n), ``fits`` (quantity -> c, e), ``panda``, ``targets``.
    """
    work.mkdir(parents=True, exist_ok=True)
    runs = []
    for n in sizes:
        log(f"scaling: python -m derive of a synthetic {n}-joint chain, then gcc -O2 of its C ...")
        runs.append(measure_chain(n, work))
        log("scaling: " + json.dumps({k: v for k, v in runs[-1].items() if k != "ops_by_function"}))
    panda = panda_numbers(spatial)
    return {"runs": runs, "fits": fit_exponents(runs), "panda": panda, "targets": target_rows(runs, panda)}


def main(argv=None) -> int:
    """``python -m bench.scaling [N ...]``: the section alone, JSON on stdout."""
    import tempfile
    sizes = [int(a) for a in (argv if argv is not None else sys.argv[1:])] or list(SIZES)
    with tempfile.TemporaryDirectory(prefix="fjm-scaling-") as tmp:
        res = bench_scaling(Path(tmp), sizes, log=lambda m: print(m, file=sys.stderr, flush=True))
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    sys.exit(main())
