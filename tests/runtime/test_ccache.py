"""The compiled-code cache (fjm_runtime.ccache): an entry is reused, rebuilt when corrupt or missing, keyed by
the source, and built once when two processes ask for it at the same time."""
import json
import os
import subprocess
import sys

import pytest

import fjm_runtime
from fjm_runtime.ccache import cache_dir
from fjm_runtime.control.factory import make_controller
from fjm_runtime.sim.compiled import sampled_loop_runner
from fjm_runtime.sim.sensor import SensorModel
from fjm_runtime.sim.step_layout import make_layout
from support.paths import REPO

pytestmark = pytest.mark.slow  # builds C, a wheel or derives in a subprocess: `pytest -m 'not slow'` skips it


_CHILD = """
import numpy as np, fjm_runtime
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import Sinusoid
from fjm_runtime.sim.simulate import simulate
m = fjm_runtime.load("link1")
ctrl = make_controller("smc", m, {}, lam=8.0, k_s=300.0, delta=2.0)
r = simulate(m, ctrl, Sinusoid(0.5, 1.0), duration=0.2, true_params={"K": 110.0}, backend="compiled")
print(repr(float(r.x[-1, 0])))
"""


def _child(cache):
    env = dict(os.environ, FJM_CACHE=str(cache), PYTHONPATH=str(REPO))
    out = subprocess.run([sys.executable, "-c", _CHILD], env=env, cwd=str(REPO),
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return float(out.stdout.strip().splitlines()[-1])


def _entries(cache):
    return sorted(cache.glob("*.so")), sorted(cache.glob("*.json"))


def test_cache_is_reused_and_rebuilt_when_corrupt(private_cache):
    ref_value = _child(private_cache)          # builds the entry
    (so,), (meta,) = _entries(private_cache)
    record = json.loads(meta.read_text())
    stamp = so.stat().st_mtime_ns
    assert _child(private_cache) == ref_value  # reused: not rebuilt
    assert so.stat().st_mtime_ns == stamp

    so.write_bytes(b"\x7fELF garbage, not a library")   # corrupt the library
    assert _child(private_cache) == ref_value
    assert json.loads(meta.read_text())["so_sha256"] == record["so_sha256"]  # rebuilt, same bytes

    meta.write_text("{ not json")                       # corrupt the record
    assert _child(private_cache) == ref_value
    assert json.loads(meta.read_text())["key"] == record["key"]

    so.unlink()                                         # missing library
    assert _child(private_cache) == ref_value
    assert len(_entries(private_cache)[0]) == 1


def test_cache_key_changes_with_the_source(private_cache):
    m = fjm_runtime.load("link1")
    c1 = make_controller("smc", m, {}, lam=8.0, k_s=300.0, delta=2.0)
    c2 = make_controller("smc", m, {}, lam=9.0, k_s=300.0, delta=2.0)
    L = make_layout(m, c1, 1e-3, 1, SensorModel.ideal(), 0, False)
    sampled_loop_runner(m, c1, L, 10)
    sampled_loop_runner(m, c2, L, 10)
    sampled_loop_runner(m, c1, L, 10)
    assert len(_entries(cache_dir())[0]) == 2


_BUILDER = """
import sys
from fjm_runtime.ccache import compile_library
print(compile_library("double fjm_lock_probe(double x) { return 2.0 * x; }\\n", "fjm_lock_probe"))
"""


def test_concurrent_processes_build_an_entry_once(private_cache, tmp_path):
    """Two processes asking for the same entry at once: one compiles, the other waits for it (the lock)."""
    import ctypes
    log = tmp_path / "cc.log"
    cc = tmp_path / "slow-cc"   # a compiler that logs each call and is slow enough for the two to overlap
    cc.write_text(f"#!/bin/sh\necho \"$@\" >> '{log}'\nsleep 1\nexec gcc \"$@\"\n")
    cc.chmod(0o755)
    env = dict(os.environ, FJM_CACHE=str(private_cache), CC=str(cc), PYTHONPATH=str(REPO))
    procs = [subprocess.Popen([sys.executable, "-c", _BUILDER], env=env, cwd=str(REPO), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1] for o in outs]
    paths = {o[0].strip().splitlines()[-1] for o in outs}
    assert len(paths) == 1, paths
    assert len(log.read_text().splitlines()) == 1, log.read_text()   # compiled once, not twice
    (so,), (meta,) = _entries(private_cache)
    assert str(so) in paths and json.loads(meta.read_text())["function"] == "fjm_lock_probe"
    fn = ctypes.CDLL(str(so)).fjm_lock_probe
    fn.restype, fn.argtypes = ctypes.c_double, [ctypes.c_double]
    assert fn(1.5) == 3.0
