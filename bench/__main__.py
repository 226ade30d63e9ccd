"""``python -m bench`` (``make bench``): speed against peers measured in the same run.

Every peer's output is compared with the generated code in the same run
(:data:`bench.checks.TOLERANCES`); ``make bench`` exits 1 when one disagrees, when
``generated/`` differs from a fresh ``python -m derive``, or when a section
fails. A full run writes ``bench/results.json`` (nested; dotted keys like
``derive.planar7.seconds`` resolve through the nesting and are also listed flat
under ``"flat"``) and rewrites the tables between ``<!-- bench:begin -->`` and
``<!-- bench:end -->`` in README.md and bench/README.md from it
(:mod:`bench.report`). ``--quick`` (one repetition per figure) and ``--only``
runs write ``build/bench-results.json`` unless ``--out`` is given, and leave the
READMEs alone.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

from . import report
from .checks import TOLERANCES, check, metric_diff, rel_diff
from .generated_tree import differing_files
from .sections import SECTIONS, plan

# TOLERANCES, check, metric_diff, rel_diff (bench.checks) and differing_files (bench.generated_tree)
# are re-exported: the names ``bench.__main__`` has always had
__all__ = ["DEFAULT_OUT", "TOLERANCES", "check", "differing_files", "exit_status", "flatten", "machine", "main",
           "metric_diff", "parse_args", "rel_diff", "run_sections"]

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
DEFAULT_OUT = HERE / "results.json"


def flatten(d: dict, prefix: str = "") -> dict:
    """The scalars of the nested ``d`` under dotted keys (``results.json["flat"]``)."""
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, key + "."))
        elif isinstance(v, (int, float, bool, str)) or v is None:
            out[key] = v
    return out


def machine() -> dict:
    """Python, CPU, vector ISA and the load average at the start (``results.json["machine"]``)."""
    info = {"python": platform.python_version(), "cpu_count": os.cpu_count(),
            "platform": platform.platform(), "processor": platform.processor()}
    try:
        with open("/proc/cpuinfo") as fh:
            info["cpu_model"] = next((ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")),
                                     platform.processor())
    except OSError:
        info["cpu_model"] = platform.processor()
    try:
        from fjm_runtime.batch.simd import vector_isa
        info["simd_isa"] = vector_isa()[0]
    except Exception:  # noqa: BLE001 - informative only
        info["simd_isa"] = "unknown"
    try:
        info["load_average_start"] = os.getloadavg()[0]
    except OSError:
        info["load_average_start"] = float("nan")
    return info


def parse_args(argv=None) -> argparse.Namespace:
    """The command line (``--quick``, ``--skip-derive``, ``--only``, ``--out``)."""
    ap = argparse.ArgumentParser(prog="python -m bench", description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="one repetition per figure (smoke test / checks)")
    ap.add_argument("--skip-derive", action="store_true", help="skip the derive and gcc timings")
    ap.add_argument("--only", nargs="+", choices=SECTIONS, help="run only these sections")
    ap.add_argument("--out", type=Path, default=None,
                    help="results file (default: bench/results.json for a full run, "
                         "build/bench-results.json otherwise)")
    return ap.parse_args(argv)


def run_sections(sections: set, quick: bool, results: dict, checks: list) -> list:
    """Run the chosen sections in table order into ``results``; the names of those that raised."""
    failed = []
    with tempfile.TemporaryDirectory(prefix="fjm-bench-") as tmp:
        work = Path(tmp)
        os.environ.setdefault("FJM_CACHE", str(work / "cache"))  # cold, private compile cache
        for name, run in plan(work, quick, checks, results):
            if name not in sections:
                continue
            try:
                results[name] = run()
            except Exception as exc:  # noqa: BLE001 - report, keep measuring the rest
                import traceback
                traceback.print_exc()
                results[name] = {"error": f"{type(exc).__name__}: {exc}"}
                failed.append(name)
    return failed


def exit_status(checks: list, failed: list) -> int:
    """1 (and why, on stderr) if a peer check disagrees or a section raised, else 0."""
    bad = [c for c in checks if not c["ok"]]
    status = 0
    if bad:
        print(f"\nFAILED: {len(bad)} of {len(checks)} peer checks disagree with the generated code:", file=sys.stderr)
        for c in bad:
            print(f"  {c['key']}: {c['what']}: {c['measured']:.3g} > tolerance {c['tolerance']:.3g}",
                  file=sys.stderr)
        status = 1
    if failed:
        print(f"sections that failed: {', '.join(failed)} (see the traceback above)", file=sys.stderr)
        status = 1
    if not status:
        print(f"all {len(checks)} peer checks agree with the generated code")
    return status


def main(argv=None) -> int:
    """``python -m bench``: run, write the results file (the READMEs after a full run), exit status."""
    args = parse_args(argv)
    sections = set(args.only or SECTIONS)
    if args.skip_derive:
        sections.discard("derive")
    full = not args.quick and len(sections) == len(SECTIONS)
    out = args.out or (DEFAULT_OUT if full else REPO / "build" / "bench-results.json")
    t_start = time.perf_counter()
    results = {"machine": machine(), "quick": bool(args.quick)}
    checks: list = []
    failed = run_sections(sections, bool(args.quick), results, checks)
    results["bench_seconds"] = time.perf_counter() - t_start
    results["finished_utc"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    results["checks"] = checks
    results["tolerances"] = dict(TOLERANCES)
    results["flat"] = flatten({k: v for k, v in results.items()
                               if k not in ("machine", "checks", "tolerances", "quick", "finished_utc")})
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2, sort_keys=True) + "\n")
    print(report.render_bench_readme(results))
    print(f"\nwrote {out} in {results['bench_seconds']:.0f} s")
    if out.resolve() == DEFAULT_OUT.resolve():
        for path in report.write_all(results):
            print(f"rewrote the bench tables in {path}")
    return exit_status(checks, failed)


if __name__ == "__main__":
    sys.exit(main())
