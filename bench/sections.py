"""The section table of ``python -m bench``: every section's name, in run order, and what it runs.

:data:`SECTIONS` is what ``--only`` accepts; :func:`plan` binds each section to the run's work
directory, repetitions and ``checks`` list. A section returns its ``results.json`` entry (a dict,
under its name) and appends its peer comparisons to ``checks``.
"""
from __future__ import annotations

from pathlib import Path

from .checks import check
from .derive_timing import bench_derive
from .kernel_sections import bench_alpha_beta, bench_spatial
from .loop_sections import bench_batch, bench_closed_loop
from .realtime import bench_realtime
from .timing import log

__all__ = ["SECTIONS", "plan"]

SECTIONS = ("derive", "alpha_beta", "spatial", "closed_loop", "batch", "realtime", "controller_step", "sampled_batch",
            "scaling", "sampled_loop", "design")


def controller_step_section(work: Path, steps: int) -> dict:
    """The exported controller library's step (:mod:`bench.controller_step`): the Panda design, timed in C."""
    from .controller_step import bench_controller_step
    return bench_controller_step(work, steps)


def sampled_batch_section(checks: list) -> dict:
    """The sampled-data batch throughput section (:mod:`bench.sampled_batch`)."""
    from .sampled_batch import bench_sampled_batch
    return bench_sampled_batch(checks)


def sampled_loop_section() -> dict:
    """The sampled-data loop section (:mod:`bench.sampled_loop`): substeps and delay prediction."""
    from .sampled_loop import bench_sampled_loop
    return bench_sampled_loop(log=log)


def scaling_section(work: Path, results: dict) -> dict:
    """The scaling section (:mod:`bench.scaling`): synthetic chains of 7..30 joints, fitted growth."""
    from .scaling import bench_scaling
    spatial = results.get("spatial")
    return bench_scaling(work / "scaling", spatial=spatial if isinstance(spatial, dict) else None, log=log)


def design_section(work: Path) -> dict:
    """The design section (:mod:`bench.design_timing`): ``fjm design`` on the Panda, cold and warm."""
    from .design_timing import bench_design
    return bench_design(work / "design", log=log)


def plan(work: Path, quick: bool, checks: list, results: dict) -> list:
    """``[(name, run)]`` in :data:`SECTIONS` order; ``run()`` returns the section's results.

    ``quick``: one repetition per figure (derive once, 10^4 realtime steps); else 5 (3 for the slow
    figures, the derive runs and the Python loop).
    """
    reps, slow = (1, 1) if quick else (5, 3)
    return [("derive", lambda: bench_derive(work, 1 if quick else 3, checks)),
            ("alpha_beta", lambda: bench_alpha_beta(work, reps, checks)),
            ("spatial", lambda: bench_spatial(work, reps, checks)),
            ("closed_loop", lambda: bench_closed_loop(work, reps, slow, checks)),
            ("batch", lambda: bench_batch(reps, slow, checks)),
            ("realtime", lambda: bench_realtime(work, 10 ** 4 if quick else 10 ** 6, checks, check)),
            ("controller_step", lambda: controller_step_section(work, 10 ** 4 if quick else 10 ** 5)),
            ("sampled_batch", lambda: sampled_batch_section(checks)),
            ("scaling", lambda: scaling_section(work, results)),
            ("sampled_loop", lambda: sampled_loop_section()),
            ("design", lambda: design_section(work))]
