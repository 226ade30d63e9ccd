"""The real-time controller of examples/c (realtime.c) on link1 and panda, double and float.

Builds it with the example's own Makefile (``-std=c99 -Wall -Wextra -Werror -pedantic -O2``),
then for each model and precision:

* ``realtime bench STEPS``: ``STEPS`` controller steps inside the closed loop with the generated
  plant, each timed on its own (``CLOCK_MONOTONIC``), and one ``alpha`` + ``beta`` call of the
  same model at the same state: median, 99.9th percentile and worst-case step time, and the
  ratio of medians. A step is the emitted law plus the forward-Euler update of its state:
  link1 ``<model>_control_ismc`` on the state; panda the torque-sensed
  ``<model>_control_ismc_tau`` at 1 kHz on ``m = [q; dq; tau_J; dtau_J; dq_m]`` built from the
  simulated plant with its true stiffness (0.8 x nominal; the law knows only the nominal);
* ``realtime run``: the 10 s closed loop; the float and double torques are compared
  sample by sample (``realtime compare``).
"""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

HERE = Path(__file__).resolve().parent
EXAMPLE = HERE.parent / "examples" / "c"
MODELS = ("link1", "panda")
#: The law each model runs in realtime.c (the Makefile's TORQUE_MODELS run the torque-sensed one).
LAWS = {"link1": "control_ismc (state x)", "panda": "control_ismc_tau (m = [q; dq; tau_J; dtau_J; dq_m])"}
#: Float vs double torque along the 10 s closed loop (plant and controller both in float), max |du| / max |u|:
#: measured 4e-4 (link1) and 8e-3 (panda, torque-sensed, 1 kHz).
FLOAT_U_RTOL = 0.05


def _json_lines(text: str) -> list:
    return [json.loads(ln) for ln in text.splitlines() if ln.startswith("{")]


def bench_realtime(work: Path, steps: int, checks: list, check) -> dict:
    """Build, time and compare; ``check(checks, key, what, measured, tolerance)`` records peer checks."""
    out = work / "realtime"
    run = subprocess.run(["make", "--no-print-directory", "-C", str(EXAMPLE), "realtime", f"OUT={out}"],
                         check=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    runs = _json_lines(run.stdout)
    timed = subprocess.run(["make", "--no-print-directory", "-C", str(EXAMPLE), "rt-bench", f"OUT={out}",
                            f"STEPS={int(steps)}"],
                           check=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    res = {"steps": int(steps), "laws": dict(LAWS)}
    for row in _json_lines(timed.stdout):
        res.setdefault(row["model"], {})[row["real"]] = {
            k: row[k] for k in ("step_median_ns", "step_max_ns", "step_p999_ns", "alpha_beta_median_ns",
                                "alpha_beta_max_ns", "ratio_median", "period_ns")}
    for row in runs:
        if "max_abs_u_deviation" in row:
            m = row["model"]
            res[m]["float_vs_double_u_max_abs"] = row["max_abs_u_deviation"]
            res[m]["float_vs_double_u_relative"] = row["relative"]
            check(checks, f"realtime.{m}.float", f"{m}: float vs double torque along the 10 s closed loop, "
                  "max |du| / max |u|", row["relative"], FLOAT_U_RTOL)
        elif "rms_error" in row:
            res[row["model"]].setdefault(row["real"], {}).update(
                {"closed_loop_rms_error": row["rms_error"], "closed_loop_final_error": row["final_error"],
                 "rate_hz": row["rate_hz"]})
    for m in MODELS:
        for real in ("double", "float"):
            r = res.get(m, {}).get(real, {})
            # the worst case of a shared, non-real-time OS is preemption (ms); the 99.9th percentile
            # is what the code costs, and must fit the period
            check(checks, f"realtime.{m}.{real}.deadline", f"{m} ({real}): 99.9th percentile step time / "
                  "control period", r.get("step_p999_ns", float("nan")) / r.get("period_ns", float("nan")), 1.0)
    return res
