"""``fjm identify MODEL LOG --out params.toml``: the drives' parameters from a robot log (docs/identification.md)."""
from __future__ import annotations

import shlex
from pathlib import Path

from .models import MODEL_HELP
from .common import check_output_file
from .ranges import VELOCITY, Range

__all__ = ["add_arguments", "run"]

#: The smoothing window, s (the log must also hold it: checked on the log).
WINDOW = Range(0, 60, "s", "window", lo_open=True)
#: Share of a motor's RMS speed below which its windows are left out of the motor equation (stiction).
REVERSAL = Range(0, 0.9, "", "share")


def add_arguments(p) -> None:
    """The arguments of ``fjm identify`` on its parser ``p`` (name, help, description: commands.toml)."""
    p.add_argument("model", help="the reduced model the log is of: " + MODEL_HELP)
    p.add_argument("log", type=Path, help="the log: .csv (header t, q_1, q_m_1, u_1, [tau_J_1], ...) or .npz")
    p.add_argument("--out", type=Path, required=True, help="parameter file to write (TOML)")
    p.add_argument("--spring", choices=("linear", "cubic"), default=None,
                   help="spring law (default: cubic for a model with k1, k3, else linear)")
    p.add_argument("--friction", choices=("viscous", "coulomb", "stribeck"), default="coulomb",
                   help="motor friction: B_m only, + Coulomb F_c tanh(dq_m/v_c) (default), + Stribeck F_s")
    p.add_argument("--v-c", type=VELOCITY, default=None,
                   help=f"Coulomb regularization velocity, {VELOCITY} (default: the model's v_c where it has friction, else 0.01)")
    p.add_argument("--v-s", type=VELOCITY, default=None,
                   help=f"Stribeck velocity, {VELOCITY} (default: the model's v_s where it has friction, else 0.1)")
    p.add_argument("--window", type=WINDOW, default=0.04,
                   help=f"zero-phase smoothing/differentiation window, {WINDOW} (default 0.04; shorter for fast, clean motors, longer for noisy encoders)")
    p.add_argument("--reversal-share", type=REVERSAL, default=None,
                   help=f"leave the motor equation's windows where |dq_m| drops below this share of its RMS out (dry "
                        f"friction's stiction near a reversal), {REVERSAL}; 0 keeps all (default 0.1, 0 for stribeck)")


def run(args) -> int:
    """Run ``fjm identify``; returns the exit status (0)."""
    from .. import load
    from ..model import command_name
    from ..ident.identify import identify
    from ..ident.log import read_log
    from ..ident.report import table_lines
    check_output_file(args.out, "--out")
    m = load(args.model)
    log = read_log(args.log, m)
    ident = identify(m, log, spring=args.spring, friction=args.friction, v_c=args.v_c, v_s=args.v_s,
                     window=args.window, reversal_share=args.reversal_share)
    s = ident.settings
    print(f"{m.name}: {s['samples']} samples, {s['duration_s']:.3g} s at {s['rate_hz']:.4g} Hz; tau_J from the "
          f"{s['tau_J']}; filter {s['filter']}")
    print("\n".join(table_lines(ident)))
    ident.to_toml(args.out, m)
    print(f"wrote {args.out} (fjm design {command_name(m)} --params {shlex.quote(str(args.out))})")
    return 0
