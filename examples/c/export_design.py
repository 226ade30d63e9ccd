"""Export a design's controller library and write the header designed_controller.c is built with.

    python export_design.py DESIGN.json OUT_DIR [--name NAME] [--k-true SCALE] [--substeps S]

1. ``fjm export controller <model> --gains DESIGN.json --out OUT_DIR/lib --name NAME``: the C99
   library of the design (``OUT_DIR/lib``, built by its own Makefile).
2. ``OUT_DIR/design.h``: what the example program needs besides the library -- the library's
   names under fixed aliases (``CTRL_STEP`` ...), the design's task (reference sines, duration),
   the sensor the design was verified with (noise level of every reading slot, encoder
   quantization, tau_J offset), the plant's parameters (the model defaults with every
   stiffness x ``--k-true``: the controller only knows the nominal ones) and the thresholds of
   ``fjm design`` (2e-3 rad, 2 %, 3 N m on joints 1-4). The plant runs on the design's RK4
   substeps; ``--substeps`` changes only the library's predictor (a cheaper step, less accurate).

Needs ``fjm_runtime`` (run it with the Python fjm is installed in; the Makefile's ``FJM_PYTHON``).
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

try:
    import numpy as np

    import fjm_runtime
    from fjm_runtime.cli.main import main as fjm_main
    from fjm_runtime.control.design import Design
    from fjm_runtime.export.controller import design_controller
    from fjm_runtime.sim.sensor import noise_slots
except ImportError as exc:  # the Makefile's FJM_PYTHON is not the Python fjm is installed in
    raise SystemExit(f"export_design.py: {exc} in {sys.executable}; expected the Python fjm is installed in "
                     "(`make venv` at the repository root, or make FJM_PYTHON=/path/to/python)") from None


def _num(v) -> str:
    """A C double literal that round-trips (``10`` -> ``10.0``: an int would break printf's %g)."""
    text = f"{float(v):.17g}"
    return text if any(ch in text for ch in ".en") else text + ".0"


def _arr(values) -> str:
    return "{" + ", ".join(_num(v) for v in np.ravel(values)) + "}"


def header(design, k_true: float, plant_substeps: int) -> str:
    gains, L, sensor, model = design.design, design.layout, design.sensor, design.model
    n, name = L.n, design.name
    task = gains.task or {}
    if gains.reference(model) is None:
        raise SystemExit(f"{gains.file}: the design records no sine task (reference offset/amplitude/omega)")
    if "u_max" not in gains.gains:
        raise SystemExit(f"{gains.file}: the design has no torque limit u_max")
    _, levels = noise_slots(sensor, L.sensing, n)
    p_nom = np.asarray(design.controller.p_nom, dtype=float)
    k_idx = [i for i, s in enumerate(model.param_names) if s.startswith("K") and s[1:].isdigit()]
    p_true = p_nom.copy()
    p_true[k_idx] *= k_true
    alias = {a: f"{name}_{s}" for a, s in (("CTRL_T", "controller"), ("CTRL_REAL", "real"), ("CTRL_INIT", "init"),
                                            ("CTRL_RESET", "reset"), ("CTRL_STEP", "step"))}
    alias.update({f"CTRL_{s}": f"{name.upper()}_{s}" for s in ("OK", "SATURATED", "INPUT_NOT_FINITE", "NM", "N",
                                                              "PERIOD")})
    lines = [f"/* design.h: written by export_design.py from {gains.file} - do not edit */",
             f'#include "{name}_controller.h"']
    lines += [f"#define {a} {v}" for a, v in alias.items()]
    lines += [f'#define DESIGN_NAME "{name}"', f"#define SENSING_TORQUE {int(L.sensing == 'torque')}",
              f"#define RATE_HZ {_num(1.0 / L.T)}", f"#define DURATION {_num(gains.report.get('duration', 10.0))}",
              f"#define N_RUN {int(round(float(gains.report.get('duration', 10.0)) / L.T))}L   /* samples of the task */",
              f"#define REF_CENTER {_arr(task['offset'])}", f"#define REF_AMPL {_arr(task['amplitude'])}",
              f"#define REF_OMEGA {_arr(task['omega'])}", f"#define REF_PHASE {_num(task.get('phase', 0.0))}",
              f"#define PLANT_SUBSTEPS {int(plant_substeps)}   /* RK4 steps per period: the design's */",
              f"#define U_MAX {_arr(np.broadcast_to(np.asarray(gains.gains['u_max'], dtype=float), (n,)))}",
              f"#define P_TRUE {_arr(p_true)}", f"#define K_TRUE_SCALE {_num(k_true)}",
              f"#define K_TRUE_VALUES {_arr(p_true[k_idx])}",
              f"#define NOISE_LEVELS {_arr(levels)}   /* std of every reading slot */",
              f"#define NOISE_SEED {int(sensor.seed)}ULL",
              f"#define Q_QUANT {_num(sensor.q_quant)}", f"#define Q_M_QUANT {_num(sensor.q_m_quant)}",
              f"#define MOTOR_ANGLE_IN_DQM {int(L.differentiated and L.sensing == 'torque')}",
              f"#define TAU_OFFSET_SIGMA {_arr(sensor.offsets(n))}",
              "#define MAX_RMS 2e-3", "#define MAX_AT_LIMIT 0.02", "#define MAX_JITTER 3.0",
              f"#define JITTER_JOINTS {min(4, n)}", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("design", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--name", default=None)
    ap.add_argument("--k-true", type=float, default=1.0, help="plant stiffness / nominal (default 1)")
    ap.add_argument("--substeps", type=int, default=None, help="RK4 substeps of the library's predictor "
                    "(default: the design's substeps rule; the plant always uses that)")
    args = ap.parse_args(argv)
    if not (math.isfinite(args.k_true) and args.k_true > 0):
        raise SystemExit(f"--k-true {args.k_true}: expected a finite scale > 0")
    gains = Design.load(args.design, where=str(args.design))
    gains = dataclasses.replace(gains, file=gains.file or str(args.design))
    model = gains.model
    cli = ["export", "controller", str(model), "--gains", str(args.design), "--out", str(args.out / "lib")]
    cli += ["--name", args.name] if args.name else []
    if fjm_main(cli + (["--substeps", str(args.substeps)] if args.substeps else [])) != 0:
        return 1
    design = design_controller(fjm_runtime.load(model), gains, name=args.name)
    (args.out / "design.h").write_text(header(design, args.k_true, design.layout.substeps))
    return 0


if __name__ == "__main__":
    sys.exit(main())
