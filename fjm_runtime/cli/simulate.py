"""``fjm simulate MODEL ...``: one sampled-data closed loop, metrics as JSON on stdout, optionally a PNG.

``--json`` prints one object for scripts (docs/simulation.md): ``diverged``, per-joint
``rms_second_half``, ``peak_torque``, ``time_at_limit``, ``torque_jitter``, where the gains came from
(``gains_source``, ``designed_for_these_conditions``) and the settings used. Bad input, a run too
large to hold and gains for another model are refused before any work
(:mod:`fjm_runtime.cli.simulate_checks`); a run that diverges or leaves the workspace exits 3.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Dict, Optional

import numpy as np

from .models import MODEL_HELP
from ..analysis.certificates.lemma1 import FALLBACK_SWITCHING_GAIN, paper_beta_hat, paper_bound_applies
from ..control.defaults import DEFAULT_LAM, DEFAULT_LAYER_RATE, PAPER_K_RANGE, default_delta
from ..control.factory import CONTROLLER_KINDS, FULL_SENSED_KINDS, make_controller
from ..control.references import REFERENCE_KINDS, make_reference
from ..drives import drive_indices, linear_stiffness_indices
from ..sim.metrics import peak_torque, rms_second_half, time_at_limit, time_at_rate_limit, torque_jitter
from ..sim.sensor import PRESETS, SensorModel, sensor_from_spec
from ..sim.simulate import simulate, stderr_progress
from ..sim.step import SimulationDivergedError
from ..validation import FjmValueError, check_magnitudes
from .common import add_interface_argument, check_output_file, finite_or_note, interface_arg, parse_assignments
from .ranges import ANGLE, DELAY, DURATION, FACTOR, GAIN, LAYER, MASS, PERIOD, RATE, SEED, STIFFNESS, TORQUE
from ..control.design import Design
from .simulate_checks import (DEFAULT_MAX_MEMORY_GB, MAX_SUBSTEPS, MEMORY_GB, check_flag_ranges,
                              check_gain_magnitudes, check_pole, check_run_size, check_substeps, gains_provenance,
                              workspace_exit)
from .simulate_laws import check_run_interface, check_set_point, impedance_controller, take_law_sensing
from .simulate_conditions import (default_gains, design_sensor, peak_text, peak_until, run_effort_limits,
                                  say_conditions, shipped_for_sensor, take_design_conditions)


def add_arguments(sim) -> None:
    """The arguments of ``fjm simulate`` on its parser ``sim`` (name, help, description: commands.toml)."""
    sim.add_argument("model", help=MODEL_HELP)
    sim.add_argument("--controller", default=None, choices=CONTROLLER_KINDS + FULL_SENSED_KINDS,
                     help="smc: paper's law with sat; sign: paper's discontinuous law; ismc: integral "
                          "sliding surface; fl: plain feedback linearization; adaptive: integral surface "
                          "with an online stiffness estimate projected onto [--k-min, --k-max]; impedance: "
                          "motor-side impedance with torque feedback (motor interface); joint_impedance: "
                          "link-side impedance, tau_d for a joint_torque interface (both read q, dq, q_m, dq_m, "
                          "tau_J, dtau_J) (default: the kind of --gains, else smc)")
    sim.add_argument("--reference", default=None,
                     help=f"one of {', '.join(REFERENCE_KINDS)}, or 'task': the task the gains were designed on "
                          "(default: 'task' when the gains come from a design file that records one, else sine)")
    sim.add_argument("--q-d", type=ANGLE, default=1.0, help=f"set point for step/constant, {ANGLE} (default 1)")
    sim.add_argument("--rise-time", type=DURATION, default=2.0, help=f"smooth step duration, {DURATION} (default 2)")
    sim.add_argument("--amplitude", type=float, default=0.5,
                     help="sine amplitude, rad (default 0.5; a run beyond 4 pi rad leaves the workspace, exit 3)")
    sim.add_argument("--omega", type=float, default=1.0, help="sine frequency, 0 <= omega <= pi x rate rad/s (default 1)")
    sim.add_argument("--duration", type=float, default=10.0,
                     help=f"simulated time, {DURATION}, and duration x rate within --max-memory (default 10)")
    sim.add_argument("--dt", type=PERIOD, default=None, help=f"control period, {PERIOD} (default 1e-3; or --rate)")
    sim.add_argument("--K", type=float, default=None,
                     help=f"TRUE joint stiffness of the plant, {STIFFNESS}, and at most {MAX_SUBSTEPS} RK4 substeps per sample "
                          "(link1: K; planar<n>: every K_i)")
    sim.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                     help="TRUE plant parameter (repeatable), e.g. --param J_l=1.2")
    sim.add_argument("--nominal", action="append", default=[], metavar="NAME=VALUE",
                     help="NOMINAL controller parameter (repeatable); default: model defaults")
    sim.add_argument("--lam", type=float, default=None,
                     help=f"pole magnitude lambda, 1/s, at most pi x rate (default {DEFAULT_LAM:g})")
    sim.add_argument("--k-s", type=GAIN, default=None,
                     help=f"switching gain, {GAIN} (default: Lemma 1 bound for link1 with K in "
                          f"[--k-min, --k-max]; {FALLBACK_SWITCHING_GAIN:g} otherwise)")
    sim.add_argument("--delta", type=LAYER, default=None,
                     help=f"boundary layer, {LAYER} (default max(k_s, 1) / {DEFAULT_LAYER_RATE:g})")
    sim.add_argument("--k-min", type=STIFFNESS, default=PAPER_K_RANGE[0],
                     help=f"stiffness lower bound for Lemma 1, {STIFFNESS} (default {PAPER_K_RANGE[0]:g})")
    sim.add_argument("--k-max", type=STIFFNESS, default=PAPER_K_RANGE[1],
                     help=f"stiffness upper bound for Lemma 1, {STIFFNESS} (default {PAPER_K_RANGE[1]:g})")
    sim.add_argument("--beta-hat", choices=("paper", "model"), default="paper",
                     help="link1: paper's constant (beta_max + beta_min)/2 or beta(x; nominal) (default paper)")
    sim.add_argument("--u-max", type=TORQUE, default=None,
                     help=f"torque limit, {TORQUE}, every joint (default: the model's effort limits, Model.limits.effort)")
    sim.add_argument("--no-effort-limits", action="store_true",
                     help="apply no torque limit where the model states effort limits (a design's u_max stays)")
    sim.add_argument("--plot", type=Path, default=None,
                     help="write a PNG of angles, error, torque and s (its directory must exist)")
    sim.add_argument("--quiet", action="store_true", help="no progress on stderr")
    _add_sampled_data_flags(sim)


def _add_sampled_data_flags(sim) -> None:
    """The sampled-data and scripting flags (rate, substeps, sensing, noise, delay, scales, gains, --json)."""
    sim.add_argument("--rate", type=float, default=None,
                     help=f"control rate, {RATE}, and duration x rate within --max-memory (same as --dt 1/HZ; "
                          "default: the --gains file's, else 1000)")
    sim.add_argument("--substeps", type=int, default=None,
                     help=f"RK4 plant steps per control sample, 1..{MAX_SUBSTEPS} (default: the fastest-mode rule)")
    sim.add_argument("--sensing", choices=("state", "torque", "full"), default=None,
                     help="what the controller measures: the state, or q, dq, tau_J, dtau_J, dq_m, or (full, the "
                          "impedance laws') q, dq, q_m, dq_m, tau_J, dtau_J (default: the --gains file's, else full "
                          "for the impedance laws, else state)")
    sim.add_argument("--delay-samples", type=int, default=None,
                     help=f"computation delay in samples, {DELAY} (default: the --gains "
                          "file's, else 0)")
    sim.add_argument("--predict", action=argparse.BooleanOptionalAction, default=None,
                     help="predict the delayed measurement with the nominal model (default: the --gains file's, "
                          "else off)")
    sim.add_argument("--noise", default=None,
                     help="sensor model: a preset (ideal, panda_white, franka_like) or a TOML sensor file "
                          "(docs/simulation.md; default: the --gains file's sensor, else ideal)")
    sim.add_argument("--seed", type=SEED, default=0, help=f"noise seed, {SEED} (default 0)")
    add_interface_argument(sim)
    sim.add_argument("--k-scale", default=None, metavar="A[,B,..]",
                     help="TRUE stiffness = nominal x A (one value, or one per joint)")
    sim.add_argument("--jm-scale", default=None, metavar="A[,B,..]",
                     help="TRUE motor inertia = nominal x A (one value, or one per joint)")
    sim.add_argument("--payload", type=MASS, default=None,
                     help=f"TRUE payload mass, {MASS} (models with an m_load parameter)")
    sim.add_argument("--params", type=Path, default=None, metavar="FILE",
                     help="parameter file (TOML [parameters], e.g. from `fjm identify`): the controller's NOMINAL "
                          "values (over the gains file's; --nominal overrides them)")
    sim.add_argument("--gains", type=Path, default=None,
                     help='JSON {"kind": KIND, "gains": {lam, k_s, delta, k_lin, u_max, ...}} (docs/simulation.md)')
    sim.add_argument("--json", action="store_true",
                     help="print one JSON object for scripts (diverged, per-joint metrics, settings)")
    sim.add_argument("--max-memory", type=float, default=DEFAULT_MAX_MEMORY_GB, metavar="GB",
                     help=f"refuse a run whose estimated peak memory exceeds this, {MEMORY_GB} "
                          f"(default {DEFAULT_MAX_MEMORY_GB:g})")


def _scales(text: Optional[str], n: int, flag: str) -> Optional[np.ndarray]:
    """``'0.7,1.3'`` -> per-joint factors (one value broadcast); FjmValueError on anything else."""
    if text is None:
        return None
    try:
        vals = np.array([float(v) for v in text.split(",")], dtype=float)
    except ValueError:
        raise FjmValueError(f"{flag} {text!r}: expected numbers separated by commas, e.g. {flag} 0.7,1.3") from None
    if vals.size == 1:
        vals = np.full(n, vals[0])
    if vals.size != n or not all(FACTOR.contains(v) for v in vals):
        raise FjmValueError(f"{flag} {text!r}: expected one or {n} factors {FACTOR}")
    return vals


def _true_params(m, args, nominal) -> Dict[str, float]:
    true = parse_assignments(args.param, "--param")
    check_magnitudes(true, true.values(), "--param ")
    if args.K is not None:
        if not args.K > 0:                        # above: the substeps it needs, then STIFFNESS (check_flag_ranges)
            STIFFNESS.check("--K", args.K)
        for i in linear_stiffness_indices(m, "--K"):
            true.setdefault(m.param_names[i], args.K)
    p_nom = m.params_array(nominal, arg="--nominal")
    m.params_array(true, arg="--param")           # the user's values named by their flag, not p[...]
    for flag, text, role in (("--k-scale", args.k_scale, "stiffness"), ("--jm-scale", args.jm_scale, "rotor_inertia")):
        factors = _scales(text, m.n, flag)
        if factors is not None:
            linear_stiffness_indices(m, flag)     # the scales are for linear springs: refused on a nonlinear one
            for j, i in enumerate(drive_indices(m, role)):
                true[m.param_names[i]] = float(p_nom[i] * factors[j])
    if args.payload is not None:
        if "m_load" not in m.param_names:
            raise FjmValueError(f"--payload: model {m.name} has no m_load parameter (expected a model with a payload)")
        if not (math.isfinite(args.payload) and args.payload >= 0):
            raise FjmValueError(f"--payload {args.payload}: expected a finite mass >= 0 kg")
        true["m_load"] = float(args.payload)
    return true


def _sensor(args) -> SensorModel:
    """``--noise PRESET|FILE.toml`` (presets: ideal, panda_white, franka_like; ``none``, ``panda`` the former
    names) with ``--seed``; a ``.json`` file of SensorModel fields is still read; the ``--gains`` file's
    sensor when it was taken (:func:`take_design_conditions`)."""
    taken = design_sensor(args)
    if taken is not None:
        return taken
    path = Path(args.noise)
    if path.suffix != ".json":
        return sensor_from_spec(args.noise, seed=args.seed, what="--noise")
    if not path.is_file():
        raise FjmValueError(f"--noise {args.noise!r}: expected a preset among {sorted(PRESETS)}, a .toml sensor "
                            "file or an existing .json file")
    try:
        fields = json.loads(path.read_text())
    except ValueError as exc:
        raise FjmValueError(f"--noise {path}: not valid JSON ({exc})") from None
    if not isinstance(fields, dict):
        raise FjmValueError(f"--noise {path}: expected a JSON object of SensorModel fields")
    fields.setdefault("seed", args.seed)
    return SensorModel.from_dict(fields, where=f"--noise {path}")


def _load_gains(args) -> Optional[Design]:
    """The ``--gains FILE`` design (``{"kind": ..., "gains": {...}}`` or a fjm design output), its kind checked
    against --controller; None without ``--gains``."""
    if args.gains is None:
        return None
    design = Design.load(args.gains)
    if args.controller is not None and args.controller != design.kind:
        raise FjmValueError(f"--gains {args.gains}: holds gains for {design.kind!r}, not --controller "
                            f"{args.controller!r}")
    return design


def _gains_file(args, m, rate: float, design: Optional[Design]):
    """``(design, source)``: the ``--gains`` design, else the shipped design for this model, rate, delay and
    sensing (any kind unless --controller names one) when no gain flag is given, else the flags or the
    defaults (design None; source ``"command line"`` or ``"defaults"``). Every design is checked against
    the model before any work (:meth:`Design.check`)."""
    if design is not None:
        design.check(m)
        check_gain_magnitudes(args.gains, design)
        return design, (f"--gains {args.gains}" if args.gains is not None else design.source)
    flags_given = args.lam is not None or args.k_s is not None or args.delta is not None
    shipped = None if flags_given else Design.shipped(m.name, args.controller, args.sensing, rate,
                                                      args.delay_samples)
    if shipped is None:
        return None, "command line" if flags_given else "defaults"
    return shipped.check(m), shipped.source


def _period(args) -> float:
    if args.rate is not None and args.dt is not None:
        raise FjmValueError("--rate and --dt: give one of them (the control period is 1 / rate)")
    if args.rate is not None:
        if not (math.isfinite(args.rate) and args.rate > 0):
            raise FjmValueError(f"--rate {args.rate}: expected a finite rate > 0 Hz")
        return 1.0 / args.rate
    if args.dt is not None and not (math.isfinite(args.dt) and 0 < args.dt <= args.duration):
        raise FjmValueError(f"--dt {args.dt}: expected a finite control period 0 < dt <= --duration s")
    return 1e-3 if args.dt is None else args.dt


def _check_flags(args, dt: float) -> None:
    """The run's scalar flags, before any work: a finite duration, a reference a law sampled at
    ``1/dt`` can follow (sine frequency up to the Nyquist frequency ``pi / dt``), finite set points."""
    if not (math.isfinite(args.duration) and args.duration > 0):
        raise FjmValueError(f"--duration {args.duration}: expected a finite time > 0 s")
    if dt > args.duration:
        raise FjmValueError(f"--duration {args.duration}: expected at least one control period ({dt:g} s)")
    nyquist = math.pi / dt
    if not (math.isfinite(args.omega) and 0 <= args.omega <= nyquist):
        raise FjmValueError(f"--omega {args.omega}: expected a sine frequency 0 <= omega <= pi x rate = "
                            f"{nyquist:.4g} rad/s (the Nyquist frequency)")
    for flag, v in (("--amplitude", args.amplitude), ("--q-d", args.q_d)):
        if not math.isfinite(v):
            raise FjmValueError(f"{flag} {v}: expected a finite angle (rad)")
    if not (math.isfinite(args.rise_time) and args.rise_time > 0):
        raise FjmValueError(f"--rise-time {args.rise_time}: expected a finite time > 0 s")


def _build_controller(m, args, nominal, ref, kind, file_gains):
    """The controller of the run and the Lemma 1 gain record (or None)."""
    if kind in FULL_SENSED_KINDS:
        return impedance_controller(m, args, nominal, kind, file_gains), None, None, None
    k_bounds = (args.k_min, args.k_max)
    extra: Dict[str, object] = {}
    if args.beta_hat == "paper" and paper_bound_applies(m) and args.sensing == "state":
        extra["beta_hat"] = paper_beta_hat(m, nominal, k_bounds)
    gain = None
    k_s = file_gains.get("k_s", args.k_s)
    rate = 1.0 / _period(args)
    if "lam" in file_gains:
        lam = check_pole(file_gains["lam"], rate, f"--gains {args.gains or 'shipped design'}: gains.lam =")
    elif "c" not in file_gains:
        lam = check_pole(DEFAULT_LAM if args.lam is None else args.lam, rate, "--lam")
    else:
        lam = None
    if k_s is None:
        _, k_s, _, gain = default_gains(m, nominal, ref, lam=lam, k_bounds=k_bounds, reference=args.reference,
                                        amplitude=args.amplitude, omega=args.omega)
        if not np.all(np.isfinite(np.asarray(k_s, dtype=float))):
            raise FjmValueError(f"Lemma 1 switching gain {k_s!r} for the nominal parameters and --k-min/--k-max "
                                f"{args.k_min:g}/{args.k_max:g}: not finite; expected parameters in a physical "
                                "range (--nominal) or an explicit --k-s")
    delta = file_gains.get("delta", args.delta if args.delta is not None else default_delta(k_s))
    if kind == "adaptive":
        # beta from the estimated stiffness (not the paper's constant); the bounds project K_hat
        extra.pop("beta_hat", None)
        if not (0 < args.k_min < args.k_max):
            raise FjmValueError(f"--k-min/--k-max = {args.k_min}/{args.k_max}: expected 0 < k_min < k_max "
                                "for the adaptive controller")
        extra["K_bounds"] = k_bounds
    kw = {"k_s": k_s, "delta": delta, "u_max": args.u_max, **extra}
    if lam is not None:
        kw["lam"] = args.lam = lam
    kw.update({k: v for k, v in file_gains.items() if k not in ("lam", "k_s", "delta")})
    if args.sensing != "state":
        kw["sensing"] = args.sensing
    try:
        ctrl = make_controller(kind, m, nominal, **kw)
    except TypeError as exc:
        raise FjmValueError(f"--gains/--sensing: {exc}") from None
    return ctrl, gain, k_s, delta


def _per_joint(values) -> list:
    """A per-joint array as a JSON list, ``None`` where not finite."""
    return [float(v) if math.isfinite(float(v)) else None for v in np.asarray(values, dtype=float)]


def _script_report(res, settings: dict, diverged: Optional[SimulationDivergedError], provenance: dict,
                   left=None) -> dict:
    """The ``--json`` object: diverged (the state blew up, or ``left`` = ``(t, reason)``: the run left the
    workspace; then with the time and reason but metrics kept), per-joint metrics (null plus a reason),
    where the gains came from (``provenance``), the settings."""
    out: Dict[str, object] = {"diverged": diverged is not None or left is not None}
    if left is not None:
        out["divergence_time"], out["reason"] = float(left[0]), left[1]
        out["peak_torque_until_divergence"] = peak_until(res.t[:-1], res.u[:-1], left[0])
    names = ("rms_second_half", "peak_torque", "time_at_limit", "torque_jitter", "time_at_rate_limit")
    if diverged is not None:
        out.update({k: None for k in names})
        out["reason"] = str(diverged)
        out["divergence_time"] = float(diverged.t)
        if diverged.peak_torque is not None:
            out["peak_torque_until_divergence"] = _per_joint(diverged.peak_torque)
    else:
        fns = (rms_second_half, peak_torque, time_at_limit, torque_jitter, time_at_rate_limit)
        for k, fn in zip(names, fns):
            out[k] = _per_joint(fn(res))
            if any(v is None for v in out[k]):
                out[k + "_note"] = "not finite (run shorter than the 20 ms jitter window?)"
        out["metrics"] = {}
        for k, v in res.metrics.as_dict().items():
            finite_or_note(out["metrics"], k, v)
    out.update(provenance)
    out["settings"] = settings
    return out


def _reference(m, args, design: Optional[Design]):
    """``(reference, x0)``: ``--reference`` (None: the gains file's task if it records one, else sine)."""
    task = None
    if design is not None and args.reference in (None, "task"):
        ref = design.reference(m)
        task = None if ref is None else (ref, design.start_state(m))
    if args.reference == "task" and task is None:
        raise FjmValueError("--reference task: the gains (file or shipped design) record no task; expected "
                            f"one of {', '.join(REFERENCE_KINDS)}")
    if task is not None:
        args.reference = "task"
        return task
    args.reference = args.reference or "sine"
    ref_kw = {"sine": {"amplitude": args.amplitude, "omega": args.omega},
              "step": {"q_d": args.q_d, "rise_time": args.rise_time},
              "constant": {"q_d": args.q_d}}.get(args.reference, {})
    return make_reference(args.reference, m.n, **ref_kw), None


def params_file_nominal(path, m) -> Dict[str, float]:
    """The ``[parameters]`` of a parameter file (``--params``, docs/design-command.md), ``{}`` without one."""
    if path is None:
        return {}
    from ..analysis.search.draws import load_params_file
    return dict(load_params_file(path, m).overrides)


def run(args) -> int:
    """Run ``fjm simulate``; returns the exit status (3: the run diverged or left the workspace)."""
    from .. import load
    if args.plot is not None:
        check_output_file(args.plot, "--plot")
    m = load(args.model)
    file_design = _load_gains(args)
    by_sensor = None if file_design is not None else shipped_for_sensor(args, m)
    take_law_sensing(args, file_design or by_sensor)
    taken = take_design_conditions(args, file_design or by_sensor)
    dt = _period(args)
    _check_flags(args, dt)
    sensor = _sensor(args)
    design, source = _gains_file(args, m, 1.0 / dt, file_design or by_sensor)
    from_file = params_file_nominal(args.params, m)
    check_magnitudes(from_file, from_file.values(), f"--params {args.params}: [parameters] ")
    given = parse_assignments(args.nominal, "--nominal")
    check_magnitudes(given, given.values(), "--nominal ")
    nominal = {**(design.nominal(m) if design else {}), **from_file, **given}
    true = _true_params(m, args, nominal)
    kind = design.kind if design else (args.controller or "smc")
    ref, x0 = _reference(m, args, design)
    limits = run_effort_limits(m, args, design)
    ctrl, gain, k_s, delta = _build_controller(m, args, nominal, ref, kind, design.gains if design else {})
    if file_design is None:  # a shipped design made with prediction keeps it
        args.predict = bool(args.predict or (design and design.predict))
    interface = interface_arg(args, design)
    check_run_interface(kind, interface, args, design)
    check_set_point(kind, m, args, ref, nominal)
    _check_size(m, args, ctrl, ref, x0, true, sensor, dt, interface)
    conditions = {"model": m.name, "kind": kind, "sensing": args.sensing, "rate": 1.0 / dt,
                  "delay": args.delay_samples, "predict": bool(args.predict), "sensor": sensor, "interface": interface}
    provenance = gains_provenance(source, design, conditions,
                                  None if gain is None else f"K in [{args.k_min:g}, {args.k_max:g}]")
    say_conditions(m, args, ref, dt, taken, source, provenance, limits, (args.lam, k_s, delta))
    progress = None if (args.quiet or args.json) else stderr_progress(f"simulating {args.model} ({args.duration:g} s)")
    settings = {"model": m.name, "controller": kind, "rate": 1.0 / dt, "dt": dt, "substeps": args.substeps,
                "delay_samples": args.delay_samples, "predict": bool(args.predict), "sensing": args.sensing,
                "seed": args.seed, "noise": args.noise, "interface": interface.as_dict(),
                "duration": args.duration,
                "effort_limits": limits[0], "effort_limits_from": limits[1],
                "true_params": dict(zip(m.param_names, m.params_array(true).tolist())),
                "nominal_params": dict(zip(m.param_names, m.params_array(nominal).tolist())),
                "gains": str(args.gains) if args.gains is not None else (design.file if design else None)}
    try:
        res = simulate(m, ctrl, ref, duration=args.duration, dt=dt, true_params=true, progress=progress, x0=x0,
                       substeps=args.substeps, sensor=sensor, delay_samples=args.delay_samples,
                       predict=args.predict, interface=interface)
    except SimulationDivergedError as exc:
        if args.json:
            print(json.dumps(_script_report(None, settings, exc, provenance), allow_nan=False))
        peak = "" if exc.peak_torque is None else f"; {peak_text(_per_joint(exc.peak_torque), limits)}"
        print(f"fjm: diverged: {exc}{peak}", file=sys.stderr)
        return 3
    settings["substeps"] = res.settings["substeps"]
    left = workspace_exit(res.t, res.x[:, :m.n], res.e1)
    if args.json:
        print(json.dumps(_script_report(res, settings, None, provenance, left), allow_nan=False))
        status = 0
    else:
        status = _print_report(m, args, res, kind, true, nominal, k_s, delta, gain, ctrl, provenance, left, limits)
    if left is not None:
        peak = peak_until(res.t[:-1], res.u[:-1], left[0])
        print(f"fjm: diverged: the run {left[1]}; {peak_text(peak, limits)}", file=sys.stderr)
        return 3
    return status


def _check_size(m, args, ctrl, ref, x0, true, sensor, dt, interface) -> None:
    """Refuse, before allocating, a run whose substeps or memory are out of reach (:func:`check_run_size`)."""
    from ..sim.sample_step import check_loop_settings
    from ..sim.step_layout import make_layout
    from ..sim.substeps import SAFETY, STEP_PER_RADIAN, fastest_mode
    sensor, delay = check_loop_settings(sensor, args.delay_samples, args.predict)
    if args.substeps is not None and (isinstance(args.substeps, bool) or args.substeps < 1):
        raise FjmValueError(f"--substeps {args.substeps}: expected an integer >= 1 (RK4 steps per control sample)")
    p_true = m.params_array(true)
    if x0 is None:
        q0 = np.asarray(ref(0.0), dtype=float)[0]
        x0 = np.concatenate([q0, np.zeros(m.n), q0, np.zeros(m.n)])
    with np.errstate(all="ignore"):
        omega = fastest_mode(m, x0, p_true)
    if not math.isfinite(omega):
        raise FjmValueError("the plant's fastest mode at the TRUE parameters is not finite; expected a "
                            "stiffness and inertia in a physical range (--K, --param, --k-scale, --jm-scale)")
    subs = args.substeps if args.substeps is not None else max(1.0, SAFETY * dt * omega / STEP_PER_RADIAN)
    check_substeps(subs, None if args.substeps is not None else omega)
    subs = int(math.ceil(subs - 1e-12))
    layout = make_layout(m, ctrl, dt, subs, sensor, delay, args.predict, interface=interface)
    check_run_size(layout.nw, m.n, layout.nm, args.duration, dt, args.max_memory)
    check_flag_ranges(args)


def _print_report(m, args, res, kind, true, nominal, k_s, delta, gain, ctrl, provenance, left, limits) -> int:
    """The indented report (and the optional PNG) of ``fjm simulate`` without ``--json``."""
    metrics: Dict[str, object] = {}
    for k, v in res.metrics.as_dict().items():
        finite_or_note(metrics, k, v)
    report = {"model": m.name, "controller": kind, "reference": args.reference,
              "true_params": dict(zip(m.param_names, m.params_array(true).tolist())),
              "nominal_params": dict(zip(m.param_names, m.params_array(nominal).tolist())),
              "lam": args.lam, "k_s": k_s, "delta": delta,
              "lemma1": None if gain is None else {"k_s": gain.k_s, "k_s_tight": gain.k_s_tight, "W": gain.W,
                                                   "H": gain.H, "beta_hat": gain.beta_hat},
              "effort_limits": limits[0], "effort_limits_from": limits[1],
              "settings": res.settings, "metrics": metrics, **provenance,
              "diverged": left is not None}
    if left is not None:
        report["divergence_time"], report["reason"] = float(left[0]), left[1]
        report["peak_torque_until_divergence"] = peak_until(res.t[:-1], res.u[:-1], left[0])
    if hasattr(ctrl, "stiffness_estimate"):
        report["K_hat_final"] = ctrl.stiffness_estimate(res.z[-1]).tolist()
    print(json.dumps(report, indent=2, allow_nan=False))
    if args.plot is not None:
        from ..sim.plot import pyplot
        mt = res.metrics
        fig = res.plot(args.plot, f"{args.model}, {kind}, reference {args.reference}: final |e1| = "
                                  f"{mt.final_error:.3g} rad, RMS = {mt.rms_error:.3g} rad, "
                                  f"max |u| = {mt.max_abs_u:.3g} N m")
        pyplot().close(fig)
        print(f"  wrote {args.plot}", file=sys.stderr, flush=True)
    return 0
