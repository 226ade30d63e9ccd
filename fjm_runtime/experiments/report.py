"""Markdown pieces of the demo summary: number formatting, metric rows, the divergence marker, progress."""
from __future__ import annotations

import sys
from typing import List, Optional, Sequence

import numpy as np

METRIC_HEADER = ("final abs(e1) (rad) | RMS e1 (rad) | RMS e1, 2nd half (rad) | max abs(u) (N m) | "
                 "reaching time (s) | TV(u) (N m)")
#: Number of cells of :data:`METRIC_HEADER` (a diverged row fills them with the marker and blanks).
METRIC_CELLS = 6


def log(msg: str) -> None:
    """Print one progress line on stderr (the default ``progress`` of the demo)."""
    print(msg, file=sys.stderr, flush=True)


def fmt(v: Optional[float], digits: int = 3) -> str:
    """A metric as a table cell: ``digits`` significant digits, ``'not reached'`` for inf, ``'-'`` for NaN/None."""
    if v is None or not np.isfinite(v):
        return "not reached" if v == np.inf else "-"
    return f"{v:.{digits}g}" if abs(v) >= 1e-3 or v == 0 else f"{v:.2e}"


def fmt_vec(a) -> str:
    """Comma-separated values with 4 significant digits (a scalar or a vector of shape (n,))."""
    a = np.atleast_1d(np.asarray(a, dtype=float))
    return ", ".join(f"{v:.4g}" for v in a)


def diverged_marker(t: float, why: str = "") -> str:
    """The one way every table says a run diverged: ``'diverged at t = 1.234 s'`` (plus ``why``)."""
    return f"diverged at t = {t:.3f} s" + (f" ({why})" if why else "")


def row(cells: Sequence[str]) -> str:
    """One Markdown table row from its cells."""
    return "| " + " | ".join(cells) + " |"


def diverged_row(label: List[str], t: float, why: str = "", cells: int = METRIC_CELLS) -> str:
    """A table row for a diverged run: the ``label`` cells, the marker, then blanks up to ``cells`` metric cells."""
    return row(list(label) + [diverged_marker(t, why)] + [""] * (cells - 1))


def metrics_row(label: List[str], r) -> str:
    """A table row: the ``label`` cells then the :data:`METRIC_HEADER` metrics of the result ``r``."""
    m = r.metrics
    return row(list(label) + [fmt(m.final_error), fmt(m.rms_error), fmt(m.rms_error_second_half),
                              fmt(m.max_abs_u), fmt(m.reaching_time), fmt(m.total_variation_u)])


def result_row(label: List[str], r, err: Optional[str]) -> str:
    """:func:`metrics_row` for a result, or the label, ``err`` (a divergence marker) and blanks when ``r`` is None."""
    if r is None:
        return row(list(label) + [err] + [""] * (METRIC_CELLS - 1))
    return metrics_row(label, r)
