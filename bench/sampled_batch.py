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
DT, DELAY = 1e-3, 1
#: Peer vs batch, final states (rad, rad/s), max abs over the runs. Both sides evaluate THE same
#: sample step in double with the same inputs; only the order of the operations differs (CasADi's
#: virtual machine vs the emitted C), so they differ by rounding, which this stiff closed loop
#: (torque saturation, filtered dtau_J at 1 kHz) amplifies about 100x per decade of samples:
#: measured 2e-17 after 1 sample, 1e-15 after 10, 2e-13 after 100 (PEER_DURATION), 3e-2 after 1000.
#: Hence a 0.1 s comparison and a tolerance 500x the rounding measured there; a wrong input is
#: decades above it (measured: the former peer's tiled parameters 1.69, seeds off by one 0.8,
#: 12 plant substeps instead of 13 1.5e-7).
PEER_TOLERANCE = 1e-10
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
    return m, ctrl, ref, P, SensorModel.panda_white(seed=0)


def casadi_map_peer(m, ctrl, ref, P, sensor, subs, threads, duration, x0, seeds):
    """The CasADi map peer: ``(wall seconds, x_final (B, 4n))``.

    THE same work as ``simulate_batch(..., x0=x0, seeds=seeds, substeps=subs)``: the layout, the
    initial step state (``controller.initial_state`` of the noise-free first measurement), the
    reference rows ``r_k`` (5n, ``ref.sample`` flattened per sample), run ``i``'s noise from
    ``seeds[i]`` and its TRUE parameters at EVERY sample. ``map`` of a ``mapaccum`` expects the
    non-accumulated inputs of run ``i`` as N columns; given one column per run (``P.T``, B columns)
    CasADi silently tiles it, so run ``i`` met ``P[(i N + k) % B]`` at sample ``k`` (the 1.69 of
    the former peer): each run's parameters are repeated N times.
    """
    import casadi as ca
    from fjm_runtime.sim.sample_step import initial_measurement, initial_step_state, sample_step_function
    from fjm_runtime.sim.step_layout import make_layout
    from fjm_runtime.sim.sensor import noise_array
    n, B = int(m.n), P.shape[0]
    L = make_layout(m, ctrl, DT, subs, sensor, DELAY, False)
    N = int(round(duration / DT))
    R = np.asarray(ref.sample(DT * np.arange(N)), dtype=float).reshape(N, 5 * n)
    W0 = np.column_stack([initial_step_state(m, L, x0, np.asarray(ctrl.initial_state(
        0.0, initial_measurement(m, L, x0, p), R[0].reshape(5, n)), dtype=float), p) for p in P])
    noise = np.hstack([noise_array(sensor.with_seed(int(s)), L.sensing, n, N).T for s in seeds])
    fold = sample_step_function(m, ctrl, L).mapaccum("fold", N)
    par = fold.map(B, "thread", threads)
    args = (W0, ca.repmat(ca.DM(R.T), 1, B), noise, np.repeat(P.T, N, axis=1))
    if [a.shape[1] for a in args] != [B, N * B, N * B, N * B]:
        raise RuntimeError(f"peer inputs with {[a.shape for a in args]} columns: expected B, then N B")
    t0 = time.perf_counter()
    w, _aux = par(*args)
    wall = time.perf_counter() - t0
    w = np.asarray(w)
    return wall, np.array([w[:L.nx, (i + 1) * N - 1] for i in range(B)])


def bench_sampled_batch(checks: list) -> dict:
    """The section's results (keys in the module docstring); appends the peer-agreement check."""
    from fjm_runtime.batch.runner import simulate_batch
    m, ctrl, ref, P, sensor = _case()
    out = {"model": "panda", "law": "ismc_tau", "rate_hz": 1000, "delay_samples": DELAY, "runs": RUNS,
           "duration_s": DURATION}
    x0 = np.zeros(int(m.nx))                            # [q_d(0); 0; q_d(0); 0] (the batch's default), explicit
    q0 = np.asarray(ref.sample(np.zeros(1)), dtype=float).reshape(5, -1)[0]
    x0[0:7], x0[14:21] = q0, q0
    seeds = int(sensor.seed) + np.arange(RUNS)          # the batch's default (sensor.seed + i), explicit
    kw = dict(dt=DT, sensor=sensor, delay_samples=DELAY, predict=False, x0=x0)
    for simd in (False, True):
        name = "simd" if simd else "scalar"
        t0 = time.perf_counter()  # all rows: the substeps (part of the build) are the largest rule over them
        simulate_batch(m, ctrl, ref, P, duration=0.01, simd=simd, seeds=seeds, **kw)
        out[f"{name}_build_s"] = time.perf_counter() - t0
        for threads in (1, 2):
            t0 = time.perf_counter()
            b = simulate_batch(m, ctrl, ref, P, duration=DURATION, simd=simd, threads=threads, seeds=seeds, **kw)
            out[f"{name}_{threads}t_sim_s_per_s"] = RUNS * DURATION / (time.perf_counter() - t0)
            out[f"{name}_path"] = b.info["path"]
    out["substeps"] = b.info["substeps"]  # the largest rule over the rows (one value per batch): the peer's too
    short = simulate_batch(m, ctrl, ref, P, duration=PEER_DURATION, simd=False, seeds=seeds,
                           substeps=out["substeps"], **kw)
    dev = 0.0
    for threads in (1, 2):
        wall, x_fin = casadi_map_peer(m, ctrl, ref, P, sensor, out["substeps"], threads, PEER_DURATION, x0, seeds)
        out[f"casadi_map_{threads}t_sim_s_per_s"] = RUNS * PEER_DURATION / wall
        dev = max(dev, float(np.max(np.abs(x_fin - short.x_final))))
    checks.append({"key": "sampled_batch.peer_max_abs_dx", "what": "CasADi map peer vs batch final state",
                   "measured": dev, "tolerance": PEER_TOLERANCE, "ok": bool(dev <= PEER_TOLERANCE)})
    out["peer_max_abs_dx"] = dev
    return out
