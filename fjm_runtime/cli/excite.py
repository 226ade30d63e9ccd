"""``fjm excite MODEL --duration T --out traj.csv``: an excitation trajectory for ``fjm identify``."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .models import MODEL_HELP
from ..validation import FjmValueError
from .common import check_output_file
from .ranges import AMPLITUDE, ANGLE, DURATION, RATE, SEED, Range, check_stored_size

__all__ = ["add_arguments", "run"]

#: Harmonics per joint: two of each kind go to starting at rest; the search's cost grows with them.
HARMONICS = Range(3, 1000, "", "harmonics", integer=True)
#: Lowest base frequency, Hz.
BASE_FREQUENCY = Range(0, 1000, "Hz", "f0", lo_open=True)
#: Random series drawn, and local-search iterations (each rates the series on one period).
CANDIDATES = Range(1, 1000, "", "candidates", integer=True)
ITERATIONS = Range(0, 10_000, "", "iterations", integer=True)
#: Most Fourier terms (sample x harmonic x joint) the search and the final rating evaluate: each series is
#: rated up to 12 times on min(samples per period, 400) samples, the chosen one up to 20 times on a whole
#: period of the log's grid; numpy evaluates ~1e8 terms/s, so this is under a minute.
MAX_FOURIER_TERMS = 2e9
#: Columns held per sample besides the CSV's 1 + 7n: the closed-loop check's stored run (state, torque,
#: reference, noise, outputs), about 20 per joint, held twice while it is written.
CHECK_COLUMNS_PER_JOINT = 20


def add_arguments(p) -> None:
    """The arguments of ``fjm excite`` on its parser ``p`` (name, help, description: commands.toml)."""
    p.add_argument("model", help=MODEL_HELP)
    p.add_argument("--duration", type=DURATION, required=True,
                   help=f"length, {DURATION}: whole base periods (the base frequency is raised to fit)")
    p.add_argument("--out", type=Path, required=True, help="CSV t, q_d_<i>, dq_d_<i>, ddq_d_<i>, q_m_d_<i>, "
                   "dq_m_d_<i>, tau_J_d_<i>, u_ff_<i> (and OUT.json: coefficients, conditions, limits' usage)")
    p.add_argument("--harmonics", type=HARMONICS, default=5,
                   help=f"harmonics per joint, {HARMONICS}, the highest below the Nyquist frequency (default 5)")
    p.add_argument("--base-freq", type=BASE_FREQUENCY, default=0.2,
                   help=f"lowest base frequency, {BASE_FREQUENCY} (default 0.2)")
    p.add_argument("--amplitude", type=AMPLITUDE, default=0.5,
                   help=f"largest excursion from the posture, {AMPLITUDE} (default 0.5)")
    p.add_argument("--posture", default=None, metavar="Q1,Q2,...",
                   help=f"base posture, each angle {ANGLE} (default: the middle of the joint ranges, 0 where none is "
                        "stated)")
    p.add_argument("--candidates", type=CANDIDATES, default=20, help=f"random series drawn, {CANDIDATES} (default 20)")
    p.add_argument("--iterations", type=ITERATIONS, default=40,
                   help=f"local-search iterations after them, {ITERATIONS} (default 40)")
    p.add_argument("--rate", type=RATE, default=1000.0, help=f"sample rate of the CSV, {RATE} (default 1000)")
    p.add_argument("--seed", type=SEED, default=0, help=f"seed of the random draws, {SEED} (default 0)")
    p.add_argument("--check-noise", default="franka_like", metavar="PRESET|FILE",
                   help="sensor of the closed-loop check (default franka_like)")
    p.add_argument("--no-check", action="store_true", help="skip the closed-loop check on the nominal model")


def _posture(text, n: int):
    if text is None:
        return None
    try:
        q = np.array([float(v) for v in str(text).split(",")])
    except ValueError:
        q = np.array([np.nan])
    if q.size != n or not all(ANGLE.contains(v) for v in q):
        raise FjmValueError(f"--posture {text!r}: expected {n} comma-separated angles, each {ANGLE}")
    return q


def _check_size(args, n: int) -> None:
    """Refuse, before any work, a log too long to hold and harmonics beyond the Nyquist frequency."""
    rows = math.floor(args.duration * args.rate) + 1
    check_stored_size(f"--duration {args.duration:g} s at --rate {args.rate:g} Hz", rows,
                      1 + 7 * n + CHECK_COLUMNS_PER_JOINT * n, "shorten --duration or lower --rate", factor=2)
    from ..ident.excite import SEARCH_SAMPLES, whole_periods
    per = whole_periods(args.duration, args.base_freq, args.rate)[2]
    check_stored_size(f"--harmonics {args.harmonics} on one period of {per} samples (--duration {args.duration:g} s, "
                      f"--rate {args.rate:g} Hz)", per, args.harmonics, "lower --harmonics or --rate", factor=6)
    terms = ((args.candidates + args.iterations) * 12 * min(per, SEARCH_SAMPLES) + 20 * per) * args.harmonics * n
    if terms > MAX_FOURIER_TERMS:
        raise FjmValueError(f"--harmonics {args.harmonics}, --candidates {args.candidates}, --iterations "
                            f"{args.iterations} on {n} joint(s) and {per} samples per period: {terms:.3g} Fourier "
                            f"terms to evaluate; expected at most {MAX_FOURIER_TERMS:g} (under a minute): lower "
                            "--harmonics, --candidates, --iterations or --rate")
    if args.harmonics * args.base_freq >= args.rate / 2:
        raise FjmValueError(f"--harmonics {args.harmonics}: the highest harmonic, {args.harmonics} x --base-freq "
                            f"{args.base_freq:g} Hz, is at or beyond the Nyquist frequency {args.rate / 2:g} Hz of "
                            f"--rate {args.rate:g}; expected harmonics < {args.rate / 2 / args.base_freq:g}")


def _usage_line(use: dict) -> str:
    parts = []
    for k in ("position", "velocity", "torque"):
        if use.get(k) is not None:
            parts.append(f"{k} {100 * use[k]:.0f} % (joint {int(np.argmax(use[k + '_joints'])) + 1})")
    return ", ".join(parts) if parts else "the model states no limits"


def run(args) -> int:
    """Run ``fjm excite``; returns 0, or 3 when the closed-loop check diverges or passes a limit."""
    from .. import load
    from ..ident.excite import TORQUE_SHARE, VELOCITY_SHARE, design_excitation
    from ..ident.excite_loop import check_in_closed_loop, write_excitation
    check_output_file(args.out, "--out")
    m = load(args.model)
    _check_size(args, m.n)
    exc = design_excitation(m, args.duration, q0=_posture(args.posture, m.n), amplitude=args.amplitude,
                            harmonics=args.harmonics, base_freq=args.base_freq, candidates=args.candidates,
                            iterations=args.iterations, seed=args.seed, rate=args.rate)
    ref = exc.reference
    print(f"{m.name}: {exc.periods} period(s) of {ref.period:.4g} s (base frequency {exc.base_freq:.4g} Hz, "
          f"{ref.a.shape[1]} harmonics), from rest to rest at q0 = {np.round(ref.q0, 4).tolist()}")
    print(f"regressor condition number {exc.condition:.3g} (worst joint; 1 is ideal; the first random draw: "
          f"{exc.first:.3g}; per joint {' '.join(f'{c:.3g}' for c in exc.joints)}; {exc.evaluations} evaluations)")
    print(f"limits used by the nominal motion: {_usage_line(exc.usage)} (allowed: velocity {VELOCITY_SHARE:.0%}, "
          f"torque {TORQUE_SHARE:.0%})")
    check, status = {}, 0
    if not args.no_check:
        check = check_in_closed_loop(m, exc, sensor=args.check_noise, seed=args.seed)
        if "diverged" in check:
            print(f"closed-loop check on the nominal model: DIVERGED ({check['diverged']})")
            status = 3
        else:
            use = check["usage"]
            past = [k for k in ("position", "velocity", "torque") if (use.get(k) or 0.0) > 1.0]
            print(f"closed-loop check (motor PD + feedforward, nominal model, {check['sensor']} sensor, "
                  f"{args.rate:g} Hz): max |q - q_d| {check['max_error']:.3g} rad; limits used: {_usage_line(use)}"
                  + (f"; PAST the {', '.join(past)} limit" if past else ""))
            status = 3 if past else 0
    write_excitation(args.out, exc, m, rate=args.rate, check=check)
    print(f"wrote {args.out} ({int(round(exc.duration * args.rate)) + 1} rows) and {args.out.with_suffix('.json')}")
    return status
