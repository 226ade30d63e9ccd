"""``fjm simulate``'s run conditions: what a design file fixes, the default gains, the arm's own limits.

* :func:`take_design_conditions`: ``--gains DESIGN`` brings its rate, delay, prediction, sensing and
  sensor (as ``fjm analyze`` takes them); a flag given explicitly overrides one, and the line it
  returns says which were taken and which overridden.
* :func:`default_gains`: the gains of a run without a design or gain flags (``lam`` = DEFAULT_LAM, ``k_s``
  from Lemma 1 for the paper's link, else FALLBACK_SWITCHING_GAIN, ``delta`` by the layer rule); ``fjm
  analyze`` analyzes the same gains when it is given no ``--gains``.
* :func:`effort_limits`: the torque limit of the run (``--u-max``, else the model's effort limits
  ``Model.limits.effort`` unless ``--no-effort-limits``).
* :func:`position_limit_warning`: the joints whose reference leaves ``Model.limits.position``.
* :func:`peak_until`: the peak applied torque per joint up to a time (a diverged run).
"""
from __future__ import annotations

import math
import sys
from dataclasses import replace
from typing import List, Optional, Tuple

import numpy as np

from ..control.defaults import DEFAULT_LAM, PAPER_K_RANGE, default_delta

__all__ = ["SIMULATE_DEFAULTS", "shipped_for_sensor", "take_design_conditions", "default_gains", "default_design", "effort_limits",
           "run_effort_limits", "position_limit_warning", "peak_until", "peak_text", "say_conditions"]

#: ``fjm simulate``'s conditions without a design file: 1 kHz, state sensing, no delay, no prediction,
#: the ideal sensor (also those of ``fjm analyze`` on the default gains).
SIMULATE_DEFAULTS = {"rate": 1000.0, "sensing": "state", "delay_samples": 0, "predict": False, "noise": "ideal"}


def _recorded(design) -> dict:
    """The conditions a design file records (a hand-written ``{kind, gains}`` records none of them)."""
    out = {"rate": design.rate, "sensing": design.sensing, "delay_samples": design.delay, "predict": design.predict}
    if isinstance(design.sensor, dict) or design.noise is not None:
        out["noise"] = design.same_sensor(design.sensor_model())[1]   # its preset's current name ('panda' -> panda_white)
    return {k: v for k, v in out.items() if v is not None}


def _say(key: str, value) -> str:
    return {"rate": lambda v: f"{float(v):g} Hz", "sensing": lambda v: f"{v} sensing",
            "delay_samples": lambda v: f"delay {int(v)}", "predict": lambda v: "prediction" if v else "no prediction",
            "noise": lambda v: f"sensor {v}"}[key](value)


def take_design_conditions(args, design) -> Optional[str]:
    """Fill ``args.rate``, ``sensing``, ``delay_samples``, ``predict``, ``noise`` left unset (None) from the
    design file (``design``; None: no ``--gains``), else from :data:`SIMULATE_DEFAULTS`.

    ``args.noise`` taken from a design that records its sensor's fields is marked ``args.design_sensor``
    (the run uses those fields, :meth:`Design.sensor_model`, with ``--seed``).

    Returns
    -------
    str or None
        One line (without ``fjm:``) naming the design's conditions taken and the flags that override
        them; None without a design file or when it records no condition.
    """
    recorded = _recorded(design) if design is not None else {}
    args.design_sensor = None
    explicit = {"rate": args.rate is not None or args.dt is not None, "sensing": args.sensing is not None,
                "delay_samples": args.delay_samples is not None, "predict": args.predict is not None,
                "noise": args.noise is not None}
    dt_rate = 1.0 / args.dt if (args.dt is not None and args.dt > 0) else math.nan  # a bad --dt is refused later
    given = {"rate": (dt_rate if args.dt is not None else args.rate), "sensing": args.sensing,
             "delay_samples": args.delay_samples, "predict": args.predict, "noise": args.noise}
    taken, overridden = [], []
    for key, default in SIMULATE_DEFAULTS.items():
        if explicit[key]:
            if key in recorded and not _same(key, given[key], recorded[key]):
                flag = "--" + key.replace("_", "-") if key != "rate" else ("--dt" if args.dt is not None else "--rate")
                overridden.append(f"{flag} {_flag_value(key, given[key], args)} (the design's: "
                                  f"{_say(key, recorded[key])})")
            continue
        value = recorded.get(key, default)
        if key in recorded:
            taken.append(_say(key, value))
        if key == "noise" and key in recorded:
            args.design_sensor = design.sensor_model()
        setattr(args, key, value)
    args.predict = bool(args.predict)
    if not recorded:
        return None
    where = f"--gains {args.gains}" if args.gains is not None else design.source
    line = f"the design's conditions ({where}): {', '.join(taken) or 'none taken'}"
    return line + (f"; overridden on the command line: {'; '.join(overridden)}" if overridden else "")


def shipped_for_sensor(args, m):
    """The shipped design made with ``--noise`` (a preset or sensor file) for this model, at ``--rate`` and
    ``--delay-samples`` when given, for ``--interface`` (default: a ``motor`` one), when no gains, law or
    sensing is asked for (None otherwise): the run then takes the design's conditions as from ``--gains``."""
    from pathlib import Path

    from ..control.design import Design
    from ..sim.interface import interface_from_spec
    from ..sim.sensor import sensor_from_spec
    if args.noise is None or args.gains is not None or args.controller is not None or args.sensing is not None \
            or args.lam is not None or args.k_s is not None or args.delta is not None or args.dt is not None \
            or Path(args.noise).suffix == ".json":
        return None
    sensor = sensor_from_spec(args.noise, seed=args.seed, what="--noise")
    given = getattr(args, "interface", None)
    interface = None if given is None else interface_from_spec(given, what="--interface")
    return Design.shipped_for_sensor(m.name, sensor, args.rate, args.delay_samples, interface)


def _same(key: str, a, b) -> bool:
    if key == "rate":
        return math.isclose(float(a), float(b), rel_tol=1e-9)
    if key == "noise":
        from ..sim.sensor import sensor_from_spec
        try:
            return sensor_from_spec(str(a)).name == sensor_from_spec(str(b)).name
        except ValueError:
            return str(a) == str(b)
    return a == b


def _flag_value(key: str, value, args) -> str:
    if key == "predict":
        return "(on)" if value else "(off: --no-predict)"
    if key == "rate" and args.dt is not None:
        return f"{args.dt:g}"
    return f"{value:g}" if isinstance(value, float) else str(value)


def design_sensor(args):
    """The run's sensor when the design file's is taken (its fields, ``--seed``), else None."""
    sensor = getattr(args, "design_sensor", None)
    return None if sensor is None else replace(sensor, seed=int(args.seed))


def default_gains(m, nominal, ref, *, lam: Optional[float] = DEFAULT_LAM, k_s=None, delta=None,
                  k_bounds=PAPER_K_RANGE, reference: str = "sine", amplitude: float = 0.5, omega: float = 1.0):
    """The gains of a run without a design: ``(lam, k_s, delta, lemma1)``.

    Parameters
    ----------
    m : Model
    nominal : dict
        The controller's nominal parameters.
    ref : Reference
        The run's reference (its derivative bounds enter Lemma 1's gain).
    lam : float or None
        The pole magnitude, 1/s (default DEFAULT_LAM; None: surface coefficients given instead).
    k_s, delta : optional
        Given values (rad/s^4, rad/s^3); None: the default.
    k_bounds : (float, float)
        Lemma 1's stiffness interval, N m/rad.
    reference, amplitude, omega
        The reference kind and, for a sine, its amplitude (rad) and frequency (rad/s): Lemma 1's error box.

    Returns
    -------
    lam : float or None
    k_s : float or ndarray
    delta : float or ndarray
    lemma1 : Lemma1Gain or None
        The Lemma 1 record when ``k_s`` came from it (the paper's link only).
    """
    from ..analysis.certificates.lemma1 import (FALLBACK_SWITCHING_GAIN, default_error_bounds,
                                                default_switching_gain)
    gain = None
    if k_s is None:
        gain = default_switching_gain(m, nominal, lam, ref.derivative_bounds(), k_bounds=k_bounds,
                                      error_bounds=default_error_bounds(reference, amplitude, omega))
        k_s = FALLBACK_SWITCHING_GAIN if gain is None else gain.k_s
    if delta is None and np.all(np.isfinite(np.asarray(k_s, dtype=float))):
        delta = default_delta(k_s)
    return lam, k_s, delta, gain


def default_design(m):
    """``fjm simulate``'s default run as a design: the ``smc`` law with :func:`default_gains` on its default
    reference (0.5 rad sines at 1 rad/s about q = 0), the model's effort limits, and
    :data:`SIMULATE_DEFAULTS`' conditions (what ``fjm analyze`` analyzes without ``--gains``)."""
    from ..control.design import Design
    from ..control.references import make_reference
    n = int(m.n)
    lam, k_s, delta, _ = default_gains(m, {}, make_reference("sine", n, amplitude=0.5, omega=1.0))
    gains = {"lam": float(lam), "k_s": np.asarray(k_s, dtype=float).tolist(), "delta": np.asarray(delta).tolist()}
    u_max = effort_limits(m, None, False)[0]
    if u_max is not None:
        gains["u_max"] = list(u_max)
    task = {"offset": [0.0] * n, "amplitude": [0.5] * n, "omega": [1.0] * n, "start": "at rest on q_d(0)"}
    return Design.from_dict({"model": m.name, "kind": "smc", "sensing": SIMULATE_DEFAULTS["sensing"],
                             "rate": SIMULATE_DEFAULTS["rate"], "delay": SIMULATE_DEFAULTS["delay_samples"],
                             "predict": SIMULATE_DEFAULTS["predict"], "noise": SIMULATE_DEFAULTS["noise"],
                             "reference": task, "gains": gains}, "fjm simulate's default gains")


def effort_limits(m, u_max_flag, off: bool) -> Tuple[Optional[Tuple[float, ...]], str]:
    """The run's torque limit and where it comes from.

    Parameters
    ----------
    m : Model
    u_max_flag : float or None
        ``--u-max`` (N m, every joint).
    off : bool
        ``--no-effort-limits``.

    Returns
    -------
    u_max : tuple of float (n,) or None
        N m per joint; None: no limit.
    origin : str
        ``"--u-max"``, ``"the model's effort limits"``, ``"--no-effort-limits"`` or why none applies.
    """
    n = int(m.n)
    if u_max_flag is not None:
        return tuple([float(u_max_flag)] * n), "--u-max"
    lim = np.asarray(m.limits.effort, dtype=float)
    stated = np.isfinite(lim) & (lim > 0)
    if off:
        return None, "--no-effort-limits"
    if stated.all():
        return tuple(float(v) for v in lim), "the model's effort limits"
    if stated.any():
        joints = ", ".join(str(i + 1) for i in np.flatnonzero(stated))
        return None, f"the model states effort limits for joint(s) {joints} only; --u-max sets one"
    return None, "the model states no effort limits"


#: What :func:`position_limit_warning` suggests by default (``fjm simulate``'s flags).
SIMULATE_REMEDY = "the run goes on (a real arm would stop there: --amplitude, --q-d or another task)"


def position_limit_warning(m, ref, duration: float, dt: float, remedy: str = SIMULATE_REMEDY) -> Optional[str]:
    """One line naming the joints whose reference leaves the model's position limits, or None.

    The reference is sampled on the control grid (at most 20001 evenly spaced times over the run);
    ``remedy`` ends the line (what the command does and what the user can change).
    """
    pos = np.asarray(m.limits.position, dtype=float)
    if not np.any(np.isfinite(pos)):
        return None
    t = np.linspace(0.0, duration, int(min(round(duration / dt) + 1, 20001)))
    q_d = np.asarray(ref.sample(t), dtype=float).reshape(t.size, -1)[:, :int(m.n)]
    lo, hi = q_d.min(axis=0), q_d.max(axis=0)
    out = [f"joint {j + 1} (q_d in [{lo[j]:.3g}, {hi[j]:.3g}] rad, limits [{pos[j, 0]:.3g}, {pos[j, 1]:.3g}] rad)"
           for j in range(int(m.n)) if lo[j] < pos[j, 0] or hi[j] > pos[j, 1]]
    if not out:
        return None
    return f"the reference leaves the position limits of {m.name} on {'; '.join(out)}; {remedy}"


def peak_until(t: np.ndarray, u: np.ndarray, t_end: float) -> List[Optional[float]]:
    """Per joint, the largest ``|u|`` (N m) applied at times ``<= t_end`` (None where not finite)."""
    u = np.asarray(u, dtype=float)[np.asarray(t) <= t_end]
    mag = np.where(np.isfinite(u), np.abs(u), -np.inf)
    peak = mag.max(axis=0) if mag.shape[0] else np.full(u.shape[-1], -np.inf)
    return [float(v) if math.isfinite(float(v)) else None for v in peak]


def run_effort_limits(m, args, design):
    """``(values or None, origin)`` of the run's torque limit; sets ``args.u_max`` for the controller (a
    design's ``gains.u_max`` is the law's own and is kept)."""
    if design is not None and "u_max" in design.gains:
        u = np.broadcast_to(np.asarray(design.gains["u_max"], dtype=float), (int(m.n),))
        return [float(v) for v in u], f"the design's gains.u_max ({design.source})"
    values, origin = effort_limits(m, args.u_max, args.no_effort_limits)
    args.u_max = None if values is None else list(values)
    return (None if values is None else list(values)), origin


def peak_text(peak, limits) -> str:
    """``peak torque up to then: [...] N m`` and the limits applied."""
    shown = ", ".join("not finite" if v is None else f"{v:.4g}" for v in peak)
    lim = "no torque limit" if limits[0] is None else f"limits {', '.join(f'{v:.4g}' for v in limits[0])} N m"
    return f"peak |u| per joint up to then: {shown} N m ({lim}: {limits[1]})"


def say_conditions(m, args, ref, dt, taken, source, provenance, limits, gains) -> None:
    """The stderr lines before a run: the design's conditions taken, where the gains come from and whether
    they hold, the effort limits of the model applied, a reference beyond the position limits."""
    if taken:
        print(f"fjm: {taken}", file=sys.stderr)
    if not provenance["designed_for_these_conditions"]:
        if source == "defaults" and gains[1] is None:   # an impedance law: its defaults from the nominal drives
            what = "law's default gains (from the nominal stiffness and inertia)"
        else:
            what = (f"default gains (lam {gains[0]:g} 1/s, k_s {short_gain(gains[1])} rad/s^4, delta "
                    f"{short_gain(gains[2])} rad/s^3)" if source == "defaults" else f"gains ({source})")
        print(f"fjm: warning: the {what} were not designed for {m.name} under these conditions: "
              f"{'; '.join(provenance['not_designed_because'])}", file=sys.stderr)
    elif source.startswith("shipped"):
        print(f"fjm: using the {source} (designed for these conditions)", file=sys.stderr)
    if limits[1] == "the model's effort limits":
        print(f"fjm: effort limits applied: {', '.join(f'{v:g}' for v in limits[0])} N m (the model's; "
              "--no-effort-limits turns them off)", file=sys.stderr)
    warn = position_limit_warning(m, ref, args.duration, dt)
    if warn:
        print(f"fjm: warning: {warn}", file=sys.stderr)


def short_gain(v) -> str:
    """A gain for a message: one number when every joint has it, else the list (4 digits)."""
    a = np.atleast_1d(np.asarray(v, dtype=float))
    return f"{a[0]:.4g}" if np.all(a == a[0]) else "[" + ", ".join(f"{x:.4g}" for x in a) + "]"
