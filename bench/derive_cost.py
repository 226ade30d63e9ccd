"""``python -m bench.derive_cost``: measure ``python -m derive`` on synthetic chains, fit the cost model.

For each size n it writes a synthetic URDF chain (:mod:`derive.guard.synthetic`) or
picks the built-in ``planar<n>``, runs ``python -m derive ... --out TMP --no-cost-limit``
in a fresh process (:func:`bench.scaling.run_measured`), and records the
wall-clock seconds, the peak resident memory and the operation count (all
generated functions, from ``--timings``). It then fits ``value = c n^e`` by
least squares on log-log axes per quantity and prints the measurements and
the fitted coefficients as JSON, ready to be copied into
:data:`derive.guard.cost.CALIBRATION` (which states the run they come from).

``--repo DIR`` measures another checkout's derive (e.g. a clean
``git archive HEAD`` export), using this checkout's synthetic chains.
``--compare`` prints, beside each measurement, the estimate of the current
:mod:`derive.guard.cost` model (the accuracy of the guard). ``--keep-base`` fits over the stored
trivial derive of :data:`derive.guard.cost.CALIBRATION` instead of this run's (re-measuring one form
while keeping the other form's stored fit, which is relative to that base).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Dict, List

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

from derive.guard.cost import CALIBRATION, estimate, fit_power_law  # noqa: E402
from derive.guard.synthetic import write_synthetic_chain  # noqa: E402
from bench.scaling import run_measured  # noqa: E402


def measure(n: int, form: str, repo: Path, python: str, guard_flag: bool) -> Dict[str, float]:
    """One derive of an n-joint chain (``form``: "spatial" or "planar") in a fresh process."""
    with tempfile.TemporaryDirectory(prefix="fjm-cost-") as tmp:
        tmp = Path(tmp)
        if form == "spatial":
            toml, _ = write_synthetic_chain(n, tmp / "model")
            what = ["--model-file", str(toml)]
        else:
            what = ["--models", f"planar{n}"]
        timings = tmp / "timings.json"
        cmd = [python, "-m", "derive", *what, "--out", str(tmp / "out"),
               "--timings", str(timings)] + (["--no-cost-limit"] if guard_flag else [])
        run = run_measured(cmd, repo, None)
        if run["returncode"] != 0:
            raise RuntimeError(f"derive of n = {n} ({form}) failed:\n{run['stdout']}\n{run['stderr']}")
        ops = sum(m["operations"] for m in json.loads(timings.read_text())["models"].values())
    return {"n": n, "form": form, "seconds": run["seconds"], "peak_bytes": run["peak_bytes"], "operations": ops}


def main(argv: List[str] = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.derive_cost", description=__doc__.split("\n\n")[0])
    # the sizes where a guard matters: growth steepens with n, and a fit over small chains under-estimates big ones
    ap.add_argument("--spatial", type=int, nargs="*", default=[14, 21, 30, 45, 60], metavar="N")
    ap.add_argument("--planar", type=int, nargs="*", default=[2, 3, 4, 5, 6, 7], metavar="N")
    ap.add_argument("--repo", type=Path, default=REPO, help="checkout whose `python -m derive` is measured")
    ap.add_argument("--python", default=sys.executable)
    ap.add_argument("--old-cli", action="store_true", help="the measured derive has no --no-cost-limit flag")
    ap.add_argument("--compare", action="store_true", help="print the current estimate beside each run")
    ap.add_argument("--keep-base", action="store_true",
                    help="fit over the stored trivial derive (derive.guard.cost.CALIBRATION) instead of this run's")
    args = ap.parse_args(argv)
    base = measure(1, "planar", args.repo.resolve(), args.python, not args.old_cli)
    print(json.dumps({"baseline": base}), file=sys.stderr, flush=True)
    runs = []
    for form, sizes in (("spatial", args.spatial), ("planar", args.planar)):
        for n in sizes:
            run = measure(n, form, args.repo.resolve(), args.python, not args.old_cli)
            if args.compare:
                est = estimate(n, form)
                run["estimate"] = {"seconds": est.seconds, "peak_bytes": est.peak_bytes,
                                   "operations": est.operations}
            print(json.dumps(run), file=sys.stderr, flush=True)
            runs.append(run)
    fits = {}
    for form in ("spatial", "planar"):
        sub = [r for r in runs if r["form"] == form]
        if len(sub) >= 2:
            ref = ({"peak_bytes": CALIBRATION["base_bytes"], "seconds": CALIBRATION["base_seconds"]}
                   if args.keep_base else base)
            offsets = {"operations": 0.0, "peak_bytes": ref["peak_bytes"], "seconds": ref["seconds"]}
            fits[form] = {q: fit_power_law([r["n"] for r in sub], [r[q] for r in sub], offsets[q])
                          for q in offsets}
    print(json.dumps({"baseline": base, "runs": runs, "fits": fits}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
