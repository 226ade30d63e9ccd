"""Shared fixtures of the whole suite.

Layout: ``tests/derive`` (the symbolic derivation), ``tests/generated`` (the committed outputs:
C, reports), ``tests/runtime/<room>`` (``fjm_runtime``: model and validation at the top,
``control``, ``sim``, ``batch``, ``analysis``, ``export``, ``ident``, ``experiments``, ``cli``; a module's
tests in ``test_<module>.py``), ``tests/scenarios`` (runs through several rooms: a CLI run end to end,
a user's arm, MuJoCo against ``simulate``, the demo's figures), ``tests/packaging`` (wheel, docs,
examples, self-containment), ``tests/bench`` (the benchmark's peers). Helpers shared
by several files live in the package ``tests/support`` (no tests there).

Tests that build C, a wheel or derive in a subprocess are marked ``slow``:
``pytest -m "not slow"`` runs the rest in a fraction of the time; ``make test`` runs everything, on
every core (pytest-xdist, ``-n auto --dist loadfile --no-loadscope-reorder``): a file runs on one
worker, so its module and session fixtures (the strict C builds, the wheel and its venv, the quick
figures) are built once, and the costliest files (``HEAVY_FIRST``) start first so the tail is short.
"""

from __future__ import annotations

import os

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
def planar2():
    """The generated ``planar2`` model (``fjm_runtime.Model``), loaded once."""
    import fjm_runtime
    return fjm_runtime.load("planar2")


@pytest.fixture
def private_cache(tmp_path, monkeypatch):
    """A compiled-code cache of this test's own (``FJM_CACHE`` set to a fresh directory, ``pathlib.Path``)."""
    monkeypatch.setenv("FJM_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


@pytest.fixture(scope="session")
def panda():
    """The generated ``panda`` model (``fjm_runtime.Model``), loaded once."""
    import fjm_runtime
    return fjm_runtime.load("panda")


#: Test files by cost, costliest first (measured: ``make test`` on 2 cores, cold C cache, the machine
#: shared with another CPU-bound job); under pytest-xdist they are collected first, so with
#: ``--dist loadfile --no-loadscope-reorder`` they are handed out first and the run does not end on
#: one worker still in a long file. Only the order of the run changes; a file missing here runs after
#: them, in the usual order. (A worker is handed its next file once at most 2 tests of its current one
#: are left: the quick-figures file, 2 tests behind one ~40 s CPU fixture, always has one queued.)
HEAVY_FIRST = (
    "tests/scenarios/test_figures_quick.py",            # fjm figures --quick (~40 s CPU)
    "tests/generated/test_c_sources.py",               # strict -O2 build of every model (~37 s CPU cold, cached warm)
    "tests/runtime/batch/test_sampled_runner.py",      # panda smoke: a 1.8 MB batch C source (~16 s gcc cold)
    "tests/derive/test_interrupted_derive.py",
    "tests/runtime/analysis/certificates/test_certify.py",
    "tests/packaging/test_wheel.py",
    "tests/runtime/control/test_laws.py",
    "tests/scenarios/test_spatial_control.py",
    "tests/packaging/test_realtime_example.py",
    "tests/derive/test_derive_check_and_timings.py",
    "tests/scenarios/test_emitted_laws.py",
    "tests/derive/test_physics.py",
    "tests/packaging/test_self_contained.py",
    "tests/runtime/sim/test_simulate.py",
    "tests/runtime/sim/test_compiled.py",
    "tests/runtime/test_ccache.py",
    "tests/derive/test_guard.py",
    "tests/runtime/analysis/certificates/test_regulation.py",
)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Exhaustive tests only when asked for; under pytest-xdist, the files of ``HEAVY_FIRST`` first.

    ``@pytest.mark.exhaustive`` tests (tens of seconds or more each) are deselected unless the ``-m``
    expression names them (``.ci/run`` runs ``pytest -m exhaustive`` after ``make test``), so that
    ``make test`` and ``pytest -m 'not slow'`` leave them out alike. The heavy-first order is stable:
    the rest keeps its order.
    """
    if "exhaustive" not in (config.getoption("markexpr") or ""):
        left_out = [item for item in items if item.get_closest_marker("exhaustive") is not None]
        if left_out:
            config.hook.pytest_deselected(items=left_out)
            items[:] = [item for item in items if item.get_closest_marker("exhaustive") is None]
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return
    rank = {path: i for i, path in enumerate(HEAVY_FIRST)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::", 1)[0], len(HEAVY_FIRST)))
