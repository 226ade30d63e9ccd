"""``fjm sweep MODEL ...``: a Monte Carlo sweep on Dask, one CSV row per run and a JSON summary."""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from ..control.factory import CONTROLLER_KINDS, DEFAULT_LAYER_RATE, default_delta
from ..control.references import REFERENCE_KINDS
from ..validation import FjmValueError
from .common import check_output_file, finite_or_note

#: The absolute stiffness range used when every nominal stiffness lies in it (link1, planar<n>).
ABSOLUTE_K_RANGE = (100.0, 200.0)
#: The relative range used otherwise (factors of each joint's nominal stiffness).
RELATIVE_K_RANGE = (0.7, 1.3)


def add_parser(sub) -> None:
    """Add ``sweep`` to the sub-command set ``sub``."""
    sw = sub.add_parser("sweep", help="Monte Carlo sweep of the closed loop on Dask (chunks of compiled batches)",
                        description="Sample TRUE plants (stiffness uniform in [--k-min, --k-max] or relative to "
                                    "each joint's nominal with --k-rel, link and motor inertias +-20 %), run "
                                    "them in chunks of compiled batch simulations on Dask (a local cluster, or "
                                    "--scheduler ADDRESS), and write one row per run (parameters and metrics) "
                                    "as CSV.")
    sw.add_argument("model", help="model name, e.g. link1 (see `fjm models`)")
    sw.add_argument("--samples", type=int, default=1000, help="number of runs (default 1000)")
    sw.add_argument("--chunk", type=int, default=250, help="runs per Dask task (default 250)")
    sw.add_argument("--seed", type=int, default=0, help="sampling seed (default 0)")
    lo, hi = ABSOLUTE_K_RANGE
    rlo, rhi = RELATIVE_K_RANGE
    sw.add_argument("--k-min", type=float, default=None,
                    help=f"stiffness lower bound, N m/rad (default {lo:g} when every nominal stiffness lies in "
                         f"[{lo:g}, {hi:g}], as on link1 and planar<n>; otherwise the default is --k-rel {rlo:g} {rhi:g})")
    sw.add_argument("--k-max", type=float, default=None, help=f"stiffness upper bound, N m/rad (default {hi:g}, see --k-min)")
    sw.add_argument("--k-rel", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                    help="instead of --k-min/--k-max: every stiffness = its nominal x U[LO, HI] "
                         "(spatial arms, e.g. panda --k-rel 0.7 1.3)")
    sw.add_argument("--controller", default="smc", choices=CONTROLLER_KINDS, help="controller (default smc)")
    sw.add_argument("--lam", type=float, default=8.0, help="pole magnitude lambda, 1/s (default 8)")
    sw.add_argument("--k-s", type=float, default=1000.0, help="switching gain, rad/s^4 (default 1000)")
    sw.add_argument("--delta", type=float, default=None,
                    help=f"boundary layer (default max(k_s, 1) / {DEFAULT_LAYER_RATE:g})")
    sw.add_argument("--reference", default="sine", help=f"one of {', '.join(REFERENCE_KINDS)} (default sine)")
    sw.add_argument("--duration", type=float, default=10.0, help="simulated time, s (default 10)")
    sw.add_argument("--dt", type=float, default=1e-3, help="RK4 step, s (default 1e-3)")
    sw.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="existing dask.distributed scheduler, e.g. tcp://127.0.0.1:8786 (default: local cluster)")
    sw.add_argument("--workers", type=int, default=2, help="workers of the local cluster (default 2)")
    sw.add_argument("--out", type=Path, default=Path("out/sweep.csv"),
                    help="CSV output (default out/sweep.csv; out/ is created if missing, deeper folders are not)")


def stiffness_range(m, k_min, k_max, k_rel):
    """``(k_range, k_relative)`` for :func:`fjm_runtime.batch.sweep.sample_parameters`.

    No bounds given: :data:`ABSOLUTE_K_RANGE` when every nominal stiffness lies in it, else
    :data:`RELATIVE_K_RANGE`. An absolute range given for a model whose nominal stiffnesses lie
    outside :data:`ABSOLUTE_K_RANGE` must contain them (FjmValueError pointing at --k-rel).
    """
    from ..analysis.box import stiffness_names
    nominal = np.array([m.default_params[name] for name in stiffness_names(m)], dtype=float)
    usual = bool(np.all((nominal >= ABSOLUTE_K_RANGE[0]) & (nominal <= ABSOLUTE_K_RANGE[1])))
    if k_rel is not None:
        if k_min is not None or k_max is not None:
            raise FjmValueError("--k-rel and --k-min/--k-max: expected one of them, not both")
        return ABSOLUTE_K_RANGE, tuple(k_rel)
    if k_min is None and k_max is None:
        return (ABSOLUTE_K_RANGE, None) if usual else (ABSOLUTE_K_RANGE, RELATIVE_K_RANGE)
    lo = ABSOLUTE_K_RANGE[0] if k_min is None else k_min
    hi = ABSOLUTE_K_RANGE[1] if k_max is None else k_max
    if not usual and not (lo <= nominal.min() and nominal.max() <= hi):
        raise FjmValueError(f"--k-min/--k-max = {lo:g}/{hi:g} N m/rad: {m.name}'s nominal stiffnesses are "
                            f"{nominal.min():g}..{nominal.max():g}; expected a range containing them, or use "
                            f"--k-rel LO HI (factors of each nominal, e.g. --k-rel 0.7 1.3)")
    return (lo, hi), None


def summary(P, metrics, seconds: float, path) -> dict:
    """The JSON summary of a sweep: counts, the RMS error over the runs that did not diverge, the table path.

    No NaN: statistics over no finite value are None with a ``_note``.
    """
    rms = np.asarray(metrics["rms_error_second_half"], dtype=float)
    ok = np.asarray(metrics["diverged"]) == 0
    finite = rms[np.isfinite(rms)]
    out = {"runs": int(len(P)), "diverged": int((~ok).sum()), "seconds": seconds}
    for name, fn in (("rms_error_second_half_max", np.max), ("rms_error_second_half_median", np.median)):
        if finite.size:
            out[name] = float(fn(finite))
        else:
            finite_or_note(out, name, float("nan"), "every run diverged")
    out["table"] = str(path)
    return out


def run(args) -> int:
    """Run ``fjm sweep``; returns the exit status."""
    from .. import load
    from ..batch.sweep import SweepSpec, sample_parameters, sweep, write_table
    check_output_file(args.out, "--out", make_parent=True)
    m = load(args.model)
    k_range, k_rel = stiffness_range(m, args.k_min, args.k_max, args.k_rel)
    delta = args.delta if args.delta is not None else default_delta(args.k_s)
    options = {"lam": args.lam, "delta": delta}
    if args.controller != "fl":
        options["k_s"] = args.k_s
    spec = SweepSpec(model=args.model, controller=args.controller, controller_options=options,
                     reference=args.reference, duration=args.duration, dt=args.dt)
    P = sample_parameters(m, args.samples, seed=args.seed, k_range=k_range, k_relative=k_rel)
    t0 = time.perf_counter()
    metrics = sweep(spec, P, chunk_size=args.chunk, scheduler=args.scheduler, n_workers=args.workers,
                    progress=lambda d, t: print(f"\rfjm sweep: {d}/{t} chunks", end="", file=sys.stderr,
                                                flush=True))
    print(file=sys.stderr)
    path = write_table(args.out, m, P, metrics)
    print(json.dumps(summary(P, metrics, time.perf_counter() - t0, path), indent=2, allow_nan=False))
    return 0
