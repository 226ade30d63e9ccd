"""``fjm sweep MODEL ...``: a Monte Carlo sweep on Dask, one CSV row per run and a JSON summary."""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from .models import MODEL_HELP
from ..control.defaults import DEFAULT_LAM, DEFAULT_LAYER_RATE, DEFAULT_SWITCHING_GAIN, PAPER_K_RANGE, default_delta
from ..control.factory import CONTROLLER_KINDS
from ..control.references import REFERENCE_KINDS
from ..validation import FjmValueError
from .common import add_interface_argument, check_output_file, finite_or_note, interface_arg
from .ranges import (DELAY, DURATION, FACTOR, GAIN, LAYER, PERIOD, POLE, RATE, SEED, STIFFNESS, THREADS,
                     Range)

#: Runs of a sweep, and runs per Dask task.
SAMPLES = Range(1, 10_000_000, "", "samples", integer=True)
CHUNK = Range(1, 100_000, "", "chunk", integer=True)

#: The absolute stiffness range used when every nominal stiffness lies in it (link1, planar<n>).
ABSOLUTE_K_RANGE = PAPER_K_RANGE
#: The relative range used otherwise (factors of each joint's nominal stiffness).
RELATIVE_K_RANGE = (0.7, 1.3)


def add_arguments(sw) -> None:
    """The arguments of ``fjm sweep`` on its parser ``sw`` (name, help, description: commands.toml)."""
    sw.add_argument("model", help=MODEL_HELP)
    sw.add_argument("--samples", type=SAMPLES, default=1000, help=f"number of runs, {SAMPLES} (default 1000)")
    sw.add_argument("--chunk", type=CHUNK, default=250, help=f"runs per Dask task, {CHUNK} (default 250)")
    sw.add_argument("--seed", type=SEED, default=0, help=f"sampling seed, {SEED} (default 0)")
    lo, hi = ABSOLUTE_K_RANGE
    rlo, rhi = RELATIVE_K_RANGE
    sw.add_argument("--k-min", type=STIFFNESS, default=None,
                    help=f"stiffness lower bound, {STIFFNESS} (default {lo:g} when every nominal stiffness lies in "
                         f"[{lo:g}, {hi:g}], as on link1 and planar<n>; otherwise the default is --k-rel {rlo:g} {rhi:g})")
    sw.add_argument("--k-max", type=STIFFNESS, default=None, help=f"stiffness upper bound, N m/rad (default {hi:g}, see --k-min)")
    sw.add_argument("--k-rel", type=FACTOR, nargs=2, default=None, metavar=("LO", "HI"),
                    help=f"instead of --k-min/--k-max: every stiffness = its nominal x U[LO, HI], each {FACTOR} "
                         "(spatial arms, e.g. panda --k-rel 0.7 1.3)")
    sw.add_argument("--controller", default=None, choices=CONTROLLER_KINDS,
                    help="controller (default: the kind of --gains, else smc)")
    sw.add_argument("--lam", type=POLE, default=DEFAULT_LAM, help=f"pole magnitude lambda, {POLE} (default {DEFAULT_LAM:g})")
    sw.add_argument("--k-s", type=GAIN, default=DEFAULT_SWITCHING_GAIN,
                    help=f"switching gain, {GAIN} (default {DEFAULT_SWITCHING_GAIN:g})")
    sw.add_argument("--delta", type=LAYER, default=None,
                    help=f"boundary layer, {LAYER} (default max(k_s, 1) / {DEFAULT_LAYER_RATE:g})")
    sw.add_argument("--reference", default=None,
                    help=f"one of {', '.join(REFERENCE_KINDS)}, or 'task': the task a --gains design file records "
                         "(default: 'task' when the gains file records one, else sine)")
    sw.add_argument("--duration", type=float, default=10.0, help=f"simulated time, {DURATION} (default 10)")
    sw.add_argument("--dt", type=PERIOD, default=None, help=f"control period, {PERIOD} (default 1e-3; or --rate)")
    sw.add_argument("--rate", type=float, default=None, help=f"control rate, {RATE} (instead of --dt)")
    sw.add_argument("--sensing", default=None, choices=("state", "torque"),
                    help="what the controller measures (default: the gains file's sensing, else state)")
    sw.add_argument("--delay-samples", type=DELAY, default=0, help=f"computation delay, {DELAY} (default 0)")
    sw.add_argument("--predict", action="store_true",
                    help="delay compensation by the nominal-model predictor (on when the gains file was designed "
                         "with it)")
    add_interface_argument(sw)
    sw.add_argument("--noise", default="ideal", metavar="PRESET|FILE",
                    help="sensor model: a preset (ideal, panda_white, franka_like) or a TOML sensor file "
                         "(docs/simulation.md); run i gets noise seed --seed + i (default ideal)")
    sw.add_argument("--gains", type=Path, default=None, metavar="FILE",
                    help='gains file (a fjm design output, or JSON {"kind": KIND, "gains": {...}}): its kind and '
                         "gains replace --controller/--lam/--k-s/--delta")
    sw.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="existing dask.distributed scheduler, e.g. tcp://127.0.0.1:8786 (default: local cluster)")
    sw.add_argument("--workers", type=THREADS, default=2, help=f"workers of the local cluster, {THREADS} (default 2)")
    sw.add_argument("--out", type=Path, default=Path("out/sweep.csv"),
                    help="CSV output (default out/sweep.csv; out/ is created if missing, deeper folders are not)")


def stiffness_range(m, k_min, k_max, k_rel):
    """``(k_range, k_relative)`` for :func:`fjm_runtime.batch.sweep.sample_parameters`.

    No bounds given: :data:`ABSOLUTE_K_RANGE` when every nominal stiffness lies in it, else
    :data:`RELATIVE_K_RANGE`. An absolute range given for a model whose nominal stiffnesses lie
    outside :data:`ABSOLUTE_K_RANGE` must contain them (FjmValueError pointing at --k-rel).
    """
    from ..analysis.certificates.box import stiffness_names
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


def gains_file(path: Path, controller) -> dict:
    """``--gains FILE``: ``{"kind", "gains", ...}`` checked (kind against ``--controller``, finite gains)."""
    try:
        spec = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise FjmValueError(f"--gains {path}: cannot read a JSON object ({exc})") from None
    if not isinstance(spec, dict) or not isinstance(spec.get("gains"), dict) or \
            spec.get("kind") not in CONTROLLER_KINDS:
        raise FjmValueError(f"--gains {path}: expected {{\"kind\": one of {', '.join(CONTROLLER_KINDS)}, "
                            "\"gains\": {...}}")
    if controller is not None and controller != spec["kind"]:
        raise FjmValueError(f"--gains {path}: holds gains for {spec['kind']!r}, not --controller {controller!r}")
    for k, v in spec["gains"].items():
        vals = v if isinstance(v, list) else [v]
        if not all(isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) for x in vals):
            raise FjmValueError(f"--gains {path}: gains.{k} = {v!r}; expected a finite number or a list of them")
    return spec


def _period(args) -> float:
    if args.rate is not None and args.dt is not None:
        raise FjmValueError("--rate and --dt: give one of them (the control period is 1 / rate)")
    dt = 1e-3 if args.rate is None and args.dt is None else (args.dt if args.rate is None else 1.0 / args.rate)
    if not (np.isfinite(dt) and 0 < dt <= args.duration):
        given = f"--rate {args.rate:g}" if args.rate is not None else f"--dt {args.dt:g}"
        raise FjmValueError(f"{given}: control period {dt!r} s; expected 0 < period <= --duration {args.duration:g} s")
    return dt


def _reference(m, args, file_spec):
    """``(reference kind, options, x0)``: the gains file's task, or --reference (sine by default)."""
    task = (file_spec or {}).get("reference")
    has_task = isinstance(task, dict) and all(k in task for k in ("offset", "amplitude", "omega"))
    if args.reference == "task" and not has_task:
        raise FjmValueError("--reference task: expected a --gains design file that records its task")
    if args.reference in (None, "task") and has_task:
        from ..batch.sweep import sweep_reference
        from ..sim.rest import rest_state
        opts = {k: task[k] for k in ("offset", "amplitude", "omega")}
        opts["phase"] = float(task.get("phase", 0.0))
        x0 = None
        if "holding gravity" in str(task.get("start", "")):
            ref = sweep_reference("task", opts, int(m.n))
            x0 = tuple(rest_state(m, ref(0.0)[0], m.default_params).tolist())
        return "task", opts, x0
    return args.reference or "sine", {}, None


def _spec(m, args):
    """The :class:`SweepSpec` of the flags (controller, gains, sampled-loop settings), checked."""
    from ..batch.sweep import SweepSpec
    from ..sim.interface import interface_from_record
    from ..sim.sensor import sensor_from_spec
    if args.delay_samples < 0:
        raise FjmValueError(f"--delay-samples {args.delay_samples}: expected >= 0")
    dt = _period(args)
    from .design import MAX_LOOP_SAMPLES, check_samples
    check_samples(args.duration, 1.0 / dt, int(m.n), "--duration/--rate")
    DURATION.check("--duration", args.duration)
    if args.rate is not None:
        RATE.check("--rate", args.rate)
    if args.samples * args.duration / dt > MAX_LOOP_SAMPLES:
        raise FjmValueError(f"--samples {args.samples} x --duration {args.duration:g} s at {1.0 / dt:g} Hz = "
                            f"{args.samples * args.duration / dt:.3g} control samples; expected at most "
                            f"{MAX_LOOP_SAMPLES:g} (hours of batch runs): fewer samples, shorter runs or a lower rate")
    sensor = sensor_from_spec(args.noise, seed=args.seed, what="--noise")
    file_spec = gains_file(args.gains, args.controller) if args.gains is not None else None
    if file_spec is not None:
        kind, options = file_spec["kind"], dict(file_spec["gains"])
        sensing = args.sensing or file_spec.get("sensing", "state")
        predict = bool(args.predict or file_spec.get("predict", False))
    else:
        kind = args.controller or "smc"
        options = {"lam": args.lam, "delta": args.delta if args.delta is not None else default_delta(args.k_s)}
        if kind != "fl":
            options["k_s"] = args.k_s
        sensing, predict = args.sensing or "state", bool(args.predict)
    reference, ref_options, x0 = _reference(m, args, file_spec)
    interface = interface_arg(args) if file_spec is None or args.interface is not None else \
        interface_from_record(file_spec, f"--gains {args.gains}")
    return SweepSpec(model=args.model, controller=kind, controller_options=options, reference=reference,
                     reference_options=ref_options, duration=args.duration, dt=dt, sensing=sensing, sensor=sensor,
                     delay_samples=int(args.delay_samples), predict=predict, x0=x0, interface=interface)


def run(args) -> int:
    """Run ``fjm sweep``; returns the exit status."""
    from .. import load
    from ..batch.sweep import sample_parameters, sweep, write_table
    check_output_file(args.out, "--out", make_parent=True)
    m = load(args.model)
    k_range, k_rel = stiffness_range(m, args.k_min, args.k_max, args.k_rel)
    spec = _spec(m, args)
    P = sample_parameters(m, args.samples, seed=args.seed, k_range=k_range, k_relative=k_rel)
    t0 = time.perf_counter()
    metrics = sweep(spec, P, chunk_size=args.chunk, scheduler=args.scheduler, n_workers=args.workers,
                    progress=lambda d, t: print(f"\rfjm sweep: {d}/{t} chunks", end="", file=sys.stderr,
                                                flush=True))
    print(file=sys.stderr)
    path = write_table(args.out, m, P, metrics)
    out = summary(P, metrics, time.perf_counter() - t0, path)
    out["settings"] = {"controller": spec.controller, "sensing": spec.sensing, "rate": 1.0 / spec.dt,
                       "delay_samples": spec.delay_samples, "predict": spec.predict, "noise": args.noise,
                       "sensor": spec.sensor.name, "interface": spec.interface.as_dict(), "reference": spec.reference,
                       "gains": None if args.gains is None else str(args.gains)}
    print(json.dumps(out, indent=2, allow_nan=False))
    return 0
