"""``fjm design MODEL``: search the gains for a rate, delay and sensor model over many sampled closed loops."""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from ..validation import FjmValueError

__all__ = ["add_parser", "run", "demo_task"]


def add_parser(sub) -> None:
    """Register ``fjm design``."""
    p = sub.add_parser("design", help="search gains over sampled closed loops (batch engine)",
                       description="Search the integral sliding-mode gains (lam, k_lin, k_s, delta) for a model, "
                                   "control rate, delay and sensor model over draws of the TRUE plant "
                                   "(docs/design-command.md); writes the gains file fjm simulate --gains reads.")
    p.add_argument("model")
    p.add_argument("--controller", default="ismc", choices=("ismc",), help="law (default ismc)")
    p.add_argument("--sensing", default="torque", choices=("state", "torque"), help="default torque")
    p.add_argument("--rate", type=float, default=1000.0, help="control rate, Hz (default 1000)")
    p.add_argument("--delay-samples", type=int, default=1, help="computation delay, samples (default 1)")
    p.add_argument("--noise", default="panda", choices=("none", "panda"), help="sensor model (default panda)")
    p.add_argument("--draws", type=int, default=200, help="plant draws of the final check (default 200)")
    p.add_argument("--duration", type=float, default=10.0, help="final run length, s (default 10)")
    p.add_argument("--seed", type=int, default=0, help="draws and noise seed (default 0)")
    p.add_argument("--threads", type=int, default=None, help="OpenMP threads (default all cores)")
    p.add_argument("--simd", action=argparse.BooleanOptionalAction, default=True,
                   help="SIMD batch (default; its C build is cached, the first one takes minutes for the Panda); "
                        "--no-simd: the scalar batch")
    p.add_argument("--predict", action="store_true", help="loops run with delay compensation (the sample step's "
                                                           "nominal-model prediction)")
    p.add_argument("--task", default="auto", choices=("auto", "sine"),
                   help="auto: the demo's task where the model has one (Panda: joint-space sines about the ready "
                        "pose; Baxter: both arms on sines, the head still; from rest holding gravity); sine: "
                        "0.5 rad sines about q = 0 from rest")
    p.add_argument("--out", type=Path, default=None, help="gains file (default: print the JSON)")


def demo_task(m) -> dict:
    """The demo's task for ``m`` as :func:`fjm_runtime.analysis.design.design` keywords; ``{}`` if it has none.

    Panda: joint-space sines about the ready pose; Baxter: both arms on the same sines, the head still.
    Both start at rest holding gravity (nominal parameters).
    """
    if m.name == "panda":
        from ..experiments import panda as demo  # the demo's task: cli sits on top, like experiments
        kind, offset, amplitude, omega = ("panda ready-pose sines (the demo's)", list(demo.READY),
                                          list(demo.AMPLITUDE), list(demo.OMEGA))
    elif m.name == "baxter":
        from ..experiments import baxter as demo
        kind, offset, amplitude, omega = ("baxter two-arm sines, head still (the demo's)",
                                          [0.0] + list(demo.ARM_POSE) * 2, [0.0] + list(demo.ARM_AMPLITUDE) * 2,
                                          [1.0] + list(demo.ARM_OMEGA) * 2)
    else:
        return {}
    from ..sim.rest import rest_state
    ref = demo.reference()
    return {"reference": ref, "x0": rest_state(m, ref(0.0)[0], m.default_params),
            "task": {"kind": kind, "offset": offset, "amplitude": amplitude, "omega": omega,
                     "phase": -0.5 * math.pi, "start": "at rest holding gravity (nominal parameters)"}}


def run(args) -> int:
    """Run ``fjm design``; prints or writes the gains file, progress on stderr."""
    from .. import load
    from ..analysis.design import design
    from ..sim.sensor import SensorModel
    if args.out is not None and not args.out.parent.is_dir():
        raise FjmValueError(f"--out {args.out}: the directory {args.out.parent} does not exist")
    if args.draws < 1 or args.duration <= 0 or args.delay_samples < 0 or args.rate <= 0:
        raise FjmValueError("--draws/--duration/--delay-samples/--rate: expected >= 1, > 0 s, >= 0, > 0 Hz")
    m = load(args.model)
    sensor = SensorModel.panda(seed=args.seed) if args.noise == "panda" else SensorModel.ideal(seed=args.seed)
    task = demo_task(m) if args.task == "auto" else {}
    t0 = time.perf_counter()
    out = design(m, kind=args.controller, sensing=args.sensing, rate=args.rate, delay=args.delay_samples,
                 sensor=sensor, draws=args.draws, duration=args.duration, seed=args.seed, threads=args.threads,
                 simd=args.simd, predict=args.predict, **task)
    out["wall_seconds"] = time.perf_counter() - t0
    out["noise"] = args.noise
    text = json.dumps(out, indent=2, allow_nan=False)
    if args.out is None:
        print(text)
    else:
        args.out.write_text(text + "\n")
        print(f"fjm design: wrote {args.out} ({out['wall_seconds']:.0f} s)", file=sys.stderr)
    return 0
