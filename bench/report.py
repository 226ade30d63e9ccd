"""The measured numbers of README.md, docs/*.md and bench/README.md, written from ``bench/results.json``.

``python -m bench`` calls :func:`write_all` after a full run; by hand::

    .venv/bin/python -m bench.report            # rewrite every marked block from bench/results.json
    .venv/bin/python -m bench.report --docs     # the same (the name ``make bench`` documents)
    .venv/bin/python -m bench.report --check    # exit 1 if a block differs from the results

Two kinds of marked text are replaced, so the documentation cannot drift from the
results it quotes:

* the big tables, between ``<!-- bench:begin -->`` and ``<!-- bench:end -->``
  (docs/benchmarks.md and bench/README.md, see :func:`targets`);
* named blocks anywhere in README.md, docs/*.md and bench/README.md, between
  ``<!-- fjm:bench:NAME -->`` and ``<!-- /fjm:bench:NAME -->``; NAME is a key of
  :data:`bench.report_blocks.BLOCKS` (a number inside a sentence, or whole lines when the rendering
  has several). The values come from :mod:`bench.result_values`.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Dict, List, Optional, Sequence

from .report_blocks import render_named, scaling_lines
from .result_values import RESULTS, get, load, value_text as _f

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
README = REPO / "README.md"
BENCH_README = HERE / "README.md"
BENCHMARKS_DOC = REPO / "docs" / "benchmarks.md"
BEGIN, END = "<!-- bench:begin -->", "<!-- bench:end -->"

#: Targets: dotted key in the results, comparison, bound.
TARGETS = {
    "derive.total_seconds": ("<=", 20.0),
    "derive.planar7.seconds": ("<=", 10.0),
    "alpha_beta.planar7.ratio": ("<=", 0.7),
    "derive.planar7.c_bytes": ("<=", 0.5e6),
    "derive.planar7.gcc_seconds": ("<=", 5.0),
    "closed_loop.ratio_to_hand_c": ("<=", 1.5),
    "closed_loop.speedup_vs_python": (">=", 50.0),
    "batch.speedup_vs_numpy": (">=", 9.0),
    "batch.generated_s": ("<=", 0.3),
    "spatial.ratio": ("<=", 0.5),
    "design.cold_seconds": ("<=", 600.0),
    "design.warm_seconds": ("<=", 240.0),
    "design.compiler_peak_gb": ("<=", 1.5),
    "controller_step.design_substeps.step_p999_ns": ("<=", 50e3),
}


def target_met(results: dict, key: str) -> Optional[bool]:
    """Whether the measured ``key`` meets its target (``None``: not measured)."""
    v = get(results, key)
    if v is None:
        return None
    op, bound = TARGETS[key]
    return v <= bound if op == "<=" else v >= bound


def _status(results: dict, keys: Sequence[str]) -> str:
    met = [target_met(results, k) for k in keys]
    if any(m is None for m in met):
        return "not measured"
    return "met" if all(met) else "**missed**"


def _panda_rows(g) -> list:
    """The Panda's rows of :func:`main_table`: alpha + beta in one call, in two, under native flags, and their C."""
    return [
        ("alpha + beta compiled, Panda (7 joints), in one call (`control_core`)",
         "adam-robotics 0.5.0 (CasADi backend) on the same URDF, elastic model and Lie derivatives by "
         "CasADi AD (`jtimes`), T, alpha, beta in one Function, same codegen and flags",
         f"{g('spatial.generated_us', '.2f')} us", f"{g('spatial.peer_us', '.2f')} us",
         f"ratio {g('spatial.ratio', '.2f')}", "<= 0.5", ["spatial.ratio"]),
        ("same, as two calls (`alpha`, then `beta`)", "the peer's alpha and beta Functions",
         f"{g('spatial.two_calls.generated_us', '.2f')} us", f"{g('spatial.two_calls.peer_us', '.2f')} us",
         f"ratio {g('spatial.two_calls.ratio', '.2f')}", "-", []),
        ("same, one call, both compiled for this machine's CPU (`-O2 -march=native`); informative, every "
         "target above is at `-O2`", "the peer's core, same flags",
         f"{g('spatial.native.generated_us', '.2f')} us", f"{g('spatial.native.peer_us', '.2f')} us",
         f"ratio {g('spatial.native.ratio', '.2f')}", "-", []),
        ("C of alpha + beta, Panda", "the adam peer's C",
         f"{g('spatial.generated_c_bytes', '.0f', 1e-3)} kB, gcc -O2 {g('spatial.generated_gcc_seconds', '.1f')} s",
         f"{g('spatial.peer_c_bytes', '.0f', 1e-3)} kB, gcc -O2 {g('spatial.peer_gcc_seconds', '.1f')} s",
         "-", "-", []),
    ]


def main_table(r: dict) -> List[str]:
    """The comparison table shared by both READMEs (markdown lines)."""
    g = lambda k, f, s=1.0: _f(r, k, f, s)  # noqa: E731
    thr = get(r, "batch.threads")
    thr_s = "-" if thr is None else f"{int(thr)}"
    n_models = get(r, "derive.n_models")
    rows = [
        (f"`make derive`, all {'-' if n_models is None else int(n_models)} models", "-",
         f"{g('derive.total_seconds', '.1f')} s (planar7 {g('derive.planar7.seconds', '.2f')} s)", "-", "-",
         "<= 20 s, planar7 <= 10 s", ["derive.total_seconds", "derive.planar7.seconds"]),
        ("alpha + beta compiled, planar7, in one call (`control_core`, what every law calls)",
         "CasADi SX of the same dynamics, Lie derivatives by CasADi AD (`jtimes`), its T, alpha, beta CSE'd "
         "together in one Function, same codegen and flags",
         f"{g('alpha_beta.planar7.generated_us', '.3f')} us", f"{g('alpha_beta.planar7.peer_us', '.3f')} us",
         f"ratio {g('alpha_beta.planar7.ratio', '.2f')}", "<= 0.7", ["alpha_beta.planar7.ratio"]),
        ("same, as two calls (`alpha`, then `beta`)", "the peer's alpha and beta Functions",
         f"{g('alpha_beta.planar7.two_calls.generated_us', '.3f')} us",
         f"{g('alpha_beta.planar7.two_calls.peer_us', '.3f')} us",
         f"ratio {g('alpha_beta.planar7.two_calls.ratio', '.2f')}", "-", []),
        ("generated C, planar7", "-",
         f"{g('derive.planar7.c_bytes', '.0f', 1e-3)} kB, gcc -O2 {g('derive.planar7.gcc_seconds', '.1f')} s",
         "-", "-", "<= 0.5 MB, <= 5 s", ["derive.planar7.c_bytes", "derive.planar7.gcc_seconds"]),
        ("`python -m derive` of the 7-joint Panda (URDF), inside `make derive`", "-",
         f"{g('derive.panda.seconds', '.1f')} s (symbolic {g('derive.panda.derive_seconds', '.1f')} s, emit "
         f"{g('derive.panda.emit_seconds', '.1f')} s), {g('derive.panda.ops', '.0f')} operations", "-", "-", "-", []),
        *_panda_rows(g),
        ("closed loop link1, 10 s at 1 kHz, RK4 + SMC: the bare compiled loop (outputs preallocated)",
         "hand-written C of the same loop (`bench/hand_loop.c`, -O2)",
         f"{g('closed_loop.generated_ms', '.2f')} ms", f"{g('closed_loop.hand_c_ms', '.2f')} ms",
         f"ratio {g('closed_loop.ratio_to_hand_c', '.2f')}", "<= 1.5", ["closed_loop.ratio_to_hand_c"]),
        ("same case, the whole `simulate()` call (reference sampling, outputs, metrics), "
         '`backend="compiled"`',
         'the same call with `backend="python"` (NumPy RK4 calling the CasADi Functions)',
         f"{g('closed_loop.simulate_compiled_ms', '.1f')} ms", f"{g('closed_loop.simulate_python_ms', '.2f', 1e-3)} s",
         f"{g('closed_loop.speedup_vs_python', '.0f')}x faster", ">= 50x", ["closed_loop.speedup_vs_python"]),
        ("same call", "scipy `solve_ivp` RK45 of the same loop (law at every RHS call; context)",
         f"{g('closed_loop.simulate_compiled_ms', '.1f')} ms", f"{g('closed_loop.solve_ivp_ms', '.2f', 1e-3)} s",
         f"{g('closed_loop.solve_ivp_over_simulate_compiled', '.0f')}x faster", "-", []),
        ("batch: 1000 closed loops, K ~ U[100, 200], 10 s each, **1 thread**",
         "NumPy RK4 vectorized over the batch (1 thread), computing the same figures (`bench/numpy_batch.py`: "
         "metrics, divergence check every sample, per-joint peak torque and torque jitter)",
         f"{g('batch.generated_1thread_s', '.3f')} s", f"{g('batch.numpy_s', '.2f')} s",
         f"{g('batch.speedup_vs_numpy', '.1f')}x faster", ">= 9x", ["batch.speedup_vs_numpy"]),
        (f"same batch, **{thr_s} threads** (OpenMP)", "the same NumPy run (1 thread)",
         f"{g('batch.generated_s', '.3f')} s", f"{g('batch.numpy_s', '.2f')} s",
         f"{g('batch.speedup_vs_numpy_all_threads', '.1f')}x in total, "
         f"{g('batch.speedup_per_core_all_threads', '.1f')}x per core", "<= 0.3 s", ["batch.generated_s"]),
        ("`fjm design panda --rate 1000 --delay-samples 2 --predict --noise franka_like --rounds 3` (`--law auto`), "
         "empty C cache, then warm (2 cores)", "-",
         f"cold {g('design.cold_seconds', '.0f')} s, warm {g('design.warm_seconds', '.0f')} s; largest compiler "
         f"process {g('design.compiler_peak_gb', '.2f')} GB", "-", "-", "<= 600 s, <= 240 s, <= 1.5 GB",
         ["design.cold_seconds", "design.warm_seconds", "design.compiler_peak_gb"]),
        ("the Panda design's controller step, exported C library (`fjm export controller`), 1e5 steps timed in "
         "the closed loop (the design's recorded predictor substeps)", "-",
         f"median {g('controller_step.design_substeps.step_median_ns', '.1f', 1e-3)} us, 99.9th percentile "
         f"{g('controller_step.design_substeps.step_p999_ns', '.1f', 1e-3)} us, worst "
         f"{g('controller_step.design_substeps.step_max_ns', '.0f', 1e-3)} us", "-",
         f"2 predictor substeps: 99.9th percentile {g('controller_step.substeps_2.step_p999_ns', '.1f', 1e-3)} us",
         "99.9th percentile <= 50 us", ["controller_step.design_substeps.step_p999_ns"]),
    ]
    lines = ["| metric | peer, measured in the same run | fjm | peer | fjm vs peer | target | |",
             "|---|---|---|---|---|---|---|"]
    for label, peer, fjm, pv, cmp, target, keys in rows:
        lines.append(f"| {label} | {peer} | {fjm} | {pv} | {cmp} | {target} | "
                     f"{_status(r, keys) if keys else ''} |")
    return lines


def machine_line(r: dict) -> str:
    m = r.get("machine", {})
    load = m.get("load_average_start")
    load_s = f"{load:.1f}" if isinstance(load, (int, float)) and math.isfinite(load) else "?"
    when = r.get("finished_utc", "?")
    quick = ", `--quick`" if r.get("quick") else ""
    return (f"Run finished {when}{quick}: {m.get('cpu_count', '?')}-core {m.get('cpu_model', '?')} "
            f"({m.get('simd_isa', '?')}; batch path `{r.get('batch', {}).get('path', '?')}`), "
            f"load average {load_s} at the start, shared machine.")


def checks_line(r: dict) -> str:
    checks = r.get("checks", [])
    bad = [c for c in checks if not c.get("ok")]
    if not checks:
        return "No peer checks were run."
    if bad:
        return (f"**{len(bad)} of {len(checks)} peer checks failed** "
                f"({', '.join(c['key'] for c in bad)}): the timings above compare unequal code.")
    return (f"All {len(checks)} peer checks passed: every peer computed the same numbers as the "
            f"generated code in this run, within the stated tolerances.")


def _ab_line(r: dict) -> str:
    parts = []
    for m in ("link1", "planar2", "planar4", "planar7"):
        if get(r, f"alpha_beta.{m}.generated_us") is not None:
            parts.append(f"{m} {_f(r, f'alpha_beta.{m}.generated_us', '.3f')} / "
                         f"{_f(r, f'alpha_beta.{m}.peer_us', '.3f')}")
    return "alpha + beta in one call of a core (generated / AD peer, us): " + ", ".join(parts) + "."


def _spatial_line(r: dict) -> str:
    if get(r, "spatial.generated_us") is None:
        return ""
    g = lambda k, f, s=1.0: _f(r, k, f, s)  # noqa: E731
    return (f"Panda: operations after CSE, generated alpha {g('spatial.generated_ops.alpha', '.0f')} + beta "
            f"{g('spatial.generated_ops.beta', '.0f')} (in one call, `control_core`: "
            f"{g('spatial.generated_ops.core', '.0f')}), adam peer alpha {g('spatial.peer_ops.alpha', '.0f')} + beta "
            f"{g('spatial.peer_ops.beta', '.0f')} (its core: {g('spatial.peer_ops.core', '.0f')}; peer built in "
            f"{g('spatial.peer_build_seconds', '.1f')} s); "
            f"the shipped `panda.c` (every function it ships, the emitted control laws included) is {g('spatial.generated_c_bytes_all', '.0f', 1e-3)} kB, "
            f"gcc -O2 {g('spatial.generated_gcc_seconds_all', '.1f')} s; the C sizes above are alpha and beta "
            f"alone, code-generated from the shipped `.casadi` Functions with the same options. Parameters: "
            f"the defaults with `m_load = 0` (adam has no payload; gravity baked at g0).")


def _ops_line(r: dict) -> str:
    by = r.get("derive", {}).get("ops_growth_exponent_by_function", {})
    tot = get(r, "derive.ops_growth_exponent_planar")
    if not by or tot is None:
        return ""
    per = ", ".join(f"{q} {v:.1f}" for q, v in sorted(by.items()))
    ops = get(r, "derive.planar7.ops")
    return (f"Operation counts after CSE grow polynomially with the number of links: least-squares "
            f"slope of log(ops) vs log(n) over planar3..7 is {tot:.1f} in total ({per}); "
            f"planar7 has {ops:.0f} operations.")


def render_readme(r: dict) -> str:
    """The block of README.md's "Performance" section."""
    lines = [machine_line(r), "", *main_table(r), "", checks_line(r), "", _ab_line(r)]
    if _spatial_line(r):
        lines += ["", _spatial_line(r)]
    ops = _ops_line(r)
    if ops:
        lines += ["", ops]
    return "\n".join(lines) + "\n"


def render_bench_readme(r: dict) -> str:
    """The block of bench/README.md's "Latest run" section (table, context, peer checks)."""
    g = lambda k, f, s=1.0: _f(r, k, f, s)  # noqa: E731
    lines = [machine_line(r), "", *main_table(r), "", _ab_line(r), "",
             f"Context: the bare compiled loop takes {g('closed_loop.generated_ms', '.2f')} ms of the "
             f"{g('closed_loop.simulate_compiled_ms', '.1f')} ms `simulate()` call; the same step as a CasADi "
             f"`mapaccum` through `casadi.external` {g('closed_loop.generated_mapaccum_external_ms', '.1f')} ms. "
             f"Batch on 1 thread: scalar C loop {g('batch.generated_scalar_1thread_s', '.3f')} s, SIMD "
             f"{g('batch.generated_1thread_s', '.3f')} s ({g('batch.simd_over_scalar_1thread', '.1f')}x); "
             f"controller k_s = {g('closed_loop.k_s', '.1f')}, delta = {g('closed_loop.delta', '.3f')}, "
             f"beta_hat = {g('closed_loop.beta_hat', '.4f')} (computed by `fjm_runtime.experiments.paper.Design`).",
             ]
    if _spatial_line(r):
        lines += ["", _spatial_line(r)]
    ops = _ops_line(r)
    if ops:
        lines += ["", ops]
    lines += ["", checks_line(r), "", "| peer check | measured | tolerance | |", "|---|---|---|---|"]
    for c in r.get("checks", []):
        lines.append(f"| {c['what']} | {c['measured']:.2g} | {c['tolerance']:.0g} | "
                     f"{'ok' if c['ok'] else '**FAILED**'} |")
    return "\n".join(lines) + "\n"


def replace_block(text: str, block: str, name: str = "file") -> str:
    """``text`` with the lines between the two markers replaced by ``block``."""
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(BEGIN) > text.index(END):
        raise ValueError(f"{name}: expected one {BEGIN} followed by one {END}")
    a = text.index(BEGIN) + len(BEGIN)
    b = text.index(END)
    return text[:a] + "\n" + block + text[b:]


def current_block(text: str) -> str:
    """The text between the markers (as :func:`replace_block` writes it)."""
    a = text.index(BEGIN) + len(BEGIN)
    return text[a:text.index(END)].lstrip("\n")


def targets(r: dict) -> Dict[Path, str]:
    """The files with a ``bench:begin`` / ``bench:end`` table and the block each must hold."""
    return {BENCHMARKS_DOC: render_readme(r), BENCH_README: render_bench_readme(r)}


def doc_files() -> List[Path]:
    """The files whose named blocks :func:`render_docs` rewrites."""
    return [README, *sorted((REPO / "docs").glob("*.md")), BENCH_README]


def render_file(path: Path, r: dict) -> str:
    """The whole text ``path`` must hold: its tables and named blocks rendered from ``r``."""
    text = path.read_text(encoding="utf-8")
    block = targets(r).get(path)
    if block is not None:
        text = replace_block(text, block, str(path))
    return render_named(text, r, str(path))


def stale_files(r: dict) -> List[Path]:
    """The files whose marked text differs from what the results ``r`` render to."""
    files = list(dict.fromkeys([*targets(r), *doc_files()]))
    return [p for p in files if p.is_file() and render_file(p, r) != p.read_text(encoding="utf-8")]


def write_all(r: dict, files: Optional[Dict[Path, str]] = None) -> List[Path]:
    """Rewrite every marked table and named block from the results ``r``; returns the files that changed."""
    changed = []
    if files is not None:
        for path, block in files.items():
            old = path.read_text()
            new = replace_block(old, block, str(path))
            if new != old:
                path.write_text(new)
                changed.append(path)
        return changed
    for path in dict.fromkeys([*targets(r), *doc_files()]):
        if not path.is_file():
            continue
        old = path.read_text(encoding="utf-8")
        new = render_file(path, r)
        if new != old:
            path.write_text(new, encoding="utf-8")
            changed.append(path)
    return changed


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.report", description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if a marked block differs from the results")
    ap.add_argument("--docs", action="store_true",
                    help="rewrite every marked block of README.md, docs/*.md, bench/README.md (the default action)")
    ap.add_argument("--results", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    r = load(args.results)
    if args.check:
        stale = stale_files(r)
        for p in stale:
            print(f"{p}: a marked block differs from {args.results}: run python -m bench.report --docs",
                  file=sys.stderr)
        return 1 if stale else 0
    for p in write_all(r):
        print(f"rewrote {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
