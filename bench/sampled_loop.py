"""The sampled-data loop of a single run: how fine the plant substeps are, and what delay prediction buys.

Two measurements, both noise-free, 10 s at 1 kHz, ``backend='compiled'``:

* ``substeps``: for the Panda (ismc, lambda 80, k_lin 400, k_s 2000, delta 10, the demo's ready-pose
  sines of :func:`fjm_runtime.experiments.panda.reference` from rest holding gravity) and link1 (ismc,
  lambda 8, k_s 1000, delta 5, a 0.5 rad, 1 rad/s sine): ``omega_max`` and the default substeps of
  :mod:`fjm_runtime.sim.substeps`, and ``max |q - q_10x|`` against the same run on 10x the substeps.
* ``delay_prediction``: the Panda with a one-sample delay, state and torque sensing, TRUE stiffness
  exact / all joints x0.7 / x1.3 (the controller keeps the NOMINAL one): worst-joint second-half RMS
  of ``q - q_d`` without and with ``predict=True``; a run that diverges records its time.

``python -m bench --only sampled_loop`` runs it; :func:`merge_into` stores the section under its key
of ``bench/results.json`` without touching the other keys.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from fjm_runtime.control.defaults import DEFAULT_LAM, DEFAULT_SWITCHING_GAIN, default_delta

KEY = "sampled_loop"
DURATION, DT = 10.0, 1e-3
PANDA_GAINS = dict(lam=80.0, k_lin=400.0, k_s=2000.0, delta=10.0, u_max=(87.0,) * 4 + (12.0,) * 3)
LINK1_GAINS = dict(lam=DEFAULT_LAM, k_s=DEFAULT_SWITCHING_GAIN, delta=default_delta(DEFAULT_SWITCHING_GAIN))
STIFFNESS = (("exact", 1.0), ("x0.7", 0.7), ("x1.3", 1.3))


def _panda(sensing: str = "state"):
    import fjm_runtime
    from fjm_runtime.control.factory import make_controller
    from fjm_runtime.experiments.panda import reference
    m = fjm_runtime.load("panda")
    return m, make_controller("ismc", m, {}, sensing=sensing, **PANDA_GAINS), reference(7)


def _true(m, factor: float) -> np.ndarray:
    """The TRUE parameters: the defaults with every ``K_i`` times ``factor``, shape (n_params,)."""
    from fjm_runtime.drives import linear_stiffness_indices
    p = np.array(m.params_array({}), dtype=float)
    p[linear_stiffness_indices(m, "the stiffness factor")] *= factor
    return p


def _x0(name: str, m, ref, p_true):
    if name != "panda":
        return None
    from fjm_runtime.sim.rest import rest_state
    return rest_state(m, np.asarray(ref(0.0))[0], p_true)


def substeps_case(name: str, m, ctrl, ref) -> dict:
    """``omega_max``, default substeps and ``max |q - q_10x|`` (rad) of one noise-free 10 s run."""
    from fjm_runtime.sim.simulate import simulate
    from fjm_runtime.sim.substeps import default_substeps, fastest_mode
    p = _true(m, 1.0)
    x0 = _x0(name, m, ref, p)
    x_start = x0 if x0 is not None else np.concatenate([np.asarray(ref(0.0))[0], np.zeros(m.n)] * 2)
    omega = fastest_mode(m, x_start, p)
    subs = default_substeps(DT, omega)
    runs = {}
    for k in (1, 10):
        t0 = time.perf_counter()
        r = simulate(m, ctrl, ref, duration=DURATION, dt=DT, true_params=p, x0=x0, backend="compiled",
                     substeps=None if k == 1 else k * subs)     # None: the default rule
        runs[k] = (r, time.perf_counter() - t0)
    (a, ta), (b, tb) = runs[1], runs[10]
    if a.settings["substeps"] != subs:
        raise RuntimeError(f"simulate chose {a.settings['substeps']} substeps, the rule gives {subs}")
    n = int(m.n)
    return {"omega_max": omega, "substeps": subs, "substeps_fine": 10 * subs,
            "max_abs_q_diff": float(np.max(np.abs(a.x[:, :n] - b.x[:, :n]))),
            "max_abs_state_diff": float(np.max(np.abs(a.x - b.x))),
            "rms_second_half_worst": float(np.max(_rms(a))),
            "wall_seconds": ta, "wall_seconds_fine": tb}


def _rms(r) -> np.ndarray:
    from fjm_runtime.sim.metrics import rms_second_half
    return rms_second_half(r)


def delay_run(sensing: str, factor: float, predict: bool) -> dict:
    """Worst-joint second-half RMS (rad) of one delayed Panda run, or the time it diverged (s)."""
    from fjm_runtime.experiments.panda import divergence_time
    from fjm_runtime.sim.simulate import simulate
    from fjm_runtime.sim.step import SimulationDivergedError
    m, ctrl, ref = _panda(sensing)
    p = _true(m, factor)
    try:
        r = simulate(m, ctrl, ref, duration=DURATION, dt=DT, true_params=p, x0=_x0("panda", m, ref, p),
                     backend="compiled", delay_samples=1, predict=predict)
    except SimulationDivergedError as exc:
        return {"diverged": True, "diverged_at_s": float(exc.t), "rms_worst": None}
    t_div = divergence_time(r)
    rms = _rms(r)
    if t_div is not None or not np.all(np.isfinite(rms)):
        return {"diverged": True, "diverged_at_s": t_div, "rms_worst": None}
    return {"diverged": False, "diverged_at_s": None, "rms_worst": float(np.max(rms)),
            "worst_joint": int(np.argmax(rms)) + 1, "substeps": int(r.settings["substeps"])}


def bench_sampled_loop(log=print) -> dict:
    """Both measurements (keys in the module docstring)."""
    import fjm_runtime
    from fjm_runtime.control.factory import make_controller
    from fjm_runtime.control.references import make_reference
    out = {"duration_s": DURATION, "rate_hz": 1.0 / DT, "noise": "none", "backend": "compiled",
           "panda_reference": "fjm_runtime.experiments.panda.reference() from rest_state (ready-pose sines)",
           "substeps": {}, "delay_prediction": {}}
    m1 = fjm_runtime.load("link1")
    cases = [("panda", *_panda()),
             ("link1", m1, make_controller("ismc", m1, {}, **LINK1_GAINS),
              make_reference("sine", 1, amplitude=0.5, omega=1.0))]
    for name, m, ctrl, ref in cases:
        log(f"sampled_loop substeps {name}: default vs 10x ...")
        out["substeps"][name] = substeps_case(name, m, ctrl, ref)
    for sensing in ("state", "torque"):
        for label, factor in STIFFNESS:
            for predict in (False, True):
                log(f"sampled_loop delay {sensing} {label} predict={predict} ...")
                out["delay_prediction"].setdefault(sensing, {}).setdefault(label, {})[
                    "predict" if predict else "plain"] = delay_run(sensing, factor, predict)
    return out


def merge_into(path: Path, section: dict) -> None:
    """Set ``results[KEY] = section`` in the results file ``path``, every other key kept as it was."""
    path = Path(path)
    results = json.loads(path.read_text())
    results[KEY] = section
    path.write_text(json.dumps(results, indent=2, sort_keys=True) + "\n")


if __name__ == "__main__":
    import sys
    # python -m bench.sampled_loop [FROM]: copy the section of a `--only sampled_loop` run
    # (default build/bench-results.json) into bench/results.json
    src = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent / "build" / "bench-results.json"
    merge_into(Path(__file__).resolve().parent / "results.json", json.loads(src.read_text())[KEY])
    print(f"merged {KEY} of {src} into bench/results.json")
