"""``python -m derive --check`` (``make check-generated``) and ``--timings FILE`` on a copy of the repo.

The copy holds ``pyproject.toml``, ``derive/`` and the generated link1 and planar1 only, and every
command runs the copy's own ``derive`` (its ``generated/`` is the default output), so the real tree
is never touched.
"""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from support.paths import REPO  # noqa: E402
pytestmark = pytest.mark.slow  # builds C, a wheel or derives in a subprocess: `pytest -m 'not slow'` skips it

MODELS = ("link1", "planar1")


def tree_bytes(root: Path):
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture
def repo_copy(tmp_path):
    root = tmp_path / "repo"
    shutil.copytree(REPO / "derive", root / "derive", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy2(REPO / "pyproject.toml", root / "pyproject.toml")  # marks a source checkout
    for name in MODELS:
        shutil.copytree(REPO / "generated" / name, root / "generated" / name)
    return root


def derive(root: Path, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(root), PYTHONHASHSEED="0")
    env.pop("FJM_GENERATED", None)
    code = ("import sys, derive.__main__ as d; assert d.REPO == __import__('pathlib').Path(sys.argv[1]), d.REPO; "
            "sys.exit(d.main(sys.argv[2:]))")
    return subprocess.run([sys.executable, "-c", code, str(root), *args], cwd=root, env=env,
                          capture_output=True, text=True, timeout=300)


def test_check_passes_on_an_up_to_date_tree(repo_copy):
    before = tree_bytes(repo_copy / "generated")
    proc = derive(repo_copy, "--check", "--models", *MODELS)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "up to date" in proc.stdout
    assert tree_bytes(repo_copy / "generated") == before  # a check writes nothing
    assert not (repo_copy / "build").exists()


def test_check_fails_and_names_every_stale_file(repo_copy):
    gen = repo_copy / "generated"
    edited = gen / "planar1" / "alpha.casadi"
    lines = edited.read_text().splitlines(keepends=True)
    lines[2] = lines[2].rstrip("\n") + " (edited by hand)\n"
    edited.write_text("".join(lines))
    (gen / "link1" / "link1.h").unlink()
    (gen / "link1" / "notes.txt").write_text("not generated\n")
    proc = derive(repo_copy, "--check", "--models", *MODELS)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    err = proc.stderr
    assert "stale" in err and "make derive" in err
    assert "planar1/alpha.casadi" in err and "line 3" in err  # the edited file and where
    assert "link1/link1.h" in err and "missing" in err
    assert "link1/notes.txt" in err
    # only those: the untouched files are not reported
    named = [line for line in err.splitlines() if line.startswith("  ")]
    assert len(named) == 3, err


@pytest.mark.exhaustive  # a full derive in a subprocess (~12 s); byte-identity also: test_determinism.py
def test_timings_file_gets_per_model_seconds_and_generated_stays_byte_identical(repo_copy, tmp_path):
    gen = repo_copy / "generated"
    before = tree_bytes(gen)
    timings = tmp_path / "elsewhere" / "t.json"
    proc = derive(repo_copy, "--models", *MODELS, "--timings", str(timings))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    data = json.loads(timings.read_text())
    assert set(data["models"]) == set(MODELS)
    for name in MODELS:
        entry = data["models"][name]
        assert 0 < entry["seconds"] < 300
        assert entry["seconds"] == pytest.approx(entry["derive_seconds"] + entry["emit_seconds"], rel=1e-9)
    assert data["total_seconds"] >= max(e["seconds"] for e in data["models"].values())
    # re-derived in place: same files, same bytes (no timestamps or seconds inside generated/)
    assert tree_bytes(gen) == before
    assert not (repo_copy / "build" / "derive-timings.json").exists()  # --timings replaces the default
    # without --timings, writing the default generated/ puts them in build/derive-timings.json
    proc = derive(repo_copy, "--models", "link1")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    default = json.loads((repo_copy / "build" / "derive-timings.json").read_text())
    assert list(default["models"]) == ["link1"] and default["models"]["link1"]["seconds"] > 0
    assert tree_bytes(gen) == before
