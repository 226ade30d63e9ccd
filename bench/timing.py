"""Timing helpers of ``python -m bench``: the progress log, medians, alternation of peers."""
from __future__ import annotations

import statistics
import sys
import time

__all__ = ["alternate", "log", "median_time"]


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
