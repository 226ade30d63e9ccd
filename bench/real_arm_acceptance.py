"""The real-arm acceptance check of the Panda, as one script (``python -m bench.real_arm_acceptance``).

Panda, 1 kHz, one-sample delay, the ``panda`` sensor model, the demo's task (ready-pose sines from
rest holding gravity): every draw of K x U[0.7, 1.3] per joint (23 seeded draws plus all 0.7, all
1.3, alternating), each with J_m x 0.8 and x 1.2, and a 1 kg unknown payload, all at once (52
plants). The torque-sensed ismc with the shipped designed gains (``fjm design``, with prediction),
the same law without prediction, and the state-feedback ismc with the same gains, side by side;
then the same gains noise-free and delay-free on the nominal plant. Prints one JSON object.
"""
from __future__ import annotations

import json
import time

import numpy as np

import fjm_runtime
from fjm_runtime.batch.runner import simulate_batch
from fjm_runtime.control.design import Design
from fjm_runtime.control.factory import make_controller
from fjm_runtime.experiments import panda as task
from fjm_runtime.drives import drive_indices, linear_stiffness_indices
from fjm_runtime.sim.sensor import SensorModel

TARGETS = {"worst_rms": 2e-3, "worst_time_at_limit": 0.02, "worst_jitter_j1_4": 3.0}


def plants(m, seed: int = 2024) -> np.ndarray:
    """The 52 true parameter rows (K box draws x J_m 0.8 / 1.2, payload 1 kg)."""
    n = int(m.n)
    iK, iJ = linear_stiffness_indices(m, "the K draws"), drive_indices(m, "rotor_inertia")
    iL = m.param_names.index("m_load")
    p0 = np.asarray(m.params_array({}))
    rng = np.random.default_rng(seed)
    ks = [np.full(n, .7), np.full(n, 1.3), np.where(np.arange(n) % 2 == 0, .7, 1.3)] + \
        [rng.uniform(.7, 1.3, n) for _ in range(23)]
    rows = []
    for k in ks:
        for jm in (0.8, 1.2):
            p = p0.copy()
            p[iK] *= k
            p[iJ] *= jm
            p[iL] = 1.0
            rows.append(p)
    return np.vstack(rows)


def _worst(a, axis=None):
    """Largest finite value (per joint with ``axis=0``); ``None`` where every run diverged (JSON holds no NaN)."""
    a = np.where(np.isfinite(a), a, -np.inf)
    w = np.max(a, axis=axis)
    return [None if not np.isfinite(v) else float(v) for v in w] if axis is not None else \
        (None if not np.isfinite(w) else float(w))


def summary(b) -> dict:
    """Worst cases over the runs of a BatchResult (over the runs that did not diverge), with the targets."""
    jm = b.joint_metrics
    out = {"diverged": int(b.diverged.sum()), "worst_rms": _worst(jm["rms_second_half"]),
           "worst_time_at_limit": _worst(jm["time_at_limit"]),
           "worst_jitter_j1_4": _worst(jm["torque_jitter"][:, :4]),
           "worst_rms_per_joint": _worst(jm["rms_second_half"], axis=0),
           "worst_jitter_per_joint": _worst(jm["torque_jitter"], axis=0)}
    out["meets"] = {k: out[k] is not None and out[k] <= v for k, v in TARGETS.items()} | \
        {"no divergence": out["diverged"] == 0}
    return out


def main() -> None:
    m = fjm_runtime.load("panda")
    design = Design.shipped("panda", "ismc", "torque", 1000, 1)
    g = dict(design.gains)
    ref = task.reference()
    x0 = task.rest_state(m, ref(0.0)[0], m.default_params)
    P = plants(m)
    out = {"runs": int(P.shape[0]), "gains": g, "gains_file": design.file, "targets": TARGETS}
    for label, sensing, predict in (("torque, predict", "torque", True), ("torque", "torque", False),
                                    ("state, predict", "state", True), ("state", "state", False)):
        c = make_controller("ismc", m, {}, sensing=sensing, **g)
        t0 = time.time()
        b = simulate_batch(m, c, ref, P, duration=10.0, sensor=SensorModel.panda_white(seed=7), delay_samples=1,
                           predict=predict, x0=x0, threads=2, simd=False)
        out[label] = summary(b) | {"wall_s": time.time() - t0}
        print(label, json.dumps(out[label], allow_nan=False), flush=True)
    c = make_controller("ismc", m, {}, sensing="torque", **g)
    b = simulate_batch(m, c, ref, np.asarray(m.params_array({}))[None], duration=10.0, x0=x0, threads=2, simd=False)
    out["noise-free, delay-free, nominal: worst rms"] = float(np.nanmax(b.joint_metrics["rms_second_half"]))
    print(json.dumps(out, allow_nan=False))


if __name__ == "__main__":
    main()
