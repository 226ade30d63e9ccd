"""The step of the exported controller library (``fjm export controller``): the Panda's shipped design.

Built and timed with the example's own Makefile (``make -C examples/c designed-bench``:
:file:`examples/c/designed_controller.c` linked with the library of
``fjm_runtime/control/designed/panda_ismc_tau_1000hz_d1.json``; the library ``-std=c99 ... -O2``).
``STEPS`` calls of ``<name>_step`` inside the closed loop with the generated plant, the design's
sensor noise and delay, each timed on its own in C (``CLOCK_MONOTONIC`` around the call: no
Python, no ctypes): median, 99.9th percentile and worst case. One step is the whole sampled
controller: the dtau_J filter, the delay buffer, the prediction over one sample with the nominal
model (RK4 substeps), the torque-sensed ismc law with saturation and anti-windup, the state update.

Variants: the design's predictor (its recorded ``predict_substeps``, chosen by accuracy: 3 RK4 substeps
per 1 ms; the plant's rule gives 11) and a predictor on
:data:`FEW_SUBSTEPS` substeps (the plant keeps the design's), with the accuracy that costs: the
10 s task's figures (``make designed``: worst-joint second-half RMS, torque jitter of joints 1-4)
of each variant. The target: the 99.9th percentile under 50 us (a twentieth of the 1 kHz period,
leaving the robot's own budget) on the design's predictor.
"""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

HERE = Path(__file__).resolve().parent
EXAMPLE = HERE.parent / "examples" / "c"
#: Predictor substeps of the cheaper variant (the closed loop's figures are printed next to the design's).
FEW_SUBSTEPS = 2
#: 99.9th percentile target of one step, ns.
TARGET_P999_NS = 50e3


def _json_rows(text: str) -> list:
    return [json.loads(ln) for ln in text.splitlines() if ln.startswith("{")]


def _make(target: str, out: Path, dc_dir: Path, substeps, steps: int) -> dict:
    args = ["make", "--no-print-directory", "-C", str(EXAMPLE), target, f"OUT={out}", f"DC_DIR={dc_dir}",
            f"DC_STEPS={int(steps)}"] + ([f"DC_SUBSTEPS={int(substeps)}"] if substeps else [])
    proc = subprocess.run(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    rows = _json_rows(proc.stdout)
    if not rows:
        raise RuntimeError(f"make {target} printed no result:\n{proc.stderr[-2000:]}")
    return rows[-1]


def bench_controller_step(work: Path, steps: int) -> dict:
    """Time ``<name>_step`` (design's and :data:`FEW_SUBSTEPS` predictor substeps); figures of each variant.

    ``work / "realtime"`` is the OUT of the realtime section (its plant model object is reused). The
    50 us target on the 99.9th percentile is a row of the targets table (:mod:`bench.report`), met or
    missed like the others: a percentile of wall-clock time on a shared machine is not a peer check.
    """
    out = work / "realtime"
    res = {"steps": int(steps), "design": "fjm_runtime/control/designed/panda_ismc_tau_1000hz_d1.json",
           "target_p999_ns": TARGET_P999_NS}
    for label, subs in (("design_substeps", None), (f"substeps_{FEW_SUBSTEPS}", FEW_SUBSTEPS)):
        dc_dir = work / "controller_step" / label
        loop = _make("designed", out, dc_dir, subs, steps)
        timed = _make("designed-bench", out, dc_dir, subs, steps)
        res[label] = {"predictor_substeps": subs or "design", "step_median_ns": timed["step_median_ns"],
                      "step_p999_ns": timed["step_p999_ns"], "step_max_ns": timed["step_max_ns"],
                      "period_ns": timed["period_ns"], "worst_rms": loop["worst_rms"],
                      "worst_jitter_1_4": loop["worst_jitter_1_4"], "worst_at_limit": loop["worst_at_limit"],
                      "holds": loop["holds"]}
    return res


if __name__ == "__main__":   # this section alone: python -m bench.controller_step [STEPS]
    import sys
    import tempfile
    with tempfile.TemporaryDirectory(prefix="fjm-bench-ctrl-") as tmp:
        print(json.dumps(bench_controller_step(Path(tmp), int(sys.argv[1]) if len(sys.argv) > 1 else 10 ** 5),
                         indent=1))
