"""Derivation is deterministic: the same models derived under different PYTHONHASHSEEDs
(in different output directories, from different working directories) give identical bytes."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Dict

import pytest

from support.paths import REPO  # noqa: E402
pytestmark = pytest.mark.slow  # builds C, a wheel or derives in a subprocess: `pytest -m 'not slow'` skips it

MODELS = ("link1", "planar2")
SEEDS = ("0", "2718281")


def tree_bytes(root: Path) -> Dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


# exhaustive pass (.ci/run), to keep make test under 5 minutes on 2 cores: make check-generated
# derives every model under two hash seeds and compares with generated/ on every CI run
@pytest.mark.exhaustive
def test_derive_is_byte_identical_across_hash_seeds(tmp_path):
    procs, outs = [], []
    for seed in SEEDS:  # both runs at once (2 cores)
        out = tmp_path / f"seed{seed}" / "generated"
        work = tmp_path / f"cwd{seed}"
        work.mkdir(parents=True)
        env = dict(os.environ, PYTHONHASHSEED=seed,
                   PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "derive", "--models", *MODELS, "--out", str(out)],
            cwd=work, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True))
        outs.append(out)
    for proc in procs:
        log, _ = proc.communicate(timeout=300)
        assert proc.returncode == 0, log
    a, b = (tree_bytes(o) for o in outs)
    assert sorted({Path(k).parts[0] for k in a}) == sorted(MODELS)
    expected = {f"{m}/{f}" for m in MODELS for f in
                ["manifest.json", f"{m}.c", f"{m}.h"] + [f"{q}.casadi" for q in
                                                         ("f", "g", "ad", "T", "alpha", "beta", "energy", "inertia")]}
    assert expected <= set(a), sorted(expected - set(a))
    assert set(a) == set(b), sorted(set(a) ^ set(b))
    differ = [k for k in a if a[k] != b[k]]
    assert not differ, f"PYTHONHASHSEED {SEEDS[0]} vs {SEEDS[1]}: differing files {differ}"
    for name, data in a.items():  # no absolute paths / temp dirs leak into the outputs
        assert str(tmp_path).encode() not in data and str(REPO).encode() not in data, name


def test_baked_urdf_numbers_do_not_depend_on_the_blas_kernel(tmp_path):
    """The spatial models' baked numbers (frames, inertias) are the same bytes whatever BLAS
    kernel numpy picks: OpenBLAS chooses it per processor (FMA or not), and generated/ must
    not change from one machine to the next. Forcing two kernels stands in for two machines."""
    outs, procs = [], []
    for core in ("Prescott", "Haswell"):
        out = tmp_path / core
        env = dict(os.environ, OPENBLAS_CORETYPE=core,
                   PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        procs.append(subprocess.Popen([sys.executable, "-m", "derive", "--models", "elbow3", "--out", str(out)],
                                      cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                      text=True))
        outs.append(out)
    for proc in procs:
        log, _ = proc.communicate(timeout=300)
        assert proc.returncode == 0, log
    a, b = (tree_bytes(o) for o in outs)
    assert a and set(a) == set(b)
    assert [k for k in a if a[k] != b[k]] == []
    committed = tree_bytes(REPO / "generated")
    assert [k for k in a if committed.get(k) != a[k]] == [], "generated/elbow3 differs from a fresh derive"
