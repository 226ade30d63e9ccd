"""Sections ``closed_loop`` and ``batch``: the link1 sampled-data loop with one RK4 substep per sample
(bare compiled loop vs hand-written C, the whole ``simulate()`` call vs the Python backend, mapaccum and
solve_ivp for context) and 1000 closed loops of ``simulate_batch(..., substeps=1)`` against the NumPy
batch peer (:mod:`bench.closed_loop`)."""
from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from .checks import TOLERANCES, check, metric_diff, rel_diff
from .timing import alternate, log, median_time

__all__ = ["bench_batch", "bench_closed_loop"]


def bench_closed_loop(work: Path, reps: int, slow_reps: int, checks: list) -> dict:
    import casadi as ca
    from fjm_runtime.batch.runner import METRIC_NAMES
    from fjm_runtime.sim.compiled import sampled_loop_library
    from .closed_loop import GeneratedLoop, HandLoop, link1_case, simulate_call, solve_ivp_loop
    case = link1_case()
    log("closed loop link1 10 s @ 1 kHz: compiling generated and hand C ...")
    lib = sampled_loop_library(case.model, case.controller, case.layout())
    R, NOISE = case.reference_rows(), case.noise()
    w0 = case.w0()
    W, A = lib(w0, R, NOISE, case.p_true)
    W = W[:, :case.model.nx]                  # w = x here (stateless law, ideal sensor, no delay)
    out = (np.empty((case.n_steps, w0.size)), np.empty_like(A))
    hand = HandLoop(case, work / "hand")
    Wh, Ah = hand()
    check(checks, "closed_loop.hand_c_states", "link1 loop: hand-written C vs generated, states (max abs)",
          float(np.max(np.abs(W - Wh))), TOLERANCES["hand_c_states"])
    check(checks, "closed_loop.hand_c_outputs", "link1 loop: hand-written C vs generated, u, s, y_hat (relative)",
          rel_diff(Ah, A), TOLERANCES["hand_c_outputs"])
    # 1. the bare compiled loop (preallocated outputs) vs the hand-written C loop: same work
    gen_call = lambda: lib(w0, R, NOISE, case.p_true, out=out)  # noqa: E731
    gen_s, hand_s = alternate([gen_call, hand], 3 * reps, [1, 1])
    # 2. the whole simulate() call, backend="compiled" vs backend="python": same arguments
    log("closed loop: whole simulate() call, compiled and python backends ...")
    sim_c = simulate_call(case, "compiled")
    sim_py = simulate_call(case, "python")
    check(checks, "closed_loop.python_states",
          'link1: simulate(backend="python") vs simulate(backend="compiled"), states (max abs)',
          float(np.max(np.abs(sim_py.x - sim_c.x))), TOLERANCES["python_states"])
    met = lambda r: {k: getattr(r.metrics, k) for k in METRIC_NAMES}  # noqa: E731
    check(checks, "closed_loop.python_metrics",
          'link1: simulate(backend="python") vs simulate(backend="compiled"), metrics (relative)',
          metric_diff(met(sim_py), met(sim_c), METRIC_NAMES), TOLERANCES["metrics"])
    check(checks, "closed_loop.compiled_call_states",
          'link1: simulate(backend="compiled") vs the bare generated loop, states (max abs)',
          float(np.max(np.abs(sim_c.x[1:] - W))), TOLERANCES["python_states"])
    py_s, sim_s = alternate([lambda: simulate_call(case, "python"), lambda: simulate_call(case, "compiled")],
                            slow_reps, [1, 3])
    # 3. context: the mapaccum form through casadi.external, scipy solve_ivp
    gl = GeneratedLoop(case)
    Wm, _ = gl()
    check(checks, "closed_loop.mapaccum_states", "link1 loop: mapaccum via casadi.external vs the C loop, states",
          float(np.max(np.abs(Wm[:, :case.model.nx] - W))), TOLERANCES["mapaccum_states"])
    dm_args = [ca.DM(a) for a in gl.args()]
    mapaccum_s = median_time(lambda: gl.runner.call(dm_args), reps)
    log("closed loop: scipy solve_ivp RK45 ...")
    ivp = solve_ivp_loop(case)
    check(checks, "closed_loop.solve_ivp_states",
          "link1: scipy RK45 (continuous law) vs RK4 + zero-order hold, states (max abs)",
          float(np.max(np.abs(ivp.y.T[1:] - W))) if ivp.success else float("inf"),
          TOLERANCES["solve_ivp_states"])
    ivp_s = median_time(lambda: solve_ivp_loop(case), slow_reps, warmup=0)
    return {
        "steps": case.n_steps,
        "k_s": float(case.controller.k_s[0]), "delta": float(case.controller.delta[0]),
        "beta_hat": float(case.controller.beta_hat[0, 0]),
        # bare loops, same work
        "generated_ms": 1e3 * gen_s, "hand_c_ms": 1e3 * hand_s, "ratio_to_hand_c": gen_s / hand_s,
        # whole simulate() calls, same work
        "simulate_compiled_ms": 1e3 * sim_s, "simulate_python_ms": 1e3 * py_s,
        "speedup_vs_python": py_s / sim_s,
        # context
        "generated_mapaccum_external_ms": 1e3 * mapaccum_s,
        "solve_ivp_ms": 1e3 * ivp_s, "solve_ivp_nfev": int(ivp.nfev),
        "solve_ivp_over_simulate_compiled": ivp_s / sim_s,
        "max_state_diff_generated_vs_hand_c": float(np.max(np.abs(W - Wh))),
        "max_state_diff_python_vs_compiled": float(np.max(np.abs(sim_py.x - sim_c.x))),
        "max_state_diff_solve_ivp_vs_rk4": float(np.max(np.abs(ivp.y.T[1:] - W))),
    }


def bench_batch(reps: int, slow_reps: int, checks: list, n_runs: int = 1000) -> dict:
    import warnings
    from fjm_runtime.batch.runner import METRIC_NAMES, SimdFallbackWarning, simulate_batch
    from fjm_runtime.batch.simd import vector_isa
    from .closed_loop import PEER_INTERFACE, link1_case
    from .numpy_batch import JOINT_PEER_FIGURES, numpy_batch
    case = link1_case()
    from fjm_runtime.control.defaults import PAPER_K_RANGE
    Ks = np.random.default_rng(0).uniform(*PAPER_K_RANGE, n_runs)
    P = np.tile(case.p_true, (n_runs, 1))
    P[:, 2] = Ks

    def run(threads=None, simd=True):
        with warnings.catch_warnings():
            warnings.simplefilter("error", SimdFallbackWarning)   # an error here, not a footnote
            return simulate_batch(case.model, case.controller, case.reference, P, duration=case.duration,
                                  dt=case.dt, x0=case.x0(), substeps=1, simd=simd, threads=threads,
                                  interface=PEER_INTERFACE)

    log(f"batch {n_runs} x 10 s: compiling ...")
    one, allt, scal = run(threads=1), run(), run(simd=False)
    want = f"simd-{vector_isa()[0]}"
    check(checks, "batch.simd_path", f"simulate_batch ran `{one.info['path']}` / `{allt.info['path']}`, "
          f"expected `{want}` on this CPU (0 = yes)",
          0.0 if one.info["path"] == allt.info["path"] == want else 1.0, 0.0)
    check(checks, "batch.threads_agree", "simulate_batch on 1 thread vs all threads, metrics (relative)",
          metric_diff(one.metrics, allt.metrics, METRIC_NAMES), 0.0)
    check(checks, "batch.scalar_vs_simd", "simulate_batch scalar loop vs SIMD, metrics (relative)",
          metric_diff(scal.metrics, one.metrics, METRIC_NAMES), TOLERANCES["metrics"])
    log(f"batch {n_runs} x 10 s: numpy-vectorized RK4 ...")
    nb = numpy_batch(case, Ks)
    check(checks, "batch.numpy_metrics", "NumPy batch peer vs simulate_batch, metrics (relative)",
          metric_diff(one.metrics, nb, METRIC_NAMES), TOLERANCES["metrics"])
    check(checks, "batch.numpy_states", "NumPy batch peer vs simulate_batch, final states (max abs)",
          float(np.max(np.abs(one.x_final - nb["x_final"]))), TOLERANCES["numpy_batch_states"])
    check(checks, "batch.numpy_joint_metrics", "NumPy batch peer vs simulate_batch, per-joint figures (rms "
          "second half, peak torque, time at limit, torque jitter; relative) and divergence (0 = same runs)",
          max(metric_diff(one.joint_metrics, nb["joint_metrics"], JOINT_PEER_FIGURES),
              float(np.any(one.diverged != nb["diverged"]))), TOLERANCES["metrics"])
    # timed in alternation: numpy (1 thread) | batch on 1 thread | batch on all threads
    np_s, one_s, all_s = alternate([lambda: numpy_batch(case, Ks), lambda: run(threads=1), run],
                                   slow_reps, [1, 2 if reps > 1 else 1, 2 if reps > 1 else 1])
    scalar_s = median_time(lambda: run(threads=1, simd=False), max(1, reps // 2), warmup=0)
    t0 = time.process_time()
    run()
    cpu_s = time.process_time() - t0
    threads = int(allt.info["threads"])
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = float("nan")
    return {"n": n_runs, "path": one.info["path"], "lanes": one.info["lanes"],
            "numpy_s": np_s, "numpy_threads": 1,
            "generated_1thread_s": one_s, "speedup_vs_numpy": np_s / one_s,
            "generated_s": all_s, "threads": threads, "speedup_vs_numpy_all_threads": np_s / all_s,
            "speedup_per_core_all_threads": np_s / all_s / threads,
            "generated_cpu_s": cpu_s, "generated_scalar_1thread_s": scalar_s,
            "simd_over_scalar_1thread": scalar_s / one_s,
            "load_average_1min": load,
            "max_rel_metric_diff_vs_numpy": metric_diff(one.metrics, nb, METRIC_NAMES),
            "diverged": int(np.sum(one.diverged))}
