"""``fjm tune MODEL``: argparse and printing of the gain synthesis (the analysis is :mod:`fjm_runtime.analysis`).

Every input error is one line on stderr naming what is wrong and what was expected,
exit status 2, no traceback (parser errors here; ``ValueError`` of the analysis in
:func:`fjm_runtime.cli.main.main`). A synthesis that finds no admissible gain is a
result, not an input error: the JSON says why and the exit status is 1.
"""
from __future__ import annotations

import json
import sys
from typing import Dict, List, Tuple

from .models import MODEL_HELP
from ..analysis.certificates.box import default_stiffness_box, param_box_from_ranges
from ..analysis.certificates.certify import GUARANTEE, synthesize_gains
from ..analysis.certificates.certify_tau import GUARANTEE_TAU, synthesize_torque_gains, torque_param_box
from ..analysis.certificates.lemma1 import paper_beta_hat
from ..control.defaults import DEFAULT_LAM, DEFAULT_LAYER_RATE
from ..validation import check_magnitudes
from .common import parse_assignments
from .ranges import AMPLITUDE, ANGLE, DURATION, FACTOR, FREQUENCY, MASS, POLE, STIFFNESS, TORQUE, Range

#: Ranges of the certificate's own flags (the others: :mod:`fjm_runtime.cli.ranges`).
INERTIA = Range(0, 1e4, "kg m^2", "J_m", lo_open=True)
DAMPING = Range(0, 1e6, "N m s/rad", "B_m")
LINK_MASS = Range(0, 1e4, "kg", "m", lo_open=True)
ETA = Range(0, 1e20, "rad/s^4", "eta", lo_open=True)
LAYER_RATE = Range(0, 1e6, "1/s", "rate", lo_open=True)
#: Grid points of the certificate (its time grows with them: link1 60000 takes 4 s, 1e6 50 s).
BUDGET = Range(1, 1_000_000, "", "budget", integer=True)
DISTURBANCE = Range(0, 1e6, "N m", "D")
#: A bound of the reference's derivatives or of the tracking errors (SI units of each derivative).
BOUND = Range(0, 1e12, "", "bound")

DEFAULT_ERROR_BOX = {"sine": [0.05, 0.5, 0.5, 0.5], "step": [0.05, 0.1, 0.5, 1.0]}


def _floats(text: str, count: int, flag: str) -> List[float]:
    try:
        vals = [float(v) for v in str(text).replace(",", " ").split()]
    except ValueError:
        raise ValueError(f"{flag} {text!r}: expected {count} numbers separated by commas") from None
    if len(vals) != count:
        raise ValueError(f"{flag} {text!r}: expected {count} numbers separated by commas, got {len(vals)}")
    if not all(BOUND.contains(v) for v in vals):
        raise ValueError(f"{flag} {text!r}: expected {count} bounds, each {BOUND}")
    return vals


def _one_line_error(prog: str):
    def error(message: str):
        print(f"{prog}: error: {message} (see {prog} --help)", file=sys.stderr)
        sys.exit(2)
    return error


def add_arguments(tp) -> None:
    """The arguments of ``fjm tune`` on its parser ``tp`` (name, help, description: commands.toml)."""
    tp.add_argument("model", help=MODEL_HELP)
    tp.add_argument("--controller", choices=("smc", "sign", "ismc"), default=None,
                    help="law to certify: smc/sign = paper surface, ismc = integral surface (default smc; "
                         "ismc with --sensing torque)")
    tp.add_argument("--sensing", choices=("state", "torque"), default="state",
                    help="state: the law on x = [q; dq; q_m; dq_m]; torque: the torque-sensed law on "
                         "m = [q; dq; tau_J; dtau_J; dq_m] (control_<kind>_tau), certified on a box of the stiffness "
                         "ratio K/K_nom (--gamma-range), J_m (--jm-ratio) and payload (--payload) (default state)")
    tp.add_argument("--gamma-range", type=FACTOR, nargs=2, default=(0.7, 1.3), metavar=("LO", "HI"),
                    help=f"--sensing torque: true stiffness ratio K/K_nom of every joint, each {FACTOR} (default 0.7 1.3)")
    tp.add_argument("--jm-ratio", type=FACTOR, nargs=2, default=(0.8, 1.2), metavar=("LO", "HI"),
                    help=f"--sensing torque: true motor inertia ratio J_m/J_m,nom of every joint, each {FACTOR} "
                         "(default 0.8 1.2)")
    tp.add_argument("--payload", type=MASS, default=1.0, metavar="KG",
                    help=f"--sensing torque: unknown payload 0..KG kg, {MASS} (m_load; planar chains: added to the last "
                         "link's mass) (default 1)")
    tp.add_argument("--lam", type=POLE, default=DEFAULT_LAM, help=f"pole magnitude lambda, {POLE} (default {DEFAULT_LAM:g})")
    tp.add_argument("--nominal", action="append", default=[], metavar="NAME=VALUE",
                    help="NOMINAL controller parameter (repeatable); default: model defaults")
    tp.add_argument("--k-range", type=STIFFNESS, nargs=2, default=None, metavar=("LO", "HI"),
                    help=f"true stiffness of every joint, each {STIFFNESS} (default: each joint's nominal stiffness "
                         "x [2/3, 4/3], i.e. 100 200 at 150)")
    tp.add_argument("--jm-range", type=INERTIA, nargs=2, default=None, metavar=("LO", "HI"),
                    help=f"true motor inertia of every joint, each {INERTIA} (default: nominal, exact)")
    tp.add_argument("--bm-range", type=DAMPING, nargs=2, default=None, metavar=("LO", "HI"),
                    help=f"true motor damping of every joint, each {DAMPING} (default: nominal, exact)")
    tp.add_argument("--mass-range", type=LINK_MASS, nargs=2, default=None, metavar=("LO", "HI"),
                    help=f"true link (link1: tip) mass of every link, each {LINK_MASS} (default: nominal, exact)")
    tp.add_argument("--param-box", action="append", default=[], metavar="NAME=LO:HI",
                    help="interval of any true parameter (repeatable), e.g. --param-box K2=120:180")
    tp.add_argument("--reference", choices=("sine", "step"), default="sine",
                    help="reference whose derivative bounds R_0..R_4 define the box (default sine)")
    tp.add_argument("--amplitude", type=AMPLITUDE, default=0.5, help=f"sine amplitude, {AMPLITUDE} (default 0.5)")
    tp.add_argument("--omega", type=FREQUENCY, default=1.0, help=f"sine frequency, {FREQUENCY} (default 1)")
    tp.add_argument("--q-d", type=ANGLE, default=1.0, help=f"step target, {ANGLE} (default 1)")
    tp.add_argument("--rise-time", type=DURATION, default=2.0, help=f"step duration, {DURATION} (default 2)")
    tp.add_argument("--reference-bounds", default=None, metavar="R0,R1,R2,R3,R4",
                    help="explicit bounds of |y_d^(k)|, k = 0..4 (overrides --reference)")
    tp.add_argument("--error-box", default=None, metavar="E1,E2,E3,E4",
                    help="bounds of |y_hat_k - y_dk| (default 0.05,0.5,0.5,0.5 for sine, 0.05,0.1,0.5,1 for step)")
    tp.add_argument("--beta-hat", choices=("paper", "model"), default="paper",
                    help="link1: the paper's constant (beta_max + beta_min)/2 over --k-range, or beta(x; nominal); "
                         "chains always use beta(x; nominal) (default paper)")
    tp.add_argument("--eta", type=ETA, default=10.0, help=f"reaching margin, {ETA} (default 10)")
    tp.add_argument("--u-max", default=None, metavar="U[,U2,..]",
                    help="actuator limit, N m: one number for every joint or one per joint, e.g. "
                         "87,87,87,87,12,12,12 (default none)")
    tp.add_argument("--layer-rate", type=LAYER_RATE, default=DEFAULT_LAYER_RATE,
                    help=f"boundary layer delta = k_s / rate, {LAYER_RATE} (default 200)")
    tp.add_argument("--budget", type=BUDGET, default=60000, help=f"approximate grid size, {BUDGET} (default 60000)")
    tp.add_argument("--disturbance-bound", type=DISTURBANCE, default=0.0, metavar="D",
                    help=f"{DISTURBANCE}: bound of a matched motor torque disturbance (Coulomb friction level + any bounded "
                         "torque), N m (default 0)")
    tp.add_argument("--no-margin", action="store_true",
                    help="do not make the grid's curvature margin part of the condition")
    tp.error = _one_line_error(tp.prog)




def _intervals(items: List[str]) -> Dict[str, Tuple[float, float]]:
    out = {}
    for item in items:
        name, sep, rng = item.partition("=")
        lo, sep2, hi = rng.partition(":")
        if not sep or not sep2:
            raise ValueError(f"--param-box {item!r}: expected NAME=LO:HI, e.g. --param-box K2=120:180")
        try:
            out[name.strip()] = (float(lo), float(hi))
        except ValueError:
            raise ValueError(f"--param-box {item!r}: LO and HI must be numbers") from None
    return out


def _box(m, args, nominal):
    k_extra = {}
    k_range = None
    if args.k_range is not None:
        lo, hi = args.k_range
        if not (0 < lo <= hi):
            raise ValueError(f"--k-range {lo} {hi}: expected 0 < LO <= HI (N m/rad)")
        k_range = (lo, hi)
    else:
        k_extra = default_stiffness_box(m, nominal)
    k_extra.update(_intervals(args.param_box))
    return param_box_from_ranges(m, k_range=k_range, jm_range=args.jm_range, bm_range=args.bm_range,
                                 mass_range=args.mass_range, extra=k_extra)


def _reference(args, n):
    from ..control.references import Sinusoid, SmoothStep
    if args.reference_bounds is not None:
        return _floats(args.reference_bounds, 5, "--reference-bounds"), "explicit"
    if args.reference == "sine":
        return (Sinusoid(args.amplitude, args.omega, n=n).derivative_bounds(),
                f"sine amplitude {args.amplitude:g} rad, omega {args.omega:g} rad/s")
    return (SmoothStep(args.q_d, n=n, rise_time=args.rise_time).derivative_bounds(),
            f"smooth step to {args.q_d:g} rad in {args.rise_time:g} s")


def _u_max(args, n: int):
    if args.u_max is None:
        return None
    try:
        vals = [float(v) for v in str(args.u_max).replace(",", " ").split()]
    except ValueError:
        vals = []
    if len(vals) not in (1, n) or not all(TORQUE.contains(v) for v in vals):
        raise ValueError(f"--u-max {args.u_max!r}: expected one limit {TORQUE} or {n} separated by commas")
    return vals[0] if len(vals) == 1 else vals


def _run_torque(m, args, nominal, R, E, u_max):
    """``fjm tune --sensing torque``: the certificate of the torque-sensed law (or its obstacle)."""
    if args.controller == "sign":
        raise ValueError("--controller sign with --sensing torque: expected smc or ismc (the torque-sensed "
                         "laws are emitted for sat, integral and fl)")
    lo, hi = args.gamma_range
    jlo, jhi = args.jm_ratio
    for flag, (a, b) in (("--gamma-range", (lo, hi)), ("--jm-ratio", (jlo, jhi))):
        if not (0 < a <= b):
            raise ValueError(f"{flag} {a:g} {b:g}: expected 0 < LO <= HI")
    if not args.payload >= 0:
        raise ValueError(f"--payload {args.payload:g}: expected a payload >= 0 kg")
    box = torque_param_box(m, nominal, (lo, hi), (jlo, jhi), args.payload)
    box.update(_intervals(args.param_box))
    return synthesize_torque_gains(m, nominal, param_box=box, reference_bounds=R, error_bounds=E, lam=args.lam,
                                   integral=(args.controller or "ismc") == "ismc", eta=args.eta, u_max=u_max,
                                   layer_rate=args.layer_rate, include_margin=not args.no_margin,
                                   budget=args.budget)


def run(args) -> int:
    """``fjm tune``: print the :class:`~fjm_runtime.analysis.certificates.certify.TuneResult` as JSON.

    Returns
    -------
    int
        0 when a gain exists, 1 when none is admissible (the JSON and one stderr line say why).
    """
    from .. import load
    m = load(args.model)
    nominal = parse_assignments(args.nominal, "--nominal")
    check_magnitudes(nominal, nominal.values(), "--nominal ")
    m.params_array(nominal, arg="--nominal")
    box = _box(m, args, nominal)
    R, ref_label = _reference(args, int(m.n))
    E = _floats(args.error_box, 4, "--error-box") if args.error_box is not None else DEFAULT_ERROR_BOX[args.reference]
    u_max = _u_max(args, int(m.n))
    torque = args.sensing == "torque"
    if torque:
        res = _run_torque(m, args, nominal, R, E, u_max)
    else:
        beta_hat = paper_beta_hat(m, nominal, box=box) if args.beta_hat == "paper" else None
        res = synthesize_gains(m, nominal, param_box=box, reference_bounds=R, error_bounds=E, lam=args.lam,
                               integral=(args.controller == "ismc"), beta_hat=beta_hat, eta=args.eta,
                               u_max=u_max, layer_rate=args.layer_rate, include_margin=not args.no_margin,
                               budget=args.budget, disturbance_bound=args.disturbance_bound)
    s0 = res.max_sliding_variable()
    report = res.as_dict()
    report.update({"controller": args.controller or ("ismc" if torque else "smc"), "sensing": args.sensing,
                   "lam": args.lam, "reference": ref_label, "s0_max": s0.tolist(),
                   "reaching_time_bound": None if not res.feasible else res.reaching_time_bound(s0).tolist(),
                   "guarantee": GUARANTEE_TAU if torque else GUARANTEE})
    print(json.dumps(report, indent=2))
    if not res.feasible:
        why = res.settings.get("obstacle") or res.reason
        print(f"fjm tune: no admissible gain: {why}", file=sys.stderr)
        return 1
    return 0
