"""``fjm excite MODEL --duration T --out traj.csv``: an excitation trajectory for ``fjm identify``."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .common import check_output_file

__all__ = ["add_parser", "run"]


def add_parser(sub) -> None:
    """Register ``fjm excite``."""
    p = sub.add_parser("excite", help="an excitation trajectory (Fourier series) for fjm identify",
                       description="Draw finite Fourier series for the link angles, keep the one that makes the "
                                   "identification best conditioned (motor and spring regressors of the nominal "
                                   "model's motion) within half the velocity and 80 %% of the torque limits, check it "
                                   "in closed loop on the nominal model, write it (docs/identification.md).")
    p.add_argument("model")
    p.add_argument("--duration", type=float, required=True, help="length, s")
    p.add_argument("--out", type=Path, required=True,
                   help="CSV t, q_d_<i>, dq_d_<i>, ddq_d_<i>, u_ff_<i> (and OUT.json: the coefficients)")
    p.add_argument("--amplitude", type=float, default=0.5, help="largest excursion from the centre, rad (0.5)")
    p.add_argument("--harmonics", type=int, default=5, help="harmonics per joint (default 5)")
    p.add_argument("--base-freq", type=float, default=0.2, help="base frequency, Hz (default 0.2)")
    p.add_argument("--candidates", type=int, default=40, help="random series tried (default 40)")
    p.add_argument("--rate", type=float, default=1000.0, help="sample rate of the CSV, Hz (default 1000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-check", action="store_true", help="skip the closed-loop check on the nominal model")


def run(args) -> int:
    """Run ``fjm excite``; returns 0, or 3 when the closed-loop check fails."""
    from .. import load
    from ..ident.excite import check_in_closed_loop, design_excitation, write_excitation
    from ..sim.step import SimulationDivergedError
    check_output_file(args.out, "--out")
    m = load(args.model)
    exc = design_excitation(m, args.duration, amplitude=args.amplitude, harmonics=args.harmonics,
                            base_freq=args.base_freq, candidates=args.candidates, seed=args.seed, rate=args.rate)
    use = ", ".join(f"{k} {100 * v:.0f} %" for k, v in exc.usage.items()) if m.effort_limits is not None \
        else "the model states no limits"
    print(f"{m.name}: best of {exc.candidates} series: regressor condition number {exc.condition:.3g} "
          f"(worst joint; 1 is ideal); limits used: {use}")
    write_excitation(args.out, exc, m, args.duration, args.rate)
    print(f"wrote {args.out} and {args.out.with_suffix('.json')}")
    if args.no_check:
        return 0
    try:
        res = check_in_closed_loop(m, exc.reference, args.duration, args.rate)
    except SimulationDivergedError as err:
        print(f"closed-loop check on the nominal model: {err}")
        return 3
    e = np.max(np.abs(res.e1))
    print(f"closed-loop check (integral SMC, nominal model, {args.rate:g} Hz): max tracking error {e:.3g} rad, "
          f"peak torque {np.max(np.abs(res.u)):.3g} N m")
    return 0
