"""Values of a bench run: ``bench/results.json`` read, a dotted key looked up, a number formatted."""
from __future__ import annotations

import json
import math
from pathlib import Path

__all__ = ["RESULTS", "load", "get", "value_text"]

#: The committed results of the last full ``make bench``.
RESULTS = Path(__file__).resolve().parent / "results.json"


def load(path: Path = RESULTS) -> dict:
    """The results of a bench run (``bench/results.json`` by default)."""
    return json.loads(Path(path).read_text())


def get(results: dict, key: str):
    """Value of a dotted key (``derive.planar7.seconds``), ``None`` if absent or not a number."""
    v = results
    for part in key.split("."):
        if not isinstance(v, dict) or part not in v:
            return None
        v = v[part]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        return None
    return v


def value_text(results: dict, key: str, fmt: str, scale: float = 1.0) -> str:
    """``key``'s value times ``scale`` in ``fmt`` (``-`` when not measured)."""
    v = get(results, key)
    return "-" if v is None else format(v * scale, fmt)
