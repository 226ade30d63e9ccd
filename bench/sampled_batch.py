"""Closed-loop throughput of the sampled-data batch on the Panda (simulated seconds per wall second).

The torque-sensed integral law at 1 kHz with a one-sample delay and the Panda sensor model, plant on
the substeps rule: ``simulate_batch`` scalar and SIMD on 1 and 2 threads, against a CasADi peer that
folds THE same sample step with ``mapaccum`` over samples and ``map(B, 'thread', k)`` over runs (noise
arrays from sensor.py's generator). The peer's final states are checked against the batch's.
"""
from __future__ import annotations

import time

import numpy as np

RUNS, DURATION, PEER_DURATION = 16, 1.0, 0.1
U_MAX = [87.0] * 4 + [12.0] * 3


def _case():
    import fjm_runtime
    from fjm_runtime.control.factory import make_controller
    from fjm_runtime.control.references import make_reference
    from fjm_runtime.sim.sensor import SensorModel
    m = fjm_runtime.load("panda")
    ctrl = make_controller("ismc", m, {}, sensing="torque", lam=80.0, k_lin=400.0, k_s=2000.0, delta=10.0, u_max=U_MAX)
    ref = make_reference("sine", 7, amplitude=0.5, omega=1.0)
    rng = np.random.default_rng(0)
    P = np.tile(m.params_array({}), (RUNS, 1))
    P[:, :7] *= rng.uniform(0.7, 1.3, (RUNS, 7))      # K1..K7
    return m, ctrl, ref, P, SensorModel.panda(seed=0)


def _peer(m, ctrl, ref, P, sensor, subs, threads, duration):
    """The CasADi map peer: ``(wall seconds, x_final (B, 4n))``."""
    import casadi as ca
    from fjm_runtime.sim.sample_step import initial_step_state, make_layout, sample_step_function
    from fjm_runtime.sim.sensor import noise_array
    L = make_layout(m, ctrl, 1e-3, subs, sensor, 1, False)
    N = int(round(duration / 1e-3))
    t = 1e-3 * np.arange(N)
    R = np.asarray(ref.sample(t)).reshape(N, -1)
    W0 = np.column_stack([initial_step_state(m, L, np.r_[R[0, :7], np.zeros(7), R[0, :7], np.zeros(7)],
                                             np.zeros(L.nz), p) for p in P])
    noise = np.hstack([noise_array(sensor.with_seed(i), "torque", 7, N).T for i in range(P.shape[0])])
    fold = sample_step_function(m, ctrl, L).mapaccum("fold", N)
    par = fold.map(P.shape[0], "thread", threads)
    t0 = time.perf_counter()
    w, _aux = par(W0, ca.repmat(ca.DM(R.T), 1, P.shape[0]), noise, P.T)
    wall = time.perf_counter() - t0
    w = np.asarray(w)
    return wall, np.array([w[:28, (i + 1) * N - 1] for i in range(P.shape[0])])


def bench_sampled_batch(checks: list) -> dict:
    """The section's results (keys in the module docstring); appends the peer-agreement check."""
    from fjm_runtime.batch.runner import simulate_batch
    m, ctrl, ref, P, sensor = _case()
    out = {"model": "panda", "law": "ismc_tau", "rate_hz": 1000, "delay_samples": 1, "runs": RUNS,
           "duration_s": DURATION}
    for simd in (False, True):
        name = "simd" if simd else "scalar"
        t0 = time.perf_counter()
        b = simulate_batch(m, ctrl, ref, P[:1], duration=0.01, sensor=sensor, delay_samples=1, simd=simd)
        out[f"{name}_build_s"] = time.perf_counter() - t0
        out["substeps"] = b.info["substeps"]
        for threads in (1, 2):
            t0 = time.perf_counter()
            b = simulate_batch(m, ctrl, ref, P, duration=DURATION, sensor=sensor, delay_samples=1, simd=simd,
                               threads=threads)
            out[f"{name}_{threads}t_sim_s_per_s"] = RUNS * DURATION / (time.perf_counter() - t0)
            out[f"{name}_path"] = b.info["path"]
    short = simulate_batch(m, ctrl, ref, P, duration=PEER_DURATION, sensor=sensor, delay_samples=1,
                           simd=False, seeds=np.arange(RUNS))
    out["substeps"] = short.info["substeps"]  # the batch takes the largest rule over its rows: the peer too
    for threads in (1, 2):
        wall, x_fin = _peer(m, ctrl, ref, P, sensor, out["substeps"], threads, PEER_DURATION)
        out[f"casadi_map_{threads}t_sim_s_per_s"] = RUNS * PEER_DURATION / wall
    dev = float(np.max(np.abs(x_fin - short.x_final)))
    checks.append({"key": "sampled_batch.peer_max_abs_dx", "what": "CasADi map peer vs batch final state",
                   "measured": dev, "tolerance": 1e-9, "ok": bool(dev <= 1e-9)})
    out["peer_max_abs_dx"] = dev
    return out
