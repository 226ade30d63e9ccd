"""``python -m bench`` (``make bench``): speed against peers measured in the same run.

Writes ``bench/results.json`` (nested; dotted keys like ``derive.planar7.seconds``
resolve through the nesting and are also listed flat under ``"flat"``) and prints
a table with the issue-5 targets. Every figure is the median of several
repetitions. Options: ``--quick`` (fewer repetitions, for smoke tests),
``--skip-derive``, ``--out PATH``.
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

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
AB_MODELS = ("link1", "planar2", "planar4", "planar7")

TARGETS = [  # (dotted key, comparison, bound, label)
    ("derive.total_seconds", "<=", 20.0, "make derive, all 8 models (s)"),
    ("derive.planar7.seconds", "<=", 10.0, "derive planar7 (s)"),
    ("alpha_beta.planar7.ratio", "<=", 0.7, "alpha+beta planar7, generated / AD peer"),
    ("derive.planar7.c_bytes", "<=", 0.5e6, "planar7 C source (bytes)"),
    ("derive.planar7.gcc_seconds", "<=", 5.0, "gcc -O2 planar7.c (s)"),
    ("closed_loop.ratio_to_hand_c", "<=", 1.5, "closed loop link1, generated / hand C"),
    ("closed_loop.speedup_vs_python", ">=", 50.0, "closed loop, speed-up vs Python loop"),
    ("batch.generated_s", "<=", 0.3, "batch 1000 x 10 s, generated (s)"),
    ("batch.speedup_vs_numpy", ">=", 9.0, "batch, speed-up vs numpy RK4"),
]


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


# -- derive -------------------------------------------------------------------------------
def parse_derive_log(text: str) -> dict:
    """Per-model seconds and ops from ``python -m derive``'s progress lines.

    ``[i/N] <model>: deriving ... <s> s (symbolic ..., emit ...), <ops> ops`` and
    ``derived N model(s) in <s> s``.
    """
    import re
    models = {}
    for m in re.finditer(r"\]\s+(\S+): deriving \.\.\.\s*([0-9.]+) s .*?(\d+) ops", text):
        models[m.group(1)] = {"seconds": float(m.group(2)), "operations": int(m.group(3))}
    tot = re.search(r"derived \d+ model\(s\) in ([0-9.]+) s", text)
    if not models or not tot:
        raise RuntimeError(f"cannot parse the derive log:\n{text[-2000:]}")
    return {"models": models, "total_seconds": float(tot.group(1))}


def bench_derive(work: Path, reps: int) -> dict:
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
           "wall_seconds": statistics.median(r["wall_seconds"] for r in runs), "repetitions": reps}
    for name in runs[0]["models"]:
        manifest = json.loads((out / name / "manifest.json").read_text())
        fn_ops = {q: f["operations"] for q, f in manifest["functions"].items()}
        res[name] = {
            "seconds": statistics.median(r["models"][name]["seconds"] for r in runs),
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
    # is the committed generated/ what derive produces now?
    same = all((out / m / f"{m}.c").read_bytes() == (REPO / "generated" / m / f"{m}.c").read_bytes()
               for m in runs[0]["models"] if (REPO / "generated" / m / f"{m}.c").exists())
    res["matches_committed_generated"] = bool(same)
    return res


# -- alpha + beta ---------------------------------------------------------------------------
def bench_alpha_beta(work: Path, reps: int, models=AB_MODELS) -> dict:
    import fjm_runtime
    from .alpha_beta import build_generated, build_peer, time_interleaved
    res = {}
    for name in models:
        m = fjm_runtime.load(name)
        rng = np.random.default_rng(1)
        x = rng.normal(scale=0.5, size=m.nx)
        p = m.params_array()
        log(f"alpha+beta {name}: compiling generated and peers ...")
        gen = build_generated(m, work / "ab")
        a_ref, b_ref = m.alpha(x, p), m.beta(x, p)
        peers, libs = {}, []
        for variant in ("structured", "generic"):
            peer, gcc_s, c_bytes = build_peer(name, variant, work / "ab", m.n, m.nx)
            a, b = peer(x, p)
            err = max(float(np.max(np.abs(a - a_ref)) / max(1.0, float(np.max(np.abs(a_ref))))),
                      float(np.max(np.abs(b - b_ref))))
            peers[variant] = {"gcc_seconds": gcc_s, "c_bytes": c_bytes, "max_rel_diff_vs_generated": err}
            libs.append(peer)
        us = time_interleaved([gen, *libs], x, p, reps=3 * reps)
        entry = {"generated_us": us[0]}
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


# -- closed loop ----------------------------------------------------------------------------
def bench_closed_loop(work: Path, reps: int, slow_reps: int) -> dict:
    from fjm_runtime.compiled import closed_loop_library
    from .closed_loop import HandLoop, link1_case, python_loop, solve_ivp_loop
    case = link1_case()
    log("closed loop link1 10 s @ 1 kHz: compiling generated and hand C ...")
    lib = closed_loop_library(case.model, case.controller, case.dt)
    R0, RH, R1 = case.reference_arrays()
    w0 = case.x0()
    W, A = lib(w0, R0, RH, R1, case.p_true)
    out = (np.empty_like(W), np.empty_like(A))
    hand = HandLoop(case, work / "hand")
    Wh, _ = hand()
    gen_call = lambda: lib(w0, R0, RH, R1, case.p_true, out=out)  # noqa: E731
    gen_call(), hand()
    gen_t, hand_t = [], []
    for _ in range(reps * 3):  # alternate, so a busy neighbour hits both sides alike
        t0 = time.perf_counter(); gen_call(); gen_t.append(time.perf_counter() - t0)  # noqa: E702
        t0 = time.perf_counter(); hand(); hand_t.append(time.perf_counter() - t0)  # noqa: E702
    gen_s, hand_s = statistics.median(gen_t), statistics.median(hand_t)
    # context: the whole simulate() call (reference sampling, outputs, metrics) and the
    # mapaccum form of the same step loaded with casadi.external
    from fjm_runtime.simulate import simulate
    from .closed_loop import GeneratedLoop
    import casadi as ca
    sim_s = median_time(lambda: simulate(case.model, case.controller, case.reference,
                                         duration=case.duration, dt=case.dt, true_params=case.p_true,
                                         x0=w0, backend="compiled"), reps)
    gl = GeneratedLoop(case)
    dm_args = [ca.DM(gl.w0), ca.DM(gl.R0), ca.DM(gl.RH), ca.DM(gl.R1), ca.DM(case.p_true)]
    mapaccum_s = median_time(lambda: gl.runner.call(dm_args), reps)
    log("closed loop: Python loop ...")
    py_s = median_time(lambda: python_loop(case), slow_reps, warmup=0)
    py = python_loop(case)
    log("closed loop: scipy solve_ivp RK45 ...")
    ivp_s = median_time(lambda: solve_ivp_loop(case), slow_reps, warmup=0)
    ivp = solve_ivp_loop(case)
    return {
        "generated_ms": 1e3 * gen_s, "hand_c_ms": 1e3 * hand_s, "python_loop_ms": 1e3 * py_s,
        "solve_ivp_ms": 1e3 * ivp_s,
        "ratio_to_hand_c": gen_s / hand_s, "speedup_vs_python": py_s / gen_s,
        "speedup_vs_solve_ivp": ivp_s / gen_s,
        "generated_simulate_call_ms": 1e3 * sim_s, "generated_mapaccum_external_ms": 1e3 * mapaccum_s,
        "steps": case.n_steps,
        "max_state_diff_generated_vs_hand_c": float(np.max(np.abs(W - Wh))),
        "max_state_diff_generated_vs_python": float(np.max(np.abs(W - py.x[1:]))),
        "max_state_diff_solve_ivp_vs_rk4": float(np.max(np.abs(ivp.y.T[1:] - W))),
        "solve_ivp_nfev": int(ivp.nfev),
    }


# -- batch ------------------------------------------------------------------------------------
def bench_batch(reps: int, slow_reps: int, n_runs: int = 1000) -> dict:
    from fjm_runtime.batch import simulate_batch
    from .closed_loop import link1_case, numpy_batch
    case = link1_case()
    Ks = np.random.default_rng(0).uniform(100.0, 200.0, n_runs)
    P = np.tile(case.p_true, (n_runs, 1))
    P[:, 2] = Ks
    run = lambda: simulate_batch(case.model, case.controller, case.reference, P,  # noqa: E731
                                 duration=case.duration, dt=case.dt, x0=case.x0())
    log(f"batch {n_runs} x 10 s: compiling ...")
    res_gen = run()
    gen_s = median_time(run, reps, warmup=0)
    t0 = time.process_time()
    run()
    cpu_s = time.process_time() - t0
    scalar = lambda: simulate_batch(case.model, case.controller, case.reference, P,  # noqa: E731
                                    duration=case.duration, dt=case.dt, x0=case.x0(), simd=False)
    scalar()
    scalar_s = median_time(scalar, max(1, reps // 2), warmup=0)
    log(f"batch {n_runs} x 10 s: numpy-vectorized RK4 ...")
    nb = numpy_batch(case, Ks)
    np_s = median_time(lambda: numpy_batch(case, Ks), slow_reps, warmup=0)
    diff = max(float(np.nanmax(np.abs(res_gen.metrics[k] - nb[k]) / np.maximum(1e-12, np.abs(nb[k]))))
               for k in ("final_error", "rms_error", "max_abs_u", "total_variation_u"))
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = float("nan")
    return {"n": n_runs, "generated_s": gen_s, "numpy_s": np_s, "speedup_vs_numpy": np_s / gen_s,
            "generated_cpu_s": cpu_s, "generated_scalar_s": scalar_s,
            "threads": os.cpu_count(), "load_average_1min": load,
            "max_rel_metric_diff_vs_numpy": diff, "diverged": int(np.sum(res_gen.diverged))}


# -- report -----------------------------------------------------------------------------------
def flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, key + "."))
        elif isinstance(v, (int, float, bool, str)) or v is None:
            out[key] = v
    return out


def table(flat: dict) -> str:
    lines = [f"{'metric':44s} {'measured':>12s} {'target':>10s}  status"]
    for key, op, bound, label in TARGETS:
        v = flat.get(key)
        if v is None:
            lines.append(f"{label:44s} {'-':>12s} {op + ' ' + format(bound, 'g'):>10s}  not measured")
            continue
        ok = v <= bound if op == "<=" else v >= bound
        lines.append(f"{label:44s} {v:12.4g} {op + ' ' + format(bound, 'g'):>10s}  {'met' if ok else 'MISSED'}")
    lines.append("")
    lines.append(f"{'alpha+beta (us/call)':20s} {'generated':>10s} {'AD peer':>10s} {'ratio':>7s}")
    for m in AB_MODELS:
        if f"alpha_beta.{m}.ratio" in flat:
            lines.append(f"{m:20s} {flat[f'alpha_beta.{m}.generated_us']:10.3f} "
                         f"{flat[f'alpha_beta.{m}.peer_us']:10.3f} {flat[f'alpha_beta.{m}.ratio']:7.3f}")
    if "closed_loop.generated_ms" in flat:
        lines.append("")
        lines.append("closed loop link1 10 s @ 1 kHz (ms): generated {:.3f}, hand C {:.3f}, Python loop {:.1f}, "
                     "solve_ivp RK45 {:.1f}".format(flat["closed_loop.generated_ms"], flat["closed_loop.hand_c_ms"],
                                                    flat["closed_loop.python_loop_ms"],
                                                    flat["closed_loop.solve_ivp_ms"]))
    if "batch.generated_s" in flat:
        lines.append("batch {} runs (s): generated {:.3f}, numpy RK4 {:.3f}".format(
            flat["batch.n"], flat["batch.generated_s"], flat["batch.numpy_s"]))
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench", description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer repetitions (smoke test)")
    ap.add_argument("--skip-derive", action="store_true", help="skip the derive and gcc timings")
    ap.add_argument("--only", nargs="+", choices=("derive", "alpha_beta", "closed_loop", "batch"),
                    help="run only these sections")
    ap.add_argument("--out", type=Path, default=HERE / "results.json")
    args = ap.parse_args(argv)
    reps, slow = (1, 1) if args.quick else (5, 3)
    sections = set(args.only or ("derive", "alpha_beta", "closed_loop", "batch"))
    if args.skip_derive:
        sections.discard("derive")
    t_start = time.perf_counter()
    results = {"machine": {"python": platform.python_version(), "cpu_count": os.cpu_count(),
                           "platform": platform.platform(), "processor": platform.processor()}}
    with tempfile.TemporaryDirectory(prefix="fjm-bench-") as tmp:
        work = Path(tmp)
        os.environ.setdefault("FJM_CACHE", str(work / "cache"))  # cold, private compile cache
        plan = [("derive", lambda: bench_derive(work, 1 if args.quick else 3)),
                ("alpha_beta", lambda: bench_alpha_beta(work, reps)),
                ("closed_loop", lambda: bench_closed_loop(work, reps, slow)),
                ("batch", lambda: bench_batch(reps, slow))]
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
    flat = flatten({k: v for k, v in results.items() if k != "machine"})
    results["flat"] = flat
    args.out.write_text(json.dumps(results, indent=2, sort_keys=True) + "\n")
    print(table(flat))
    print(f"\nwrote {args.out} in {results['bench_seconds']:.0f} s")
    if failed:
        print(f"sections that failed: {', '.join(failed)} (see the traceback above)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
