"""The named blocks of README.md, docs/*.md and bench/README.md: ``<!-- fjm:bench:NAME -->`` ... ``<!-- /fjm:bench:NAME -->``.

A block quotes a number of ``bench/results.json`` inside a sentence, or whole lines (a table);
:data:`BLOCKS` maps each NAME to its renderer and :func:`render_named` re-renders every block
of a text (:mod:`bench.report` writes the files).
"""
from __future__ import annotations

import math
import re
from typing import List, Optional

from .result_values import get, value_text as _f

__all__ = ["BLOCKS", "NAMED", "render_named", "scaling_lines"]

GCC_SHOWN = "300 (stopped)"  # bench.scaling.GCC_TIMEOUT, as the table shows a gcc run cut short


def scaling_lines(r: dict) -> List[str]:
    """The scaling section's table (synthetic chains, fitted exponents) and its targets; [] if not run."""
    sc = r.get("scaling")
    if not isinstance(sc, dict) or "runs" not in sc:
        return []
    cols = (("derive_seconds", "derive (s)", lambda v: f"{v:.1f}"),
            ("peak_bytes", "peak memory (MB)", lambda v: f"{v / 1e6:.0f}"),
            ("alpha_beta_ops", "alpha + beta ops, one call", lambda v: f"{v:.0f}"),
            ("alpha_plus_beta_ops", "alpha ops + beta ops", lambda v: f"{v:.0f}"),
            ("ad_ops", "ad ops", lambda v: f"{v:.0f}"),
            ("all_ops", "all functions ops", lambda v: f"{v:.0f}"),
            ("c_bytes", "C (MB)", lambda v: f"{v / 1e6:.2f}"),
            ("gcc_seconds", "gcc -O2 (s)", lambda v: f"{v:.1f}"))
    out = ["| joints | " + " | ".join(c[1] for c in cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for run in sc["runs"]:
        out.append(f"| {run['n']} | " + " | ".join(
            (f"> {GCC_SHOWN}" if k == "gcc_seconds" and run.get("gcc_timed_out") else "-")
            if run.get(k) is None else fmt(run[k]) for k, _, fmt in cols) + " |")
    fits = sc.get("fits", {})
    out.append("| fitted exponent e (c n^e) | " + " | ".join(
        f"{fits[k]['e']:.2f}" if k in fits else "-" for k, _, _ in cols) + " |")
    out += ["", "| target | limit | measured | |", "|---|---|---|---|"]
    for t in sc.get("targets", []):
        v = t["measured"]
        shown = "-" if v is None else (f"{v:.3g}" if isinstance(v, (int, float)) else str(v))
        out.append(f"| {t['what']} | {t['limit']:.3g} | {shown} | "
                   f"{'-' if t['ok'] is None else ('met' if t['ok'] else '**missed**')} |")
    return out


NAMED = re.compile(r"<!-- fjm:bench:([a-z0-9-]+) -->(.*?)<!-- /fjm:bench:\1 -->", re.S)


def _ns(v: Optional[float]) -> str:
    """A duration in nanoseconds, in the unit that reads best (``81 ns``, ``3.8 us``, ``2.0 ms``)."""
    if v is None:
        return "-"
    if v < 1e3:
        return f"{v:.0f} ns"
    if v < 1e6:
        return f"{v * 1e-3:.3g} us"
    return f"{v * 1e-6:.3g} ms"


def _seconds(key: str, fmt: str = ".1f"):
    return lambda r: f"{_f(r, key, fmt)} s"


def _realtime(r: dict) -> str:
    """The fixed-rate controller's step times and float-vs-double deviation (examples/c/realtime.c)."""
    rt = r.get("realtime") or {}
    if not rt:
        return "not measured in this run"
    g = lambda k: get(r, "realtime." + k)  # noqa: E731
    steps = g("steps")
    return (f"{'-' if steps is None else f'{steps:.0e}'.replace('e+0', 'e')} steps inside the closed loop, "
            f"gcc -O2: median step {_ns(g('link1.double.step_median_ns'))} (link1, 1 kHz) and "
            f"{_ns(g('panda.double.step_median_ns'))} (panda, the torque-sensed law `control_ismc_tau` at "
            f"{_f(r, 'realtime.panda.double.rate_hz', '.0f')} Hz), "
            f"{_f(r, 'realtime.link1.double.ratio_median', '.2f')}x and "
            f"{_f(r, 'realtime.panda.double.ratio_median', '.2f')}x one `alpha` + `beta` call of the same model; "
            f"99.9th percentile {_ns(g('link1.double.step_p999_ns'))} and {_ns(g('panda.double.step_p999_ns'))} "
            f"(panda's period: {_ns(g('panda.double.period_ns'))}); worst case {_ns(g('link1.double.step_max_ns'))} "
            f"and {_ns(g('panda.double.step_max_ns'))} (the OS preempting the process on a shared machine). "
            f"Float vs double over the same 10 s closed loop: max |du| / max |u| = "
            f"{_f(r, 'realtime.link1.float_vs_double_u_relative', '.1e')} (link1), "
            f"{_f(r, 'realtime.panda.float_vs_double_u_relative', '.1e')} (panda: max |du| = "
            f"{_f(r, 'realtime.panda.float_vs_double_u_max_abs', '.2g')} N m)")


def _summary(r: dict) -> str:
    """The README's few headline numbers (the full table is in docs/benchmarks.md)."""
    g = lambda k, f, s=1.0: _f(r, k, f, s)  # noqa: E731
    n = get(r, "derive.n_models")
    rows = [
        ("| what | measured |", "|---|---|"),
        (f"| `make derive`, all {'-' if n is None else int(n)} models | {g('derive.total_seconds', '.1f')} s "
         f"(Panda {g('derive.panda.seconds', '.1f')} s, planar7 {g('derive.planar7.seconds', '.1f')} s) |",),
        (f"| `alpha` + `beta` in one call, compiled, planar7 / Panda | {g('alpha_beta.planar7.generated_us', '.2f')} us / "
         f"{g('spatial.generated_us', '.2f')} us per call ({g('alpha_beta.planar7.ratio', '.2f')}x / "
         f"{g('spatial.ratio', '.2f')}x the time of CasADi AD of the same model) |",),
        (f"| link1, 10 s at 1 kHz, `simulate(backend=\"compiled\")` | {g('closed_loop.simulate_compiled_ms', '.1f')} ms "
         f"({g('closed_loop.speedup_vs_python', '.0f')}x the NumPy loop) |",),
        (f"| 1000 closed loops of link1 (`simulate_batch`, {int(get(r, 'batch.threads') or 0)} threads) | "
         f"{g('batch.generated_s', '.2f')} s |",),
    ]
    return "\n".join(line for row in rows for line in row) + "\n"


def _sl_num(v, fmt: str = ".2g") -> str:
    return "-" if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) else format(v, fmt)


def _substeps(r: dict) -> str:
    """The substeps rule against a 10x finer plant (:mod:`bench.sampled_loop`), a markdown table."""
    sub = (r.get("sampled_loop") or {}).get("substeps") or {}
    if not sub:
        return "(not measured yet: run make bench)"
    what = {"panda": "Panda, ismc (lambda 80, k_lin 400, k_s 2000, delta 10), the demo's ready-pose sines from rest",
            "link1": "link1, ismc (lambda 8, k_s 1000, delta 5), 0.5 rad sine at 1 rad/s"}
    lines = ["| case, 10 s at 1 kHz, noise-free, compiled | omega_max (rad/s) | default substeps | "
             "max abs(q - q_10x) (rad) | max abs(x - x_10x) |", "|---|---|---|---|---|"]
    for name, c in sorted(sub.items()):       # key order: results.json is written sorted
        lines.append(f"| {what.get(name, name)} | {_sl_num(c.get('omega_max'), '.0f')} | {c.get('substeps', '-')} | "
                     f"{_sl_num(c.get('max_abs_q_diff'))} | {_sl_num(c.get('max_abs_state_diff'))} |")
    return "\n".join(lines) + "\n"


def _delay_cell(c: dict) -> str:
    if not c:
        return "-"
    if c.get("diverged"):
        return f"diverged at t = {_sl_num(c.get('diverged_at_s'), '.3f')} s"
    return f"{_sl_num(c.get('rms_worst'), '.2e')} (joint {c.get('worst_joint', '?')})"


def _delay_prediction(r: dict) -> str:
    """Worst-joint second-half RMS with a one-sample delay, without / with prediction, a markdown table."""
    dp = (r.get("sampled_loop") or {}).get("delay_prediction") or {}
    if not dp:
        return "(not measured yet: run make bench)"
    lines = ["| sensing | TRUE stiffness | RMS, no prediction (rad) | RMS, `predict=True` (rad) |",
             "|---|---|---|---|"]
    for sensing, cases in sorted(dp.items()):
        for label, c in sorted(cases.items()):
            lines.append(f"| {sensing} | {'exact' if label == 'exact' else 'all joints ' + label} | "
                         f"{_delay_cell(c.get('plain') or {})} | {_delay_cell(c.get('predict') or {})} |")
    return "\n".join(lines) + "\n"


#: name -> renderer of a named block (``str``; several lines make a block of whole lines).
BLOCKS = {
    "run": lambda r: f"{r.get('finished_utc', '?')}" + (" (`--quick`)" if r.get("quick") else ""),
    "summary": _summary,
    "derive-time": _seconds("derive.total_seconds"),
    "derive-n-models": lambda r: _f(r, "derive.n_models", ".0f"),
    "planar7-derive-time": _seconds("derive.planar7.seconds"),
    "elbow3-derive-time": _seconds("derive.elbow3.seconds"),
    "elbow3-ops": lambda r: _f(r, "derive.elbow3.ops", ".0f"),
    "panda-derive-time": lambda r: (f"{_f(r, 'derive.panda.seconds', '.1f')} s (symbolic "
                                    f"{_f(r, 'derive.panda.derive_seconds', '.1f')} s, emission "
                                    f"{_f(r, 'derive.panda.emit_seconds', '.1f')} s)"),
    "panda-ops": lambda r: (f"{_f(r, 'derive.panda.ops', '.0f')} operations (" + ", ".join(
        f"{q} {_f(r, f'derive.panda.ops_by_function.{q}', '.0f')}"
        for q in ("f", "ad", "T", "alpha", "beta", "energy", "inertia")) + ")"),
    "panda-alpha-ops": lambda r: _f(r, "derive.panda.ops_by_function.alpha", ".0f"),
    "elbow3-alpha-ops": lambda r: _f(r, "derive.elbow3.ops_by_function.alpha", ".0f"),
    "panda-alpha-beta": lambda r: (f"{_f(r, 'spatial.generated_us', '.2f')} us against "
                                   f"{_f(r, 'spatial.peer_us', '.2f')} us (ratio {_f(r, 'spatial.ratio', '.2f')})"),
    "realtime": _realtime,
    "scaling": lambda r: "\n".join(scaling_lines(r)) + "\n" if scaling_lines(r) else "(not measured yet: run make bench)",
    "bench-seconds": lambda r: f"{_f(r, 'bench_seconds', '.0f')} s",
    "substeps": _substeps,
    "delay-prediction": _delay_prediction,
}


def render_named(text: str, r: dict, name: str = "file") -> str:
    """``text`` with every named block re-rendered from the results ``r``.

    Raises ``ValueError`` for a block name that :data:`BLOCKS` does not know.
    """
    def one(m: "re.Match[str]") -> str:
        key = m.group(1)
        if key not in BLOCKS:
            raise ValueError(f"{name}: unknown block <!-- fjm:bench:{key} --> (known: {', '.join(sorted(BLOCKS))})")
        value = BLOCKS[key](r)
        body = "\n" + value.rstrip("\n") + "\n" if "\n" in value.rstrip("\n") or m.group(2).startswith("\n") \
            else value
        return f"<!-- fjm:bench:{key} -->{body}<!-- /fjm:bench:{key} -->"
    return NAMED.sub(one, text)
