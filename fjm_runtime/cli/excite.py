"""``fjm excite MODEL --duration T --out traj.csv``: an excitation trajectory for ``fjm identify``."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .models import MODEL_HELP
from ..validation import FjmValueError
from .common import check_output_file

__all__ = ["add_arguments", "run"]


def add_arguments(p) -> None:
    """The arguments of ``fjm excite`` on its parser ``p`` (name, help, description: commands.toml)."""
    p.add_argument("model", help=MODEL_HELP)
    p.add_argument("--duration", type=float, required=True, help="length, s: whole base periods (the base frequency is raised to fit)")
    p.add_argument("--out", type=Path, required=True, help="CSV t, q_d_<i>, dq_d_<i>, ddq_d_<i>, q_m_d_<i>, "
                   "dq_m_d_<i>, tau_J_d_<i>, u_ff_<i> (and OUT.json: coefficients, conditions, limits' usage)")
    p.add_argument("--harmonics", type=int, default=5, help="harmonics per joint, >= 3 (default 5)")
    p.add_argument("--base-freq", type=float, default=0.2, help="lowest base frequency, Hz (default 0.2)")
    p.add_argument("--amplitude", type=float, default=0.5, help="largest excursion from the posture, rad (0.5)")
    p.add_argument("--posture", default=None, metavar="Q1,Q2,...",
                   help="base posture, rad (default: the middle of the joint ranges, 0 where none is stated)")
    p.add_argument("--candidates", type=int, default=20, help="random series drawn (default 20)")
    p.add_argument("--iterations", type=int, default=40, help="local-search iterations after them (default 40)")
    p.add_argument("--rate", type=float, default=1000.0, help="sample rate of the CSV, Hz (default 1000)")
    p.add_argument("--seed", type=int, default=0)
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
    if q.size != n or not np.all(np.isfinite(q)):
        raise FjmValueError(f"--posture {text!r}: expected {n} comma-separated angles in rad")
    return q


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
