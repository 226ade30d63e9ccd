"""``fjm simulate MODEL ...``: one closed loop, metrics as JSON on stdout, optionally a PNG."""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Dict

from ..analysis.lemma1 import (FALLBACK_SWITCHING_GAIN, default_error_bounds, default_switching_gain,
                               paper_beta_hat, paper_bound_applies)
from ..control.factory import CONTROLLER_KINDS, DEFAULT_LAYER_RATE, default_delta, make_controller
from ..control.references import REFERENCE_KINDS, make_reference
from ..sim.simulate import SimulationDivergedError, simulate, stderr_progress
from ..validation import FjmValueError
from .common import check_output_file, finite_or_note, parse_assignments


def add_parser(sub) -> None:
    """Add ``simulate`` to the sub-command set ``sub``."""
    sim = sub.add_parser("simulate", help="simulate one closed loop and print its metrics",
                         description="Simulate one closed loop (true plant vs nominal controller) and print "
                                     "metrics as JSON. Plant parameters: --K / --param; the controller uses "
                                     "the model defaults unless --nominal is given.")
    sim.add_argument("model", help="model name, e.g. link1, planar2 (see `fjm models`)")
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
                          f"[--k-min, --k-max]; {FALLBACK_SWITCHING_GAIN:g} otherwise)")
    sim.add_argument("--delta", type=float, default=None,
                     help=f"boundary layer (default max(k_s, 1) / {DEFAULT_LAYER_RATE:g})")
    sim.add_argument("--k-min", type=float, default=100.0, help="stiffness lower bound for Lemma 1 (default 100)")
    sim.add_argument("--k-max", type=float, default=200.0, help="stiffness upper bound for Lemma 1 (default 200)")
    sim.add_argument("--beta-hat", choices=("paper", "model"), default="paper",
                     help="link1: paper's constant (beta_max + beta_min)/2 or beta(x; nominal) (default paper)")
    sim.add_argument("--u-max", type=float, default=None, help="torque limit, N m (default none)")
    sim.add_argument("--plot", type=Path, default=None,
                     help="write a PNG of angles, error, torque and s (its directory must exist)")
    sim.add_argument("--quiet", action="store_true", help="no progress on stderr")


def _true_params(m, args) -> Dict[str, float]:
    true = parse_assignments(args.param, "--param")
    if args.K is not None:
        if "K" in m.param_names:
            true.setdefault("K", args.K)
        else:
            for i in range(m.n):
                true.setdefault(f"K{i + 1}", args.K)
    return true


def run(args) -> int:
    """Run ``fjm simulate``; returns the exit status (3: the simulation diverged)."""
    from .. import load
    if args.plot is not None:
        check_output_file(args.plot, "--plot")
    m = load(args.model)
    true = _true_params(m, args)
    nominal = parse_assignments(args.nominal, "--nominal")
    ref_kw = {"sine": {"amplitude": args.amplitude, "omega": args.omega},
              "step": {"q_d": args.q_d, "rise_time": args.rise_time},
              "constant": {"q_d": args.q_d}}.get(args.reference, {})
    ref = make_reference(args.reference, m.n, **ref_kw)
    k_bounds = (args.k_min, args.k_max)
    extra: Dict[str, object] = {}
    if args.beta_hat == "paper" and paper_bound_applies(m):
        extra["beta_hat"] = paper_beta_hat(m, nominal, k_bounds)
    gain = None
    k_s = args.k_s
    if k_s is None:
        gain = default_switching_gain(m, nominal, args.lam, ref.derivative_bounds(), k_bounds=k_bounds,
                                      error_bounds=default_error_bounds(args.reference, args.amplitude, args.omega))
        k_s = FALLBACK_SWITCHING_GAIN if gain is None else gain.k_s
    delta = args.delta if args.delta is not None else default_delta(k_s)
    if args.controller == "adaptive":
        # beta from the estimated stiffness (not the paper's constant); the bounds project K_hat
        extra.pop("beta_hat", None)
        if not (0 < args.k_min < args.k_max):
            raise FjmValueError(f"--k-min/--k-max = {args.k_min}/{args.k_max}: expected 0 < k_min < k_max "
                                "for the adaptive controller")
        extra["K_bounds"] = k_bounds
    ctrl = make_controller(args.controller, m, nominal, lam=args.lam, k_s=k_s, delta=delta,
                           u_max=args.u_max, **extra)
    progress = None if args.quiet else stderr_progress(f"simulating {args.model} ({args.duration:g} s)")
    try:
        res = simulate(m, ctrl, ref, duration=args.duration, dt=args.dt, true_params=true, progress=progress)
    except SimulationDivergedError as exc:
        print(f"fjm: {exc}", file=sys.stderr)
        return 3
    metrics: Dict[str, object] = {}
    for k, v in res.metrics.as_dict().items():
        finite_or_note(metrics, k, v)
    report = {"model": m.name, "controller": args.controller, "reference": args.reference,
              "true_params": dict(zip(m.param_names, m.params_array(true).tolist())),
              "nominal_params": dict(zip(m.param_names, m.params_array(nominal).tolist())),
              "lam": args.lam, "k_s": k_s, "delta": delta,
              "lemma1": None if gain is None else {"k_s": gain.k_s, "k_s_tight": gain.k_s_tight, "W": gain.W,
                                                   "H": gain.H, "beta_hat": gain.beta_hat},
              "metrics": metrics}
    if hasattr(ctrl, "stiffness_estimate"):
        report["K_hat_final"] = ctrl.stiffness_estimate(res.z[-1]).tolist()
    print(json.dumps(report, indent=2, allow_nan=False))
    if args.plot is not None:
        from ..experiments.plots import plot_run
        mt = res.metrics
        plot_run(res, f"{args.model}, {args.controller}, reference {args.reference}: final |e1| = "
                      f"{mt.final_error:.3g} rad, RMS = {mt.rms_error:.3g} rad, max |u| = {mt.max_abs_u:.3g} N m",
                 args.plot)
    return 0
