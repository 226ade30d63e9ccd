"""Byte comparison of two ``generated/`` trees (a fresh ``python -m derive`` against the committed one)."""
from __future__ import annotations

from pathlib import Path

__all__ = ["differing_files"]


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
