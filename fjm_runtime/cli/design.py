"""``fjm design MODEL``: search the gains for a rate, delay and sensor model over many sampled closed loops."""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from .common import add_interface_argument, interface_arg
from .models import MODEL_HELP
from ..analysis.search.compare import LAWS_BY_INTERFACE
from ..validation import FjmValueError, check_magnitudes
from .ranges import DELAY, DURATION, RATE, SEED, THREADS, TORQUE, Range

__all__ = ["add_arguments", "run", "demo_task"]


def add_arguments(p) -> None:
    """The arguments of ``fjm design`` on its parser ``p`` (name, help, description: commands.toml)."""
    p.add_argument("model", help=MODEL_HELP)
    laws = tuple(dict.fromkeys(law for group in LAWS_BY_INTERFACE.values() for law in group))
    p.add_argument("--law", default="auto", choices=("auto",) + laws,
                   help="auto: search every law of the --interface (motor: impedance, ismc, fl; joint_torque: "
                        "joint_impedance) on the same draws and thresholds, print them side by side and keep the best "
                        "that meets; a name: that law only (default auto)")
    p.add_argument("--controller", default=None, choices=laws, help="the same as --law NAME")
    p.add_argument("--sensing", default="torque", choices=("state", "torque"),
                   help="what ismc and fl read (default torque; impedance reads q, dq, q_m, dq_m, tau_J, dtau_J)")
    p.add_argument("--rate", type=RATE, default=1000.0, help=f"control rate, {RATE} (default 1000)")
    p.add_argument("--delay-samples", type=DELAY, default=1, help=f"computation delay, {DELAY} (default 1)")
    p.add_argument("--noise", default="panda_white", metavar="PRESET|FILE",
                   help="sensor model: a preset (ideal, panda_white, franka_like; former names none, panda) or a "
                        "TOML sensor file (docs/simulation.md); default panda_white")
    p.add_argument("--params", type=Path, default=None, metavar="FILE",
                   help="TOML parameter file: the controller's nominal values ([parameters], model-file form) and "
                        "the spread of the TRUE plant draws ([spread]); default K x U[0.7, 1.3], J_m x U[0.8, 1.2], "
                        "payload U[0, 1] kg (docs/design-command.md)")
    p.add_argument("--max-rms", type=float, default=2e-3,
                   help=f"threshold: second-half RMS tracking error of every joint, {RMS} (default 2e-3)")
    p.add_argument("--max-jitter", type=float, default=3.0,
                   help=f"threshold: torque jitter on the --jitter-joints, {TORQUE} (default 3)")
    p.add_argument("--max-at-limit", type=float, default=2.0,
                   help="threshold: time at a torque limit of every joint, percent, 0 < share <= 100 (default 2)")
    p.add_argument("--jitter-joints", default="1-4",
                   help="joints of the jitter threshold: '1-4', '1,2,3', '1-3,6' or 'all' (default 1-4, those the "
                        "model has)")
    p.add_argument("--draws", type=DRAWS, default=200, help=f"plant draws of the final check, {DRAWS} (default 200)")
    p.add_argument("--recheck-draws", type=int, default=None,
                   help="fresh plant draws and noise seeds on which passing gains are re-checked, 0..100000 (default: "
                        "--draws; 0: no re-check)")
    p.add_argument("--duration", type=float, default=10.0, help=f"final run length, {DURATION} (default 10)")
    p.add_argument("--screen-draws", type=DRAWS, default=12,
                   help=f"plant draws of the search stages, {DRAWS} (the first are the box's corners; default 12)")
    p.add_argument("--screen-duration", type=DURATION, default=2.0,
                   help=f"run length of the search stages, {DURATION} (default 2)")
    p.add_argument("--rounds", type=ROUNDS, default=6, help=f"rounds of the pattern search, {ROUNDS} (default 6)")
    p.add_argument("--seed", type=SEED, default=0, help=f"draws and noise seed, {SEED} (default 0)")
    add_interface_argument(p)
    p.add_argument("--threads", type=THREADS, default=None, help=f"OpenMP threads, {THREADS} (default all cores)")
    p.add_argument("--simd", action=argparse.BooleanOptionalAction, default=True,
                   help="SIMD batch (default; its C build is cached, the first one takes minutes for the Panda); "
                        "--no-simd: the scalar batch")
    p.add_argument("--predict", action="store_true", help="loops run with delay compensation (the sample step's "
                                                           "nominal-model prediction)")
    p.add_argument("--task", default="auto", choices=("auto", "sine"),
                   help="auto: the task the model's file states ([task]; Panda: joint-space sines about the ready "
                        "pose; Baxter: both arms on sines, the head still; from rest holding gravity) where it states "
                        "one; sine: 0.5 rad sines about q = 0 from rest")
    p.add_argument("--screen", default="none", choices=("none", "linear"),
                   help="linear: reject candidates by the linear sampled-data analysis before Monte Carlo (spectral "
                        "radius and predicted jitter on the box's corners; slow on 7 joints) and name what limits a "
                        "failed design from it; default none")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the Monte Carlo stages on an existing dask.distributed scheduler, e.g. "
                        "tcp://10.0.0.5:8786 (same gains and costs as here, bit for bit; default: this process)")
    p.add_argument("--out", type=Path, default=None, help="gains file (default: print the JSON)")


def demo_task(m, nominal=None) -> dict:
    """The task ``m``'s model file states (``m.task``) as :func:`fjm_runtime.analysis.search.search.design`
    keywords ``reference``, ``x0`` and ``task`` (its record); ``{}`` if the model states none.

    The start: at rest on the reference at ``t = 0``, holding gravity with the ``nominal`` parameters
    (default the model's).
    """
    task = m.task
    if task is None:
        return {}
    from ..control.design import task_start
    ref, record = task.reference(), task.record()
    return {"reference": ref, "x0": task_start(m, ref, record["start"], nominal), "task": record}


def _warn_position_limits(m, task: dict, duration: float, dt: float) -> None:
    """One stderr line when the task the search runs on (the model's, else 0.5 rad sines at 1 rad/s about
    q = 0) leaves the model's position limits."""
    from ..control.references import make_reference
    from .simulate_conditions import position_limit_warning
    ref = task.get("reference") or make_reference("sine", int(m.n), amplitude=0.5, omega=1.0)
    warn = position_limit_warning(m, ref, duration, dt, "the search goes on (a [task] in the model file gives "
                                  "the design a task within them)")
    if warn:
        print(f"fjm design: warning: {warn}", file=sys.stderr)


#: Largest reference table (samples x 5n doubles) a batch may hold, bytes.
MAX_REFERENCE_BYTES = 2e9
#: Plant draws of a stage.
DRAWS = Range(1, 100_000, "", "draws", integer=True)
#: Rounds of the pattern search.
ROUNDS = Range(0, 100, "", "rounds", integer=True)
#: Second-half RMS threshold, rad.
RMS = Range(0, 2 * math.pi, "rad", "rms", lo_open=True)
#: Most control samples of the final check and its re-check together (the batch runs ~1e6-1e7 samples/s).
MAX_LOOP_SAMPLES = 1e10


def check_samples(duration: float, rate: float, n: int, flags: str) -> None:
    """Refuse a run whose reference table (``duration x rate + 1`` samples of ``5n`` doubles) exceeds
    :data:`MAX_REFERENCE_BYTES`, before any work (one-line FjmValueError)."""
    need = (duration * rate + 1) * 5 * n * 8
    if need > MAX_REFERENCE_BYTES:
        raise FjmValueError(f"{flags} {duration:g} s at {rate:g} Hz: {duration * rate:.3g} samples per run would hold {need / 1e9:.3g} GB of "
                            f"reference samples; expected at most {MAX_REFERENCE_BYTES / 1e9:g} GB (shorter "
                            "runs or a lower rate)")


def _settings(args, m):
    """``(sensor, thresholds, spread)`` from the flags, checked before any work."""
    from ..analysis.search.draws import default_spread, load_params_file
    from ..analysis.search.thresholds import Thresholds, parse_joints
    from ..sim.sensor import sensor_from_spec
    sensor = sensor_from_spec(args.noise, seed=args.seed, what="--noise")
    for flag, v in (("--max-rms", args.max_rms), ("--max-jitter", args.max_jitter),
                    ("--max-at-limit", args.max_at_limit)):
        if not (math.isfinite(v) and v > 0):
            raise FjmValueError(f"{flag} {v!r}: expected a finite threshold > 0")
    RMS.check("--max-rms", args.max_rms)
    TORQUE.check("--max-jitter", args.max_jitter)
    if args.max_at_limit > 100:
        raise FjmValueError(f"--max-at-limit {args.max_at_limit!r}: expected a percentage in (0, 100]")
    joints = None if args.jitter_joints.strip() == "1-4" else parse_joints(args.jitter_joints, int(m.n))
    thresholds = Thresholds(max_rms=args.max_rms, max_jitter=args.max_jitter, max_at_limit=args.max_at_limit / 100.0,
                            jitter_joints=joints)
    spread = default_spread(m) if args.params is None else load_params_file(args.params, m)
    if args.params is not None:
        check_magnitudes(spread.overrides, spread.overrides.values(), f"--params {args.params}: [parameters] ")
    return sensor, thresholds, spread


def run(args) -> int:
    """Run ``fjm design``; prints or writes the gains file, progress and the verdict on stderr.

    Returns 0 when the gains meet every threshold (final check and re-check), 1 otherwise.
    """
    from .. import load
    from ..analysis.search.compare import comparison_lines, design_laws, laws_for
    from ..analysis.search.settings import SearchSettings
    from ..analysis.search.report import summary_lines
    from ..control.design import Design
    if args.out is not None and not args.out.parent.is_dir():
        raise FjmValueError(f"--out {args.out}: the directory {args.out.parent} does not exist")
    if args.recheck_draws is not None and args.recheck_draws < 0:
        raise FjmValueError(f"--recheck-draws {args.recheck_draws}: expected >= 0 (0: no re-check)")
    if args.recheck_draws is not None:
        Range(0, DRAWS.hi, "", "draws", integer=True).check("--recheck-draws", args.recheck_draws)
    if not (math.isfinite(args.duration) and args.duration > 0):
        raise FjmValueError(f"--duration {args.duration:g}: expected {DURATION}")
    m = load(args.model)
    check_samples(max(args.duration, args.screen_duration), args.rate, int(m.n), "--duration/--rate")
    DURATION.check("--duration", args.duration)
    runs = args.draws + (args.draws if args.recheck_draws is None else args.recheck_draws)
    if runs * args.duration * args.rate > MAX_LOOP_SAMPLES:
        raise FjmValueError(f"--draws {args.draws} (and as many re-check draws) x --duration {args.duration:g} s x "
                            f"--rate {args.rate:g} Hz = {runs * args.duration * args.rate:.3g} control samples; "
                            f"expected at most {MAX_LOOP_SAMPLES:g} (hours of batch runs): fewer draws, shorter runs "
                            "or a lower rate")
    sensor, thresholds, spread = _settings(args, m)
    task = demo_task(m, spread.nominal) if args.task == "auto" else {}
    _warn_position_limits(m, task, max(args.duration, args.screen_duration), 1.0 / args.rate)
    t0 = time.perf_counter()
    law, interface = args.controller or args.law, interface_arg(args)
    laws = laws_for(m, interface.kind, args.sensing) if law == "auto" else [law]
    settings = SearchSettings(kind=laws[0] if laws else law, sensing=args.sensing, rate=args.rate,
                              delay=args.delay_samples, sensor=sensor, interface=interface, draws=args.draws,
                              duration=args.duration, seed=args.seed,
                              threads=args.threads, simd=args.simd, predict=args.predict, thresholds=thresholds,
                              spread=spread, recheck_draws=args.recheck_draws, scheduler=args.scheduler,
                              screen_draws=args.screen_draws, screen=None if args.screen == "none" else args.screen,
                              screen_duration=args.screen_duration, rounds=args.rounds, **task)
    rec = design_laws(m, settings, laws, asked=law)
    found = Design.from_dict({**rec, "wall_seconds": time.perf_counter() - t0, "noise": args.noise}, "fjm design")
    if args.out is None:
        print(json.dumps(found.as_dict(), indent=2, allow_nan=False))
    else:
        found.save(args.out)
        print(f"fjm design: wrote {args.out} ({found.report['wall_seconds']:.0f} s)", file=sys.stderr)
    for line in comparison_lines(rec["comparison"], rec["law_choice"]["chosen"]):
        print(f"fjm design: {line}", file=sys.stderr)
    for line in summary_lines(found.as_dict()):
        print(f"fjm design: {line}", file=sys.stderr)
    return 0 if found.meets else 1
