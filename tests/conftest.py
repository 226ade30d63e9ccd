"""Shared fixtures of the whole suite.

Layout: ``tests/derive`` (the symbolic derivation), ``tests/generated`` (the committed outputs:
C, reports), ``tests/runtime/<room>`` (``fjm_runtime``: model and validation at the top,
``control``, ``sim``, ``batch``, ``analysis``, ``experiments``, ``cli``), ``tests/packaging``
(wheel, docs, examples, self-containment), ``tests/bench`` (the benchmark's peers). Helpers shared
by several files live in the package ``tests/support`` (no tests there).

Tests that build C, a wheel or derive in a subprocess are marked ``slow``:
``pytest -m "not slow"`` runs the rest in a fraction of the time; ``make test`` runs everything, on
every core (pytest-xdist, ``-n auto``).
"""

from __future__ import annotations

import pytest

from support.paths import GENERATED, REPO


@pytest.fixture(scope="session")
def repo():
    """The repository root (``pathlib.Path``)."""
    return REPO


@pytest.fixture(scope="session")
def generated_dir():
    """The committed ``generated/`` directory (``pathlib.Path``)."""
    return GENERATED


@pytest.fixture(scope="session")
def link1():
    """The generated ``link1`` model (``fjm_runtime.Model``), loaded once."""
    import fjm_runtime
    return fjm_runtime.load("link1")


@pytest.fixture(scope="session")
def panda():
    """The generated ``panda`` model (``fjm_runtime.Model``), loaded once."""
    import fjm_runtime
    return fjm_runtime.load("panda")
