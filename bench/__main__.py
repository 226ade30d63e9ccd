"""``python -m bench`` (``make bench``): speed against peers measured in the same run.

Every peer's output is compared with the generated code in the same run
(:data:`TOLERANCES`); ``make bench`` exits 1 when one disagrees, when
``generated/`` differs from a fresh ``python -m derive``, or when a section
fails. A full run writes ``bench/results.json`` (nested; dotted keys like
``derive.planar7.seconds`` resolve through the nesting and are also listed flat
under ``"flat"``) and rewrites the tables between ``<!-- bench:begin -->`` and
``<!-- bench:end -->`` in README.md and bench/README.md from it
(:mod:`bench.report`). ``--quick`` (one repetition per figure) and ``--only``
runs write ``build/bench-results.json`` unless ``--out`` is given, and leave the
READMEs alone.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from . import report
from .realtime import bench_realtime

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
AB_MODELS = ("link1", "planar2", "planar4", "planar7")
DEFAULT_OUT = HERE / "results.json"

#: Largest accepted disagreement between a peer and the generated code, per comparison.
TOLERANCES = {
    # |a - a_ref| / max(1, max |a_ref|) over alpha and beta at 3 random states
    "alpha_beta": 1e-9,
    # |checksum - sum over the timed calls of alpha[0] + beta[0, 0] from the .casadi Functions|, relative
    "alpha_beta_checksum": 1e-9,
    # states (rad, rad/s) of the hand-written C loop vs the generated loop, max abs
    "hand_c_states": 1e-9,
    # u, s, y_hat of the hand-written C loop vs the generated loop, relative to max(1, max |.|)
    "hand_c_outputs": 1e-9,
    # the mapaccum form (casadi.external) vs the C loop form of the same step, max abs state
    "mapaccum_states": 1e-12,
    # simulate(backend="python") vs simulate(backend="compiled"): states, max abs
    "python_states": 1e-9,
    # metrics of two runs of the same loop: |a - b| / max(|b|, 1e-6), inf/nan must match
    "metrics": 1e-9,
    # scipy RK45 (law evaluated continuously, no zero-order hold) vs RK4 + ZOH, max abs state
    "solve_ivp_states": 5e-3,
    # numpy batch peer vs simulate_batch, final states max abs
    "numpy_batch_states": 1e-9,
}


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def median_time(fn, reps: int, warmup: int = 1) -> float:
    for _ in range(warmup):
        fn()
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def alternate(fns, rounds: int, per_round) -> list:
    """Median seconds of each of ``fns``, timed in alternation (``per_round[i]`` calls per round).

    A busy neighbour on a shared machine then lands on every side of a comparison alike.
    """
    samples = [[] for _ in fns]
    for _ in range(rounds):
        for i, fn in enumerate(fns):
            for _ in range(per_round[i]):
                t0 = time.perf_counter()
                fn()
                samples[i].append(time.perf_counter() - t0)
    return [statistics.median(s) for s in samples]


def check(checks: list, key: str, what: str, measured: float, tolerance: float) -> None:
    """Record one peer comparison: ``ok`` iff ``measured <= tolerance`` (NaN fails)."""
    measured = float(measured)
    ok = bool(np.isfinite(measured) and measured <= tolerance)
    checks.append({"key": key, "what": what, "measured": measured, "tolerance": float(tolerance), "ok": ok})
    if not ok:
        log(f"PEER DISAGREES: {key}: {what}: {measured:.3g} > tolerance {tolerance:.3g}")


def metric_diff(a: dict, b: dict, keys) -> float:
    """``max |a - b| / max(|b|, 1e-6)`` over the metrics ``keys``; mismatched inf/nan count as inf."""
    worst = 0.0
    for k in keys:
        x, y = np.asarray(a[k], dtype=float), np.asarray(b[k], dtype=float)
        same = (x == y) | (np.isnan(x) & np.isnan(y))
        fin = np.isfinite(x) & np.isfinite(y)
        if np.any(~same & ~fin):
            return float("inf")
        if np.any(fin):
            worst = max(worst, float(np.max(np.abs(x[fin] - y[fin]) / np.maximum(np.abs(y[fin]), 1e-6))))
    return worst


def _rel(a, ref) -> float:
    a, ref = np.asarray(a, dtype=float), np.asarray(ref, dtype=float)
    return float(np.max(np.abs(a - ref)) / max(1.0, float(np.max(np.abs(ref)))))


# -- derive -------------------------------------------------------------------------------
def parse_derive_log(text: str) -> dict:
    """Per-model seconds and ops from ``python -m derive``'s progress lines.

    ``[i/N] <model>: deriving ... <s> s (symbolic ..., emit ...), <ops> ops`` and
    ``derived N model(s) in <s> s``.
    """
    import re
    models = {}
    # short models: "[i/N] m: deriving ... 1.2 s (...), k ops"; long ones print stage lines first and
    # end with "[i/N] m: 12.3 s (...), k ops"
    for m in re.finditer(r"\]\s+(\S+):(?: deriving \.\.\.)?\s*([0-9.]+) s \(.*?(\d+) ops", text):
        models[m.group(1)] = {"seconds": float(m.group(2)), "operations": int(m.group(3))}
    tot = re.search(r"derived \d+ model\(s\) in ([0-9.]+) s", text)
    if not models or not tot:
        raise RuntimeError(f"cannot parse the derive log:\n{text[-2000:]}")
    return {"models": models, "total_seconds": float(tot.group(1))}


def differing_files(fresh: Path, committed: Path, models) -> list:
    """Files of ``models`` whose bytes differ between two generated/ trees (or exist in one only)."""
    bad = []
    for m in models:
        a, b = fresh / m, committed / m
        names = {p.name for p in a.iterdir() if p.is_file()} | \
            ({p.name for p in b.iterdir() if p.is_file()} if b.is_dir() else set())
        for nm in sorted(names):
            if not (a / nm).is_file() or not (b / nm).is_file() or (a / nm).read_bytes() != (b / nm).read_bytes():
                bad.append(f"{m}/{nm}")
    return bad


def bench_derive(work: Path, reps: int, checks: list) -> dict:
    from .ccutil import compile_object
    runs = []
    out = work / "generated"
    timings_file = work / "derive-timings.json"
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    for i in range(reps):
        log(f"derive: run {i + 1}/{reps} (python -m derive --out {out}) ...")
        t0 = time.time()
        proc = subprocess.run([sys.executable, "-m", "derive", "--out", str(out), "--timings", str(timings_file)],
                              cwd=str(REPO), env=env,
                              check=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        wall = time.time() - t0
        data = parse_derive_log(proc.stdout)
        try:  # full-precision timings written by derive --timings
            if timings_file.stat().st_mtime >= t0:
                fresh = json.loads(timings_file.read_text())
                if set(fresh["models"]) == set(data["models"]):
                    data = fresh
        except (OSError, ValueError, KeyError):
            pass
        data["wall_seconds"] = wall
        runs.append(data)
    res = {"total_seconds": statistics.median(r["total_seconds"] for r in runs),
           "wall_seconds": statistics.median(r["wall_seconds"] for r in runs), "repetitions": reps,
           "n_models": len(runs[0]["models"])}
    for name in runs[0]["models"]:
        manifest = json.loads((out / name / "manifest.json").read_text())
        fn_ops = {q: f["operations"] for q, f in manifest["functions"].items()}
        res[name] = {
            "seconds": statistics.median(r["models"][name]["seconds"] for r in runs),
            **{k: statistics.median(r["models"][name][k] for r in runs)
               for k in ("derive_seconds", "emit_seconds") if all(k in r["models"][name] for r in runs)},
            "ops": runs[0]["models"][name]["operations"],
            "ops_by_function": fn_ops,
            "c_bytes": manifest["c_sources"][f"{name}.c"],
        }
    # gcc -O2 of the planar7 C source, same flags as everything else here
    src = out / "planar7" / "planar7.c"
    if src.exists():
        ts = []
        for i in range(reps):
            log(f"gcc -O2 planar7.c: run {i + 1}/{reps} ...")
            ts.append(compile_object(src, work / "planar7_gcc.o"))
        res["planar7"]["gcc_seconds"] = statistics.median(ts)
    # op-count growth exponent over planar3..7 (least-squares slope of log ops vs log n)
    ns = [n for n in range(1, 8) if f"planar{n}" in res]
    if len(ns) >= 3:
        ops = [res[f"planar{n}"]["ops"] for n in ns]
        res["ops_growth_exponent_planar"] = float(np.polyfit(np.log(ns[2:]), np.log(ops[2:]), 1)[0])
        res["ops_growth_exponent_by_function"] = {
            q: float(np.polyfit(np.log(ns[2:]), np.log([max(1, res[f"planar{n}"]["ops_by_function"][q])
                                                         for n in ns[2:]]), 1)[0])
            for q in res[f"planar{ns[-1]}"]["ops_by_function"]}
    # the committed generated/ is what derive produces now, byte for byte (every file)
    bad = differing_files(out, REPO / "generated", runs[0]["models"])
    res["matches_committed_generated"] = not bad
    res["files_differing_from_committed"] = bad
    check(checks, "derive.generated_files",
          "files of generated/ that differ from a fresh `python -m derive`"
          + (f" ({', '.join(bad[:5])}{', ...' if len(bad) > 5 else ''})" if bad else ""),
          len(bad), 0)
    return res


# -- alpha + beta ---------------------------------------------------------------------------
def timed_loop_error(m, x, p, libs, iters: int = 8) -> float:
    """Relative error of the timed C loops' checksum against the ``.casadi`` Functions.

    The timed loop of each library calls alpha + beta ``iters`` times at ``x`` with
    ``x[0]`` nudged by ``1e-9 (k & 7)`` and sums ``alpha[0] + beta[0, 0]``; the same sum
    is formed here from the model's Functions, so a loop that times the wrong work fails.

    Parameters
    ----------
    m : fjm_runtime.Model
    x : numpy.ndarray, shape (4n,)
    p : numpy.ndarray, shape (len(m.param_names),)
    libs : sequence
        Timing libraries with ``timed_run(x, p, iters) -> (seconds, checksum)``.
    iters : int

    Returns
    -------
    float
        The largest relative checksum error over ``libs``.
    """
    want = 0.0
    for k in range(iters):
        xk = x.copy()
        xk[0] = x[0] + 1e-9 * (k & 7)
        want += float(m.alpha(xk, p)[0]) + float(m.beta(xk, p)[0, 0])
    return max(abs(lib.timed_run(x, p, iters)[1] - want) / max(1.0, abs(want)) for lib in libs)


def bench_alpha_beta(work: Path, reps: int, checks: list, models=AB_MODELS) -> dict:
    import fjm_runtime
    from .alpha_beta import build_generated, build_peer, time_interleaved
    tol, tol_chk = TOLERANCES["alpha_beta"], TOLERANCES["alpha_beta_checksum"]
    res = {}
    for name in models:
        m = fjm_runtime.load(name)
        rng = np.random.default_rng(1)
        xs = [rng.normal(scale=0.5, size=m.nx) for _ in range(3)]
        x = xs[0]
        p = m.params_array()
        log(f"alpha+beta {name}: compiling generated and peers ...")
        gen = build_generated(m, work / "ab")
        # the .casadi Functions (what fjm_runtime loads) at the test states
        refs = [(m.alpha(xi, p), m.beta(xi, p)) for xi in xs]
        gen_out = [gen(xi, p) for xi in xs]
        err_c = max(max(_rel(a, ra), _rel(b, rb)) for (a, b), (ra, rb) in zip(gen_out, refs))
        entry = {"generated_c_vs_casadi": err_c}
        check(checks, f"alpha_beta.{name}.generated_c",
              f"{name}: generated C (`generated/{name}/{name}.c`) vs the generated `.casadi` Functions",
              err_c, tol)
        peers, libs = {}, [gen]
        for variant in ("structured", "generic"):
            peer, gcc_s, c_bytes = build_peer(name, variant, work / "ab", m.n, m.nx)
            err = 0.0
            for xi, (ga, gb), (ra, rb) in zip(xs, gen_out, refs):
                a, b = peer(xi, p)
                err = max(err, _rel(a, ga), _rel(b, gb), _rel(a, ra), _rel(b, rb))
            peers[variant] = {"gcc_seconds": gcc_s, "c_bytes": c_bytes, "max_rel_diff_vs_generated": err}
            check(checks, f"alpha_beta.{name}.{variant}",
                  f"{name}: AD peer ({variant}) vs generated C and `.casadi`", err, tol)
            libs.append(peer)
        # the timed loops compute what they claim: checksum of 8 calls vs the .casadi Functions
        chk_err = timed_loop_error(m, x, p, libs)
        check(checks, f"alpha_beta.{name}.timed_loop",
              f"{name}: checksum of the timed C loops (generated and peers) vs the `.casadi` Functions",
              chk_err, tol_chk)
        us = time_interleaved(libs, x, p, reps=3 * reps)
        entry["generated_us"] = us[0]
        for variant, t in zip(("structured", "generic"), us[1:]):
            peers[variant]["us"] = t
        best = min(peers, key=lambda v: peers[v]["us"])
        entry["peer_us"] = peers[best]["us"]
        entry["peer_variant"] = best
        entry["ratio"] = entry["generated_us"] / entry["peer_us"]
        entry["peers"] = peers
        res[name] = entry
        log(f"  {name}: generated {entry['generated_us']:.3f} us, peer ({best}) {entry['peer_us']:.3f} us")
    return res


# -- spatial arm: the Panda against the adam-robotics peer ------------------------------------
def bench_spatial(work: Path, reps: int, checks: list, name: str = "panda") -> dict:
    """alpha + beta of the spatial ``name``: generated C vs the adam-robotics + CasADi AD peer."""
    import fjm_runtime
    from .alpha_beta import build_generated, time_interleaved
    from .ccutil import compile_object
    from .spatial import build_adam_peer, generated_alpha_beta_c
    tol, tol_chk = TOLERANCES["alpha_beta"], TOLERANCES["alpha_beta_checksum"]
    m = fjm_runtime.load(name)
    p = m.params_array({"m_load": 0.0})  # adam knows no payload: compare without one
    rng = np.random.default_rng(1)
    xs = [rng.normal(scale=0.5, size=m.nx) for _ in range(3)]
    x = xs[0]
    log(f"spatial {name}: gcc -O2 of the shipped {name}.c (every function it ships) ...")
    obj = work / "spatial" / f"{name}.o"
    obj.parent.mkdir(parents=True, exist_ok=True)
    gcc_all = statistics.median(compile_object(REPO / "generated" / name / f"{name}.c", obj)
                                for _ in range(max(1, reps // 2)))
    gen = build_generated(m, work / "spatial", obj=obj)
    ab_only = [generated_alpha_beta_c(m, work / "spatial") for _ in range(max(1, reps // 2))]
    log(f"spatial {name}: building the adam-robotics peer (CasADi AD, CSE, codegen, gcc -O2) ...")
    peer, info = build_adam_peer(m, work / "spatial")
    refs = [(m.alpha(xi, p), m.beta(xi, p)) for xi in xs]
    gen_out = [gen(xi, p) for xi in xs]
    err_c = max(max(_rel(a, ra), _rel(b, rb)) for (a, b), (ra, rb) in zip(gen_out, refs))
    check(checks, f"spatial.{name}.generated_c",
          f"{name}: generated C (`generated/{name}/{name}.c`) vs the generated `.casadi` Functions", err_c, tol)
    err = 0.0
    for xi, (ga, gb), (ra, rb) in zip(xs, gen_out, refs):
        a, b = peer(xi, p)
        err = max(err, _rel(a, ga), _rel(b, gb), _rel(a, ra), _rel(b, rb))
    check(checks, f"spatial.{name}.adam_peer",
          f"{name}: adam-robotics + CasADi AD peer (same URDF) vs generated C and `.casadi`, alpha and beta",
          err, tol)
    chk_err = timed_loop_error(m, x, p, (gen, peer))
    check(checks, f"spatial.{name}.timed_loop",
          f"{name}: checksum of the timed C loops (generated and adam peer) vs the `.casadi` Functions",
          chk_err, tol_chk)
    gen_us, peer_us = time_interleaved([gen, peer], x, p, reps=3 * reps)
    log(f"  {name}: generated {gen_us:.2f} us, adam peer {peer_us:.2f} us")
    manifest = json.loads((REPO / "generated" / name / "manifest.json").read_text())
    return {
        "n": int(m.n),
        "generated_us": gen_us, "peer_us": peer_us, "ratio": gen_us / peer_us,
        "generated_c_bytes_all": int(manifest["c_sources"][f"{name}.c"]), "generated_gcc_seconds_all": gcc_all,
        "generated_c_bytes": int(ab_only[0]["c_bytes"]),
        "generated_gcc_seconds": statistics.median(a["gcc_seconds"] for a in ab_only),
        "generated_ops": {q: int(manifest["functions"][q]["operations"]) for q in ("alpha", "beta")},
        "peer_c_bytes": int(info["c_bytes"]), "peer_gcc_seconds": info["gcc_seconds"],
        "peer_build_seconds": info["build_seconds"], "peer_ops": info["ops"],
        "max_rel_diff_peer_vs_generated": err,
    }


# -- closed loop ----------------------------------------------------------------------------
def bench_closed_loop(work: Path, reps: int, slow_reps: int, checks: list) -> dict:
    import casadi as ca
    from fjm_runtime.batch.runner import METRIC_NAMES
    from fjm_runtime.sim.compiled import closed_loop_library
    from .closed_loop import GeneratedLoop, HandLoop, link1_case, simulate_call, solve_ivp_loop
    case = link1_case()
    log("closed loop link1 10 s @ 1 kHz: compiling generated and hand C ...")
    lib = closed_loop_library(case.model, case.controller, case.dt)
    R0, RH, R1 = case.reference_arrays()
    w0 = case.x0()
    W, A = lib(w0, R0, RH, R1, case.p_true)
    out = (np.empty_like(W), np.empty_like(A))
    hand = HandLoop(case, work / "hand")
    Wh, Ah = hand()
    check(checks, "closed_loop.hand_c_states", "link1 loop: hand-written C vs generated, states (max abs)",
          float(np.max(np.abs(W - Wh))), TOLERANCES["hand_c_states"])
    check(checks, "closed_loop.hand_c_outputs", "link1 loop: hand-written C vs generated, u, s, y_hat (relative)",
          _rel(Ah, A), TOLERANCES["hand_c_outputs"])
    # 1. the bare compiled loop (preallocated outputs) vs the hand-written C loop: same work
    gen_call = lambda: lib(w0, R0, RH, R1, case.p_true, out=out)  # noqa: E731
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
          float(np.max(np.abs(Wm - W))), TOLERANCES["mapaccum_states"])
    dm_args = [ca.DM(gl.w0), ca.DM(gl.R0), ca.DM(gl.RH), ca.DM(gl.R1), ca.DM(case.p_true)]
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


# -- batch ------------------------------------------------------------------------------------
def bench_batch(reps: int, slow_reps: int, checks: list, n_runs: int = 1000) -> dict:
    import warnings
    from fjm_runtime.batch.runner import METRIC_NAMES, SimdFallbackWarning, simulate_batch, vector_isa
    from .closed_loop import link1_case, numpy_batch
    case = link1_case()
    Ks = np.random.default_rng(0).uniform(100.0, 200.0, n_runs)
    P = np.tile(case.p_true, (n_runs, 1))
    P[:, 2] = Ks

    def run(threads=None, simd=True):
        with warnings.catch_warnings():
            warnings.simplefilter("error", SimdFallbackWarning)   # an error here, not a footnote
            return simulate_batch(case.model, case.controller, case.reference, P, duration=case.duration,
                                  dt=case.dt, x0=case.x0(), simd=simd, threads=threads)

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


# -- main -------------------------------------------------------------------------------------
def flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, key + "."))
        elif isinstance(v, (int, float, bool, str)) or v is None:
            out[key] = v
    return out


def machine() -> dict:
    info = {"python": platform.python_version(), "cpu_count": os.cpu_count(),
            "platform": platform.platform(), "processor": platform.processor()}
    try:
        with open("/proc/cpuinfo") as fh:
            info["cpu_model"] = next((ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")),
                                     platform.processor())
    except OSError:
        info["cpu_model"] = platform.processor()
    try:
        from fjm_runtime.batch.runner import vector_isa
        info["simd_isa"] = vector_isa()[0]
    except Exception:  # noqa: BLE001 - informative only
        info["simd_isa"] = "unknown"
    try:
        info["load_average_start"] = os.getloadavg()[0]
    except OSError:
        info["load_average_start"] = float("nan")
    return info


def _sampled_batch(checks: list) -> dict:
    """The sampled-data batch throughput section (:mod:`bench.sampled_batch`)."""
    from bench.sampled_batch import bench_sampled_batch
    return bench_sampled_batch(checks)


def _sampled_loop() -> dict:
    """The sampled-data loop section (:mod:`bench.sampled_loop`): substeps and delay prediction."""
    from bench.sampled_loop import bench_sampled_loop
    return bench_sampled_loop(log=log)


def _scaling(work: Path, results: dict) -> dict:
    """The scaling section (:mod:`bench.scaling`): synthetic chains of 7..30 joints, fitted growth."""
    from bench.scaling import bench_scaling
    spatial = results.get("spatial")
    return bench_scaling(work / "scaling", spatial=spatial if isinstance(spatial, dict) else None, log=log)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench", description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="one repetition per figure (smoke test / checks)")
    ap.add_argument("--skip-derive", action="store_true", help="skip the derive and gcc timings")
    ap.add_argument("--only", nargs="+", choices=("derive", "alpha_beta", "spatial", "closed_loop", "batch",
                                                  "realtime", "sampled_batch", "scaling", "sampled_loop"),
                    help="run only these sections")
    ap.add_argument("--out", type=Path, default=None,
                    help="results file (default: bench/results.json for a full run, "
                         "build/bench-results.json otherwise)")
    args = ap.parse_args(argv)
    reps, slow = (1, 1) if args.quick else (5, 3)
    sections = set(args.only or ("derive", "alpha_beta", "spatial", "closed_loop", "batch", "realtime",
                                 "sampled_batch", "scaling", "sampled_loop"))
    if args.skip_derive:
        sections.discard("derive")
    full = not args.quick and len(sections) == 9
    out = args.out or (DEFAULT_OUT if full else REPO / "build" / "bench-results.json")
    t_start = time.perf_counter()
    results = {"machine": machine(), "quick": bool(args.quick)}
    checks: list = []
    with tempfile.TemporaryDirectory(prefix="fjm-bench-") as tmp:
        work = Path(tmp)
        os.environ.setdefault("FJM_CACHE", str(work / "cache"))  # cold, private compile cache
        plan = [("derive", lambda: bench_derive(work, 1 if args.quick else 3, checks)),
                ("alpha_beta", lambda: bench_alpha_beta(work, reps, checks)),
                ("spatial", lambda: bench_spatial(work, reps, checks)),
                ("closed_loop", lambda: bench_closed_loop(work, reps, slow, checks)),
                ("batch", lambda: bench_batch(reps, slow, checks)),
                ("realtime", lambda: bench_realtime(work, 10 ** 4 if args.quick else 10 ** 6, checks, check)),
                ("sampled_batch", lambda: _sampled_batch(checks)),
                ("scaling", lambda: _scaling(work, results)),
                ("sampled_loop", lambda: _sampled_loop())]
        failed = []
        for name, run in plan:
            if name not in sections:
                continue
            try:
                results[name] = run()
            except Exception as exc:  # noqa: BLE001 - report, keep measuring the rest
                import traceback
                traceback.print_exc()
                results[name] = {"error": f"{type(exc).__name__}: {exc}"}
                failed.append(name)
    results["bench_seconds"] = time.perf_counter() - t_start
    results["finished_utc"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    results["checks"] = checks
    results["tolerances"] = dict(TOLERANCES)
    results["flat"] = flatten({k: v for k, v in results.items()
                               if k not in ("machine", "checks", "tolerances", "quick", "finished_utc")})
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2, sort_keys=True) + "\n")
    print(report.render_bench_readme(results))
    print(f"\nwrote {out} in {results['bench_seconds']:.0f} s")
    if out.resolve() == DEFAULT_OUT.resolve():
        for path in report.write_all(results):
            print(f"rewrote the bench tables in {path}")
    bad = [c for c in checks if not c["ok"]]
    status = 0
    if bad:
        print(f"\nFAILED: {len(bad)} of {len(checks)} peer checks disagree with the generated code:", file=sys.stderr)
        for c in bad:
            print(f"  {c['key']}: {c['what']}: {c['measured']:.3g} > tolerance {c['tolerance']:.3g}",
                  file=sys.stderr)
        status = 1
    if failed:
        print(f"sections that failed: {', '.join(failed)} (see the traceback above)", file=sys.stderr)
        status = 1
    if not status:
        print(f"all {len(checks)} peer checks agree with the generated code")
    return status


if __name__ == "__main__":
    sys.exit(main())
