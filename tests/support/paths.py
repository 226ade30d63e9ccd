"""Paths the tests use, whatever folder a test file sits in."""

from pathlib import Path

#: The repository root (the folder holding pyproject.toml).
REPO = Path(__file__).resolve().parents[2]
#: The committed generated/ directory.
GENERATED = REPO / "generated"
