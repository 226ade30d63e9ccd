"""Does identification say how sure it is? Every stated interval against the truth, on independent logs.

    .venv/bin/python examples/identify_validation.py [MODEL] [--duration 20] [--repeats 4]
        [--friction-joints 1,2,4,6] [--seed 0]

The logs come from MuJoCo (an engine nobody here wrote), not from fjm's simulator: the TRUE plant is
the model exported with ``fjm export mjcf`` at parameters changed per joint (:func:`truth`: stiffness
x0.8..1.25, rotor inertia x0.8..1.25, motor damping 1.5..5 J_m per second) with MuJoCo's dry friction
``frictionloss`` added to the rotors of ``--friction-joints`` (8 % of the joint's RMS motor torque along
the excitation: a constraint-based friction with stiction, not the tanh of the fit), driven along a
``fjm excite`` trajectory by a motor PD plus the nominal feedforward, logged at 1 kHz with the
``franka_like`` sensor levels (20-bit link encoder, noisy quantized motor encoder, 0.05 N m torque
noise and a constant offset per joint). It is identified twice: from the excitation played once
(``--duration`` s) and ``--repeats`` times. For every identified parameter the table gives the truth,
the estimate, its statistical standard error, its systematic term and the stated interval (value -+ 3
combined standard uncertainties), and whether the truth lies inside. Exit status 0 when all do.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

import fjm_runtime
from fjm_runtime.drives import role_names
from fjm_runtime.ident.excite import design_excitation, nominal_motion
from fjm_runtime.ident.identify import friction_names, identify
from fjm_runtime.ident.mujoco_robot import RATE, mujoco_log, tau_J_offsets
from fjm_runtime.ident.uncertainty import INTERVAL_SIGMAS

#: Per-joint factors of the truth against the model's defaults (cycled over the joints).
K_FACTORS = (1.15, 0.85, 1.25, 0.9, 1.1, 0.8, 1.2)
JM_FACTORS = (0.9, 1.2, 0.8, 1.1, 1.25, 0.85, 1.15)
#: Motor damping of the truth, N m s/rad per kg m^2 of its rotor inertia (1/s).
BM_RATES = (2.0, 4.0, 3.0, 5.0, 2.5, 3.5, 1.5)
#: Dry friction of a joint with friction, as a share of its RMS motor torque along the excitation.
FRICTION_SHARE = 0.08


def truth(model, exc, friction_joints) -> tuple:
    """``(true parameter dict, frictionloss per joint (n,) N m)`` of the module docstring."""
    n = model.n
    K, J, B = (role_names(model, r) for r in ("stiffness", "rotor_inertia", "damping"))
    p = dict(model.default_params)
    for i in range(n):
        p[K[i]] *= K_FACTORS[i % 7]
        p[J[i]] *= JM_FACTORS[i % 7]
        p[B[i]] = BM_RATES[i % 7] * p[J[i]]
    t = np.arange(0.0, exc.duration, 1.0 / RATE)
    u_rms = np.sqrt(np.mean(nominal_motion(model, exc.reference, t, model.params_array(p))["u"] ** 2, axis=0))
    friction = np.zeros(n)
    for j in friction_joints:
        friction[j - 1] = FRICTION_SHARE * u_rms[j - 1]
    return p, friction


def check(model, ident, p_true: dict, friction, offsets) -> list:
    """One row per identified parameter: ``(name, truth, value, stderr, systematic, low, high, inside,
    excited)`` (excited: the log determines it, :attr:`~fjm_runtime.ident.identify.Identification.not_excited`)."""
    rows = []
    for nm, v in ident.values.items():
        if nm in p_true:
            true = p_true[nm]
        elif nm.startswith("tau_J_offset"):
            true = float(offsets[int(nm[len("tau_J_offset"):]) - 1])
        else:
            joint = next(i for i in range(model.n) if nm in friction_names(model, i))
            true = float(friction[joint])
        lo, hi = ident.interval(nm)
        rows.append((nm, true, v, ident.stderr[nm], ident.systematic[nm], lo, hi, bool(lo <= true <= hi),
                     nm not in ident.not_excited))
    return rows


def validate(model, duration: float, repeats: int, friction_joints, work: Path, seed: int = 0) -> dict:
    """``{log length s: rows of :func:`check`}`` for the excitation played once and ``repeats`` times."""
    exc = design_excitation(model, duration, candidates=10, seed=seed)
    p_true, friction = truth(model, exc, friction_joints)
    out = {}
    for periods in (1, repeats):
        log = mujoco_log(model, exc.reference, periods * exc.duration, work, seed=seed, friction=friction,
                         p_true=p_true)
        ident = identify(model, log)
        out[round(periods * exc.duration, 6)] = check(model, ident, p_true, friction, tau_J_offsets(model.n, seed))
    return out


def table(results: dict) -> list:
    """Markdown lines: per parameter the truth and, per log length, estimate and interval."""
    lengths = list(results)
    head = "| parameter | truth | " + " | ".join(f"{L:g} s: estimate | {L:g} s: interval (+-{INTERVAL_SIGMAS:g} u)"
                                                for L in lengths) + " |"
    lines = [head, "|" + "---|" * (2 + 2 * len(lengths))]
    for k, row in enumerate(results[lengths[0]]):
        cells = [row[0], f"{row[1]:.5g}"]
        for L in lengths:
            nm, true, v, se, sys_, lo, hi, inside, excited = results[L][k]
            err = f" ({100 * (v / true - 1):+.2f} %)" if true else ""
            cells += [f"{v:.5g}{err}" + ("" if excited else " (not excited)"),
                      f"[{lo:.5g}, {hi:.5g}]" + ("" if inside else " MISSES")]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", nargs="?", default="panda")
    ap.add_argument("--duration", type=float, default=20.0, help="excitation length, s (default 20)")
    ap.add_argument("--repeats", type=int, default=4, help="the longer log plays it this many times (default 4)")
    ap.add_argument("--friction-joints", default="1,2,4,6",
                    help="joints (1-based) with MuJoCo frictionloss (default 1,2,4,6; those the model has)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    m = fjm_runtime.load(args.model)
    joints = [int(j) for j in args.friction_joints.split(",") if j.strip() and int(j) <= m.n]
    with tempfile.TemporaryDirectory(prefix="fjm-ident-validation-") as tmp:
        results = validate(m, args.duration, args.repeats, joints, Path(tmp), args.seed)
    print(f"`examples/identify_validation.py {args.model} --duration {args.duration:g} --repeats {args.repeats} "
          f"--friction-joints {','.join(map(str, joints))} --seed {args.seed}`: MuJoCo frictionloss on joints "
          f"{', '.join(map(str, joints))}\n")
    print("\n".join(table(results)))
    missed = [(L, r[0]) for L, rows in results.items() for r in rows if not r[7]]
    total = sum(len(rows) for rows in results.values())
    print(f"\n{total - len(missed)} of {total} intervals contain the truth" +
          (f"; missed: {missed}" if missed else ""))
    return 0 if not missed else 1


if __name__ == "__main__":
    sys.exit(main())
