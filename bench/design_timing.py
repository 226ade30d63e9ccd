"""``fjm design`` on the Panda at 1 kHz, delay 2, the ``franka_like`` sensor: wall time and compiler memory;
the Monte Carlo throughput in this process and on a 2-worker dask cluster.

The issue's targets: within 10 minutes on a cold C cache and 4 minutes warm (2 cores), no compiler
process above 1.5 GB resident. The command runs twice as a user runs it (``python -m fjm_runtime.cli
design ...``, a process of its own): first with an empty ``$FJM_CACHE`` (every C build of the
search, the final check and the delay margins up to ``d + 3``), then again with that cache (warm).
Every compiler process is started through a wrapper (``$CC``) that records its peak resident set
(:mod:`bench.peak_rss`), so the compiler's memory is measured apart from the design process's own.

Throughput (:func:`bench_draws`): the same rows (Panda, shipped 1 kHz / d = 1 gains, ``panda_white``,
10 s runs) through ``simulate_batch`` on this process's 2 threads and through
:func:`fjm_runtime.batch.distributed.run_on_cluster` on a ``LocalCluster`` of 2 worker processes of
one thread each (the same compiled library, loaded by each worker); draws per wall second, the
cluster's start excluded, the per-run metrics checked equal.
"""
from __future__ import annotations

import json
import os
import stat
import sys
from pathlib import Path

from .scaling import HERE, run_measured

REPO = HERE.parent
#: The command of the shipped 1 kHz / delay-2 Panda design (panda_impedance_1000hz_d2.json), --law auto.
ARGS = ["panda", "--rate", "1000", "--delay-samples", "2", "--predict", "--noise", "franka_like", "--rounds", "3"]
TARGETS = {"cold_seconds": 600.0, "warm_seconds": 240.0, "compiler_peak_gb": 1.5}


def _compiler_wrapper(work: Path) -> Path:
    """A ``$CC`` that runs gcc under :mod:`bench.peak_rss`, one peak file per compiler process."""
    peaks = work / "cc-peaks"
    peaks.mkdir(parents=True, exist_ok=True)
    gcc = os.environ.get("CC") or "gcc"
    script = work / "cc"
    script.write_text("#!/bin/sh\n"
                      f'exec "{sys.executable}" -S "{HERE / "peak_rss.py"}" "{peaks}/$$.peak" "{gcc}" "$@"\n')
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return script


def _compiler_peak(work: Path) -> float:
    files = list((work / "cc-peaks").glob("*.peak"))
    return max((int(f.read_text()) for f in files), default=0) / 1e9


def bench_draws(draws: int = 16, duration: float = 10.0) -> dict:
    """Draws per second locally (2 threads) and on 2 dask workers, same rows; the results equal."""
    import time

    import numpy as np

    import fjm_runtime
    from fjm_runtime.batch.distributed import LoopSpec, batch_substeps, client_for, run_on_cluster
    from fjm_runtime.batch.runner import BatchResult, simulate_batch
    from fjm_runtime.cli.design import demo_task
    from fjm_runtime.control.design import Design
    from fjm_runtime.control.factory import make_controller
    from fjm_runtime.analysis.search.draws import draw_params
    from fjm_runtime.sim.sensor import SensorModel
    m = fjm_runtime.load("panda")
    gains = Design.shipped("panda", "ismc", "torque", 1000, 1).gains
    ctrl = make_controller("ismc", m, {}, sensing="torque", **gains)
    task = demo_task(m)
    P = draw_params(m, draws, 0)
    seeds = np.arange(draws, dtype=np.uint64)
    subs = batch_substeps(m, task["x0"], P, 1e-3)
    sensor = SensorModel.panda_white()
    kw = dict(duration=duration, sensor=sensor, delay_samples=1, predict=True, seeds=seeds, substeps=subs,
              x0=task["x0"])
    simulate_batch(m, ctrl, task["reference"], P[:1], **{**kw, "seeds": seeds[:1], "duration": 0.01})  # build
    t0 = time.perf_counter()
    local = simulate_batch(m, ctrl, task["reference"], P, threads=2, **kw)
    t_local = time.perf_counter() - t0
    spec = LoopSpec(model=str(m.directory), model_name=m.name, kind="ismc", sensing="torque",
                    nominal={}, options=dict(gains), reference=task["reference"], duration=duration, dt=1e-3,
                    substeps=subs, sensor=sensor, delay=1, predict=True, x0=tuple(task["x0"]), simd=True)
    with client_for(None, n_workers=2, processes=True) as client:
        run_on_cluster(client, spec, P[:2], seeds[:2], None, BatchResult)          # workers build / load once
        t0 = time.perf_counter()
        dist = run_on_cluster(client, spec, P, seeds, None, BatchResult)
        t_dist = time.perf_counter() - t0
    same = all(np.array_equal(local.joint_metrics[k], dist.joint_metrics[k], equal_nan=True)
               for k in local.joint_metrics)
    return {"draws": draws, "duration_s": duration, "local_2threads_draws_per_s": draws / t_local,
            "cluster_2workers_draws_per_s": draws / t_dist, "identical": bool(same)}


def bench_design(work: Path, log=print) -> dict:
    """Run ``fjm design`` cold then warm; the section's results (seconds, peaks, outcome, targets)."""
    work.mkdir(parents=True, exist_ok=True)
    cc = _compiler_wrapper(work)
    env = dict(os.environ, FJM_CACHE=str(work / "cache"), CC=str(cc))
    out: dict = {"command": "fjm design " + " ".join(ARGS), "targets": dict(TARGETS)}
    for label in ("cold", "warm"):
        for f in (work / "cc-peaks").glob("*.peak"):
            f.unlink()
        gains = work / f"design-{label}.json"
        log(f"design: {label} run of fjm design {' '.join(ARGS)}")
        r = run_measured([sys.executable, "-m", "fjm_runtime.cli", "design", *ARGS, "--out", str(gains)], REPO, env)
        out[f"{label}_seconds"] = r["seconds"]
        out[f"{label}_process_peak_gb"] = (r["peak_bytes"] or 0) / 1e9
        out[f"{label}_compiler_peak_gb"] = _compiler_peak(work)
        out[f"{label}_compiler_processes"] = len(list((work / "cc-peaks").glob("*.peak")))
        out[f"{label}_returncode"] = r["returncode"]
        if gains.exists():
            spec = json.loads(gains.read_text())
            out[f"{label}_meets"] = spec.get("meets")
            out[f"{label}_misses"] = spec.get("misses")
            out[f"{label}_laws"] = [{k: r.get(k) for k in ("law", "meets", "rms", "compared", "seconds")}
                                    for r in spec.get("comparison", [])]
        else:
            out[f"{label}_error"] = r["stderr"][-2000:]
    out["compiler_peak_gb"] = max(out["cold_compiler_peak_gb"], out["warm_compiler_peak_gb"])
    log("design: draws per second, locally and on 2 dask workers")
    out["throughput"] = bench_draws()
    out["met"] = {"cold_seconds": out["cold_seconds"] <= TARGETS["cold_seconds"],
                  "warm_seconds": out["warm_seconds"] <= TARGETS["warm_seconds"],
                  "compiler_peak_gb": out["compiler_peak_gb"] <= TARGETS["compiler_peak_gb"]}
    return out
