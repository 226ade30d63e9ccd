"""Command line: ``fjm simulate ...``, ``fjm figures ...`` (``python -m fjm_runtime.cli``).

Examples
--------
``fjm simulate link1 --K 120 --reference sine --duration 10 --plot out/run.png``
``fjm simulate planar2 --controller ismc --param K1=120 --param K2=180 --reference sine``
``fjm figures --out out`` (``--quick``: a fast smoke run of the same pipeline)
``fjm sweep link1 --samples 1000 --chunk 250 --out out/sweep.csv`` (Dask; ``--scheduler ADDRESS``)
``fjm derive --model-file arm.toml --out DIR`` (needs ``pip install '.[derive]'``)
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from ..control.factory import CONTROLLER_KINDS, default_delta, make_controller
from ..control.laws import coefficients_from_pole
from ..control.references import REFERENCE_KINDS, make_reference
from ..sim.simulate import SimulationDivergedError, simulate, stderr_progress


def _parse_assignments(items: List[str], flag: str) -> Dict[str, float]:
    out: Dict[str, float] = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ValueError(f"{flag} {item!r}: expected NAME=VALUE, e.g. {flag} K=120")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise ValueError(f"{flag} {item!r}: VALUE {value!r} is not a number") from None
    return out


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fjm", description="Flexible-joint manipulators: feedback linearization + sliding-mode control.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    sim = sub.add_parser("simulate", help="simulate one closed loop and print its metrics",
                         description="Simulate one closed loop (true plant vs nominal controller) and print "
                                     "metrics as JSON. Plant parameters: --K / --param; the controller uses "
                                     "the model defaults unless --nominal is given.")
    sim.add_argument("model", help="model name, e.g. link1, planar2")
    sim.add_argument("--controller", default="smc", choices=CONTROLLER_KINDS,
                     help="smc: paper's law with sat; sign: paper's discontinuous law; ismc: integral "
                          "sliding surface; fl: plain feedback linearization; adaptive: integral surface "
                          "with an online stiffness estimate projected onto [--k-min, --k-max] "
                          "(default smc)")
    sim.add_argument("--reference", default="sine", help=f"one of {', '.join(REFERENCE_KINDS)} (default sine)")
    sim.add_argument("--q-d", type=float, default=1.0, help="set point for step/constant, rad (default 1)")
    sim.add_argument("--rise-time", type=float, default=2.0, help="smooth step duration, s (default 2)")
    sim.add_argument("--amplitude", type=float, default=0.5, help="sine amplitude, rad (default 0.5)")
    sim.add_argument("--omega", type=float, default=1.0, help="sine frequency, rad/s (default 1)")
    sim.add_argument("--duration", type=float, default=10.0, help="simulated time, s (default 10)")
    sim.add_argument("--dt", type=float, default=1e-3, help="RK4 step and control period, s (default 1e-3)")
    sim.add_argument("--K", type=float, default=None,
                     help="TRUE joint stiffness of the plant, N m/rad (link1: K; planar<n>: every K_i)")
    sim.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                     help="TRUE plant parameter (repeatable), e.g. --param J_l=1.2")
    sim.add_argument("--nominal", action="append", default=[], metavar="NAME=VALUE",
                     help="NOMINAL controller parameter (repeatable); default: model defaults")
    sim.add_argument("--lam", type=float, default=8.0, help="pole magnitude lambda, 1/s (default 8)")
    sim.add_argument("--k-s", type=float, default=None,
                     help="switching gain, rad/s^4 (default: Lemma 1 bound for link1 with K in "
                          "[--k-min, --k-max]; 1000 otherwise)")
    sim.add_argument("--delta", type=float, default=None, help="boundary layer (default k_s / 200)")
    sim.add_argument("--k-min", type=float, default=100.0, help="stiffness lower bound for Lemma 1 (default 100)")
    sim.add_argument("--k-max", type=float, default=200.0, help="stiffness upper bound for Lemma 1 (default 200)")
    sim.add_argument("--beta-hat", choices=("paper", "model"), default="paper",
                     help="link1: paper's constant (beta_max + beta_min)/2 or beta(x; nominal) (default paper)")
    sim.add_argument("--u-max", type=float, default=None, help="torque limit, N m (default none)")
    sim.add_argument("--plot", type=Path, default=None, help="write a PNG of angles, error, torque and s")
    sim.add_argument("--quiet", action="store_true", help="no progress on stderr")

    # `fjm derive ...` is handed to `python -m derive` as is (see main); listed here for --help.
    sub.add_parser("derive", add_help=False,
                   help="derive and emit models (needs .[derive]); --out DIR, default generated/ only in "
                        "a source checkout; see `fjm derive --help`")

    sw = sub.add_parser("sweep", help="Monte Carlo sweep of the closed loop on Dask (chunks of compiled batches)",
                        description="Sample TRUE plants (stiffness uniform in [--k-min, --k-max], link and "
                                    "motor inertias +-20 %%), run them in chunks of compiled batch "
                                    "simulations on Dask (a local cluster, or --scheduler ADDRESS), and "
                                    "write one row per run (parameters and metrics) as CSV.")
    sw.add_argument("model", help="model name, e.g. link1")
    sw.add_argument("--samples", type=int, default=1000, help="number of runs (default 1000)")
    sw.add_argument("--chunk", type=int, default=250, help="runs per Dask task (default 250)")
    sw.add_argument("--seed", type=int, default=0, help="sampling seed (default 0)")
    sw.add_argument("--k-min", type=float, default=100.0, help="stiffness lower bound, N m/rad (default 100)")
    sw.add_argument("--k-max", type=float, default=200.0, help="stiffness upper bound, N m/rad (default 200)")
    sw.add_argument("--k-rel", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                    help="instead of --k-min/--k-max: every stiffness = its default x U[LO, HI] "
                         "(spatial arms, e.g. panda --k-rel 0.7 1.3)")
    sw.add_argument("--controller", default="smc", choices=CONTROLLER_KINDS, help="controller (default smc)")
    sw.add_argument("--lam", type=float, default=8.0, help="pole magnitude lambda, 1/s (default 8)")
    sw.add_argument("--k-s", type=float, default=1000.0, help="switching gain, rad/s^4 (default 1000)")
    sw.add_argument("--delta", type=float, default=None, help="boundary layer (default k_s / 200)")
    sw.add_argument("--reference", default="sine", help=f"one of {', '.join(REFERENCE_KINDS)} (default sine)")
    sw.add_argument("--duration", type=float, default=10.0, help="simulated time, s (default 10)")
    sw.add_argument("--dt", type=float, default=1e-3, help="RK4 step, s (default 1e-3)")
    sw.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="existing dask.distributed scheduler, e.g. tcp://127.0.0.1:8786 (default: local cluster)")
    sw.add_argument("--workers", type=int, default=2, help="workers of the local cluster (default 2)")
    sw.add_argument("--out", type=Path, default=Path("out/sweep.csv"), help="CSV output (default out/sweep.csv)")

    fig = sub.add_parser("figures", help="reproduce the paper's figures and the comparisons (make demo)")
    fig.add_argument("--out", type=Path, default=Path("out"), help="output directory (default out)")
    fig.add_argument("--samples", type=int, default=40, help="Monte Carlo samples (default 40)")
    fig.add_argument("--quick", action="store_true",
                     help="smoke test: 1 s runs and at most 2 Monte Carlo samples; still writes every "
                          "figure and summary.md (not the documented numbers)")

    from .tune import add_parser as add_tune_parser
    add_tune_parser(sub)
    return parser


def _cmd_simulate(args) -> int:
    from .. import load
    from ..analysis.lemma1 import beta_bounds_link1, lemma1_gain
    m = load(args.model)
    n = m.n
    true = _parse_assignments(args.param, "--param")
    if args.K is not None:
        if m.name == "link1" or "K" in m.param_names:
            true.setdefault("K", args.K)
        else:
            for i in range(n):
                true.setdefault(f"K{i + 1}", args.K)
    nominal = _parse_assignments(args.nominal, "--nominal")
    ref_kw = {"sine": {"amplitude": args.amplitude, "omega": args.omega},
              "step": {"q_d": args.q_d, "rise_time": args.rise_time},
              "constant": {"q_d": args.q_d}}.get(args.reference, {})
    ref = make_reference(args.reference, n, **ref_kw)
    is_link1 = tuple(m.param_names) == ("J_l", "J_m", "K", "M", "g0", "L", "B_m")
    extra: Dict[str, object] = {}
    gain = None
    if is_link1 and args.beta_hat == "paper":
        if not (0 < args.k_min <= args.k_max):
            raise ValueError(f"--k-min/--k-max = {args.k_min}/{args.k_max}: expected 0 < k_min <= k_max")
        bounds = {"K": (args.k_min, args.k_max)}
        extra["beta_hat"] = beta_bounds_link1(nominal, bounds)[2]
    k_s = args.k_s
    if k_s is None:
        if is_link1:
            E = (0.05, args.amplitude * args.omega, 0.5, 0.5) if args.reference == "sine" else (0.05, 0.1, 0.5, 1.0)
            gain = lemma1_gain(coefficients_from_pole(args.lam), ref.derivative_bounds()[:, 0], nominal=nominal,
                               bounds={"K": (args.k_min, args.k_max)}, error_bounds=E)
            k_s = gain.k_s
        else:
            k_s = 1000.0
    delta = args.delta if args.delta is not None else default_delta(k_s)
    if args.controller == "adaptive":
        # beta from the estimated stiffness (not the paper's constant); the bounds project K_hat
        extra.pop("beta_hat", None)
        if not (0 < args.k_min < args.k_max):
            raise ValueError(f"--k-min/--k-max = {args.k_min}/{args.k_max}: expected 0 < k_min < k_max "
                             "for the adaptive controller")
        extra["K_bounds"] = (args.k_min, args.k_max)
    ctrl = make_controller(args.controller, m, nominal, lam=args.lam, k_s=k_s, delta=delta,
                           u_max=args.u_max, **extra)
    progress = None if args.quiet else stderr_progress(f"simulating {args.model} ({args.duration:g} s)")
    try:
        res = simulate(m, ctrl, ref, duration=args.duration, dt=args.dt, true_params=true, progress=progress)
    except SimulationDivergedError as exc:
        print(f"fjm: {exc}", file=sys.stderr)
        return 3
    report = {"model": m.name, "controller": args.controller, "reference": args.reference,
              "true_params": dict(zip(m.param_names, m.params_array(true).tolist())),
              "nominal_params": dict(zip(m.param_names, m.params_array(nominal).tolist())),
              "lam": args.lam, "k_s": k_s, "delta": delta,
              "lemma1": None if gain is None else {"k_s": gain.k_s, "k_s_tight": gain.k_s_tight, "W": gain.W,
                                                   "H": gain.H, "beta_hat": gain.beta_hat},
              "metrics": {k: (v if np.isfinite(v) else str(v)) for k, v in res.metrics.as_dict().items()}}
    if hasattr(ctrl, "stiffness_estimate"):
        report["K_hat_final"] = ctrl.stiffness_estimate(res.z[-1]).tolist()
    print(json.dumps(report, indent=2))
    if args.plot is not None:
        _plot_run(res, args, args.plot)
        print(f"wrote {args.plot}", file=sys.stderr)
    return 0


def _plot_run(res, args, path: Path) -> None:
    from ..experiments.paper import _plt
    plt = _plt()
    n = res.e1.shape[1]
    fig, ax = plt.subplots(2, 2, figsize=(12, 7.5), sharex=True)
    for i in range(n):
        sfx = f" (joint {i + 1})" if n > 1 else ""
        line, = ax[0, 0].plot(res.t, res.x[:, i], lw=1.5, label=f"link $q_l${sfx}")
        ax[0, 0].plot(res.t, res.x[:, 2 * n + i], ls="--", lw=1.0, color=line.get_color(), label=f"motor $q_m${sfx}")
        ax[0, 0].plot(res.t, res.ref[:, 0, i], ls=":", color="k", lw=1.0, label=f"reference{sfx}")
        ax[0, 1].plot(res.t, res.e1[:, i], label=f"$e_1${sfx}")
        ax[1, 0].plot(res.t, res.u[:, i], label=f"u{sfx}")
        ax[1, 1].plot(res.t, res.s[:, i], label=f"s{sfx}")
    d = float(np.max(res.delta))
    if np.isfinite(d):
        ax[1, 1].axhspan(-d, d, color="0.85", zorder=0, label=rf"$|s| \leq \delta$ = {d:.2f}")
    late = res.t > 0.5 * res.t[-1] * 0.1
    lim = max(5 * d if np.isfinite(d) else 0, 1.2 * float(np.max(np.abs(res.s[late]))))
    ax[1, 1].set_ylim(-lim, lim)
    ax[0, 0].set(title="Angles", ylabel="rad")
    ax[0, 1].set(title=r"Link position error $e_1 = q_l - q_d$", ylabel="rad")
    ax[1, 0].set(title="Control torque", ylabel="N m", xlabel="time (s)")
    ax[1, 1].set(title="Sliding variable", ylabel=r"rad/s$^3$", xlabel="time (s)")
    for a in ax.flat:
        a.legend(loc="best", fontsize=8)
    mt = res.metrics
    fig.suptitle(f"{args.model}, {args.controller}, reference {args.reference}: final |e1| = {mt.final_error:.3g} rad, "
                 f"RMS = {mt.rms_error:.3g} rad, max |u| = {mt.max_abs_u:.3g} N m", fontsize=11)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _cmd_sweep(args) -> int:
    """``fjm sweep``: sample, run on Dask, write the CSV table and a one-line summary."""
    import time
    from .. import load
    from ..batch.sweep import SweepSpec, sample_parameters, sweep, write_table
    m = load(args.model)
    delta = args.delta if args.delta is not None else default_delta(args.k_s)
    options = {"lam": args.lam, "delta": delta}
    if args.controller != "fl":
        options["k_s"] = args.k_s
    spec = SweepSpec(model=args.model, controller=args.controller, controller_options=options,
                     reference=args.reference, duration=args.duration, dt=args.dt)
    P = sample_parameters(m, args.samples, seed=args.seed, k_range=(args.k_min, args.k_max),
                          k_relative=args.k_rel)
    t0 = time.perf_counter()
    metrics = sweep(spec, P, chunk_size=args.chunk, scheduler=args.scheduler, n_workers=args.workers,
                    progress=lambda d, t: print(f"\rfjm sweep: {d}/{t} chunks", end="", file=sys.stderr,
                                                flush=True))
    print(file=sys.stderr)
    path = write_table(args.out, m, P, metrics)
    ok = metrics["diverged"] == 0
    print(json.dumps({"runs": int(len(P)), "diverged": int((~ok).sum()), "seconds": time.perf_counter() - t0,
                      "rms_error_second_half_max": float(np.nanmax(metrics["rms_error_second_half"])),
                      "rms_error_second_half_median": float(np.nanmedian(metrics["rms_error_second_half"])),
                      "table": str(path)}, indent=2))
    return 0


def _cmd_derive(argv: List[str]) -> int:
    """``fjm derive ...`` = ``python -m derive ...`` in a subprocess (the runtime never imports derive)."""
    import importlib.util
    import subprocess
    import os
    for mod in ("derive", "sympy"):
        if importlib.util.find_spec(mod) is None:
            print(f"fjm derive: error: the derivation needs the build-time extra ({mod} is missing); "
                  "install it with: pip install '.[derive]'  (or: pip install 'fjm[derive]')", file=sys.stderr)
            return 2
    code = "import sys; from derive.__main__ import main; sys.exit(main(sys.argv[1:], prog='fjm derive'))"
    root = str(Path(importlib.util.find_spec("derive").origin).resolve().parent.parent)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root] + [v for v in [os.environ.get("PYTHONPATH")] if v]))
    return subprocess.run([sys.executable, "-c", code, *argv], env=env).returncode


def main(argv: Optional[List[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["derive"]:
        return _cmd_derive(argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        if args.command == "simulate":
            return _cmd_simulate(args)
        if args.command == "sweep":
            return _cmd_sweep(args)
        if args.command == "tune":
            from .tune import run as run_tune
            return run_tune(args)
        if args.command == "figures":
            if args.samples < 1:
                raise ValueError(f"--samples = {args.samples}: expected an integer >= 1")
            from ..experiments.paper import make_figures
            summary = make_figures(args.out, n_mc=args.samples, quick=args.quick)
            print(summary)
            return 0
    except ValueError as exc:
        print(f"fjm: error: {exc}", file=sys.stderr)
        return 2
    return 2


if __name__ == "__main__":
    sys.exit(main())
