"""``fjm analyze MODEL --gains FILE``: the linear sampled-data analysis of a law with given gains.

Defaults to the gains file's own conditions (rate, delay, prediction, sensing, sensor, task); flags
override them. Prints a table per plant (nominal and the corners of the parameter box) and operating
point (at rest, and frozen-time points along the task): the verdict (stable, UNSTABLE, or NO VERDICT
with the reason), its spectral radius and method (small-signal, or the boundary layer's equivalent gain
under the sensor noise), the joint of its mode, the first unstable delay, the predicted torque jitter,
link-angle error std and time inside the layer per joint; then the
stiffness-scale range and the noise channel that dominates each joint's jitter. ``--json`` prints the
record, ``--out`` writes it (docs/design-command.md, "The linear analysis").
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from .models import MODEL_HELP
from ..validation import FjmValueError
from .common import add_interface_argument, interface_arg
from .ranges import DELAY, RATE

__all__ = ["add_arguments", "run", "conditions_from_design"]


def add_arguments(p) -> None:
    """The arguments of ``fjm analyze`` on its parser ``p`` (name, help, description: commands.toml)."""
    p.add_argument("model", help=MODEL_HELP)
    p.add_argument("--gains", type=Path, default=None,
                   help="gains file (a fjm design output or {kind, gains}); default: the gains fjm simulate uses "
                        "without one (smc, its default lam, k_s, delta and the model's effort limits; state "
                        "sensing, 1000 Hz, no delay, ideal sensor, 0.5 rad sines at 1 rad/s)")
    p.add_argument("--rate", type=RATE, default=None, help=f"control rate, {RATE} (default: the file's, else 1000)")
    p.add_argument("--delay-samples", type=DELAY, default=None,
                   help=f"delay, {DELAY} (default: the file's, else 0)")
    p.add_argument("--predict", action=argparse.BooleanOptionalAction, default=None,
                   help="delay compensation (default: the file's)")
    p.add_argument("--sensing", choices=("state", "torque"), default=None, help="default: the file's, else torque")
    p.add_argument("--noise", default=None, metavar="PRESET|FILE",
                   help="sensor model: preset or TOML file (default: the file's sensor)")
    add_interface_argument(p)
    p.add_argument("--task-times", default="0.5,1,2", metavar="S[,S..]",
                   help="frozen-time points along the task, s (default 0.5,1,2; 'none': rest only)")
    p.add_argument("--plants", choices=("corners", "nominal"), default="corners",
                   help="nominal plant and the 9 corners of the box (default), or the nominal plant only")
    p.add_argument("--no-margins", action="store_true", help="skip the delay margin and stiffness-scale range")
    p.add_argument("--json", action="store_true", help="print the JSON record instead of the table")
    p.add_argument("--out", type=Path, default=None, help="also write the JSON record to this file")


def _sensor(args, design):
    from ..sim.sensor import SensorModel, sensor_from_spec
    if args.noise is not None:
        return sensor_from_spec(args.noise, what="--noise")
    if isinstance(design.sensor, dict):
        fields = {k: v for k, v in design.sensor.items() if k in SensorModel.__dataclass_fields__}
        fields.setdefault("name", str(design.noise or "design file"))
        return SensorModel.from_dict(fields, where=f"--gains {args.gains}: sensor")
    return sensor_from_spec(design.noise or "ideal", what=f"--gains {args.gains}: noise")


def _task(m, design):
    """``(reference, x0)``: the file's task, the demo's, or 0.5 rad sines at 1 rad/s from rest."""
    from ..batch.distributed import initial_state
    from ..control.references import make_reference
    from .design import demo_task
    ref = design.reference(m)
    if ref is not None:
        return ref, initial_state(m, ref, design.start_state(m))
    demo = demo_task(m)
    if demo:
        return demo["reference"], demo["x0"]
    ref = make_reference("sine", int(m.n), amplitude=0.5, omega=1.0)
    return ref, initial_state(m, ref, None)


def conditions_from_design(m, design, args):
    """The :class:`~fjm_runtime.analysis.sampled.sampled_linear.Conditions` of a design, flags overriding."""
    from ..analysis.sampled.sampled_linear import Conditions
    rate = args.rate if args.rate is not None else float(1000.0 if design.rate is None else design.rate)
    delay = args.delay_samples if args.delay_samples is not None else int(design.delay or 0)
    if not (math.isfinite(rate) and 0 < rate <= 1e6):
        raise FjmValueError(f"--rate {rate}: expected a finite control rate in (0, 1e6] Hz")
    if delay < 0 or delay > 100:
        raise FjmValueError(f"--delay-samples {delay}: expected an integer in [0, 100]")
    predict = bool(design.predict) if args.predict is None else bool(args.predict)
    sensing = args.sensing or design.sensing or "torque"
    ref, x0 = _task(m, design)
    u_max = design.gains.get("u_max")
    return Conditions(m, design.kind, sensing, 1.0 / rate, int(delay), predict, _sensor(args, design), ref,
                      np.asarray(x0, dtype=float), {}, None if u_max is None else tuple(np.broadcast_to(
                          np.asarray(u_max, dtype=float), (int(m.n),)).tolist()), interface_arg(args, design))


def _times(text: str):
    if text.strip().lower() == "none":
        return ()
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise FjmValueError(f"--task-times {text!r}: expected times in s separated by commas, or 'none'") from None
    if not all(math.isfinite(v) and 0 < v <= 60 for v in vals):
        raise FjmValueError(f"--task-times {text!r}: expected times in (0, 60] s")
    return vals


def _fmt(vals, spec="{:.3g}"):
    return " ".join("-" if v is None else spec.format(v) for v in vals)


def _point_lines(name: str, f: dict):
    """The report of one plant's point: the verdict and its method, then the figures when stable."""
    d = f.get("first_unstable_delay", "n/a")
    verdict = {True: "", False: " UNSTABLE", None: " NO VERDICT"}[f["stable"]]
    method = f.get("method", "small-signal")
    head = f"  {name:>8}  rho {f['rho']:.4f}{verdict} ({method}"
    if method != "small-signal":
        head += f"; small-signal rho {f['rho_small_signal']:.4g}"
    lines = [head + f")  mode on joint {f['dominant_joint']}  first unstable delay {'> d+4' if d is None else d}"]
    if f["stable"] is None:
        lines.append(f"            no verdict: {f.get('reason', 'the linearization does not apply')}")
    elif method == "small-signal" and max(f.get("s_over_delta", [0.0])) > 1.0:
        lines.append(f"            the law is OUTSIDE its boundary layer here (|s|/delta up to "
                     f"{max(f['s_over_delta']):.3g}): saturated, the linearization is not the loop's")
    if f["stable"]:
        lines.append(f"            jitter N m  {_fmt(f['torque_jitter'])}")
        lines.append(f"            q std rad   {_fmt(f['q_error_std'])}")
        if "layer_fraction" in f:
            lines.append(f"            in layer    {_fmt(f['layer_fraction'], '{:.2f}')}")
        if "dominant_noise" in f:
            lines.append(f"            dominant noise  {' '.join(f['dominant_noise'])}")
    return lines


def table_lines(out: dict):
    """The readable report of an analysis record."""
    s = out["settings"]
    lines = [f"{s['rate']:g} Hz, delay {s['delay']}{' + prediction' if s['predict'] else ''}, sensing {s['sensing']}, "
             f"sensor {s['sensor']}, interface {s.get('interface')}, {s['substeps']} substeps; "
             f"jitter window {s['jitter_window_samples']} samples"]
    for row in out["plants"]:
        lines.append(f"{row['plant']}:")
        for name, f in row["points"].items():
            lines.extend(_point_lines(name, f))
    for name, sc in out.get("stiffness_scale", {}).items():
        lo, hi = sc["range"]
        lines.append(f"stiffness scale (nominal plant, {name}): " + ("unstable at g = 1" if sc["unstable"] else
                     f"K x [{'< 1/16' if lo is None else f'{lo:.3g}'}, {'> 16' if hi is None else f'{hi:.3g}'}]"))
    sm = out["summary"]
    lines.append(f"worst: rho {sm['rho']}, jitter N m {_fmt(sm['torque_jitter'])}, q std rad {_fmt(sm['q_error_std'])}")
    lines.extend(f"no verdict: {reason}" for reason in sm.get("no_verdict", []))
    lines.append(f"({out['seconds']:.1f} s)")
    return lines


def run(args) -> int:
    """Run ``fjm analyze``; 0 when the loop is stable at every plant and point, 1 otherwise (unstable or
    no verdict somewhere)."""
    from .. import load
    from ..analysis.sampled.sampled_analysis import LinearAnalyzer, default_plants
    from .common import check_output_file
    if args.out is not None:
        check_output_file(args.out, "--out")
    m = load(args.model)
    from ..control.design import Design
    if args.gains is None:
        from .simulate_conditions import default_design
        design = default_design(m).check(m)
        g = design.gains
        limit = ", ".join(f"{v:g}" for v in g["u_max"]) + " N m" if "u_max" in g else "none"
        print(f"fjm analyze: no --gains: the default gains of fjm simulate (smc, lam {g['lam']:g} 1/s, k_s "
              f"{np.max(g['k_s']):g} rad/s^4, delta {np.max(g['delta']):g} rad/s^3, torque limit {limit}; "
              "state sensing, 1000 Hz, delay 0, ideal sensor)", file=sys.stderr)
    else:
        design = Design.load(args.gains).check(m)
    cond = conditions_from_design(m, design, args)
    times = _times(args.task_times)
    plants = default_plants(m)
    analyzer = LinearAnalyzer(cond, plants=plants if args.plants == "corners" else plants[:1], task_times=times)
    # noise-free (the ideal sensor): the layer's sigma floor, 1e-300, squares past the float range in the normal
    # pdf, whose exp(-inf) = 0 is the value meant; numpy's overflow note would only alarm the user
    with np.errstate(over="ignore"):
        out = analyzer.analyze(dict(design.law_gains(), u_max=cond.u_max), margins=not args.no_margins)
    out.update({"model": m.name, "kind": design.kind, "gains_file": None if args.gains is None else str(args.gains),
                "gains_source": "defaults" if args.gains is None else f"--gains {args.gains}"})
    text = json.dumps(out, indent=2, allow_nan=False, default=lambda v: None)
    if args.out is not None:
        args.out.write_text(text + "\n")
    if args.json:
        print(text)
    else:
        print("\n".join(table_lines(out)))
    return 0 if out["summary"]["stable_everywhere"] is True else 1
