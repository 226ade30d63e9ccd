"""Packaging: the wheel ships generated/ as package data and works without SymPy.

Builds the wheel from a copy of the source tree (so the repository gets no
``build/`` debris), checks that it holds every generated file of all eight
models byte for byte, installs it with ``--no-deps`` into a fresh venv that
has only casadi==3.7.2 and numpy (no SymPy), and there loads planar3 (and
every other model) from the installed package data, comparing the numbers with
this process. Takes ~30-60 s (venv + casadi install); part of ``make test``.

The wheel is kept in the fjm C cache (``$FJM_CACHE``, ``wheel-<key>/``) under the SHA-256 of
everything it is built from (the paths and bytes of the copied source tree, the Python and pip
versions): a session whose sources are unchanged installs the wheel built by an earlier one (and
still checks its contents file by file against generated/). The venv is always new; it is created
without pip and filled by this interpreter's pip (``pip --python``), one install for casadi, numpy
and the wheel.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.ccache import cache_dir
from fjm_runtime.model import COMPLETE_QUANTITIES, QUANTITIES

from support.paths import REPO  # noqa: E402
pytestmark = pytest.mark.slow  # builds and installs a wheel: `pytest -m "not slow"` skips it
MODELS = ("link1", "planar1", "planar2", "planar3", "planar4", "planar5", "planar6", "planar7", "elbow3", "panda",
          "baxter", "link1_hd", "arm1_hd", "panda_hd")
#: Complete models (rotor spin coupling): plant functions only (fjm_runtime.model.COMPLETE_QUANTITIES).
COMPLETE = ("link1_complete", "planar2_complete", "panda_complete")
SOURCES = ("pyproject.toml", "README.md", "LICENSE", "derive", "fjm_runtime", "generated")


def _run(cmd, **kw):
    proc = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=300, **kw)
    assert proc.returncode == 0, f"{' '.join(map(str, cmd))} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc


def _clean_env():
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "FJM_GENERATED", "VIRTUAL_ENV", "PYTHONHOME")}
    return env


IGNORE = ("__pycache__", "*.pyc", "*.so", "*.o")


def _copy_sources(dst: Path) -> None:
    for name in SOURCES:
        p = REPO / name
        if p.is_dir():
            shutil.copytree(p, dst / name, ignore=shutil.ignore_patterns(*IGNORE))
        elif p.is_file():
            shutil.copy2(p, dst / name)


def _tree_key(root: Path) -> str:
    """SHA-256 of the relative paths and bytes of every file under ``root``, and the Python and pip versions."""
    pip = importlib.metadata.version("pip")
    h = hashlib.sha256(f"fjm tests/packaging wheel\0{sys.version}\0pip {pip}".encode())
    for f in sorted(p for p in root.rglob("*") if p.is_file()):
        h.update(b"\0" + str(f.relative_to(root)).encode() + b"\0")
        h.update(hashlib.sha256(f.read_bytes()).digest())
    return h.hexdigest()


def _cached_wheel(entry: Path):
    """The wheel of a cache entry whose recorded SHA-256 matches its bytes, else ``None``."""
    try:
        record = json.loads((entry / "wheel.json").read_text())
        whl = entry / record["wheel"]
        if whl.is_file() and hashlib.sha256(whl.read_bytes()).hexdigest() == record["sha256"]:
            return whl
    except (OSError, ValueError, KeyError, TypeError):
        pass
    return None


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    src = tmp_path_factory.mktemp("wheel_src")
    _copy_sources(src)
    entry = cache_dir() / f"wheel-{_tree_key(src)}"
    cached = _cached_wheel(entry)
    if cached is not None:
        return cached
    dist = tmp_path_factory.mktemp("wheel_dist")
    _run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-w", str(dist), "-q"], env=_clean_env())
    wheels = sorted(dist.glob("fjm-*.whl"))
    assert len(wheels) == 1, wheels
    # into the cache: a fresh directory renamed into place (a concurrent session's entry is kept)
    tmp = Path(tempfile.mkdtemp(prefix=".wheel-", dir=cache_dir()))
    shutil.copy2(wheels[0], tmp / wheels[0].name)
    (tmp / "wheel.json").write_text(json.dumps({"wheel": wheels[0].name,
                                                "sha256": hashlib.sha256(wheels[0].read_bytes()).hexdigest()}))
    if entry.exists() and _cached_wheel(entry) is None:  # a broken entry: replaced, not kept forever
        shutil.rmtree(entry, ignore_errors=True)
    try:
        os.rename(tmp, entry)
    except OSError:  # already there (another session) or not renamable: the built wheel is used as is
        shutil.rmtree(tmp, ignore_errors=True)
    return wheels[0]


def test_wheel_contains_generated_models(wheel):
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        for model in MODELS + COMPLETE:
            quantities = COMPLETE_QUANTITIES if model in COMPLETE else QUANTITIES
            files = [f"{q}.casadi" for q in quantities] + ["manifest.json", f"{model}.c", f"{model}.h"]
            for f in files:
                arc = f"fjm_runtime/generated/{model}/{f}"
                assert arc in names, f"wheel lacks {arc}"
                assert z.read(arc) == (REPO / "generated" / model / f).read_bytes(), f"{arc} differs from generated/"
        assert "fjm_runtime/__init__.py" in names and "fjm_runtime/model.py" in names
        shipped = sorted((REPO / "fjm_runtime" / "control" / "designed").glob("*.json"))
        assert shipped
        for f in shipped:  # the shipped designs (Design.shipped) travel with the wheel
            assert f"fjm_runtime/control/designed/{f.name}" in names, f"wheel lacks the shipped design {f.name}"
        assert not [n for n in names if "__pycache__" in n or n.startswith("tests/")]
        meta = next(n for n in names if n.endswith(".dist-info/METADATA"))
        requires = [ln for ln in z.read(meta).decode().splitlines() if ln.startswith("Requires-Dist:")]
    hard = [r for r in requires if "extra ==" not in r]
    assert any("casadi" in r for r in hard) and any("numpy" in r for r in hard), hard
    assert not any("sympy" in r for r in hard), f"SymPy must be an extra, not a runtime dependency: {hard}"


CHECK = r"""
import json, sys
import numpy as np
import fjm_runtime
from fjm_runtime.model import generated_root
try:
    import sympy  # noqa: F401
    has_sympy = True
except ImportError:
    has_sympy = False
m = fjm_runtime.load("planar3")
x = np.linspace(-0.5, 0.6, m.nx)
out = {
    "runtime_file": fjm_runtime.__file__,
    "generated_root": str(generated_root()),
    "models": fjm_runtime.available_models(),
    "has_sympy": has_sympy,
    "sympy_imported": "sympy" in sys.modules,
    "n": m.n, "nx": m.nx,
    "alpha": m.alpha(x, m.default_params).tolist(),
    "beta": m.beta(x, m.default_params).tolist(),
    "f7": fjm_runtime.load("planar7").f(np.full(28, 0.1)).tolist(),
}
print(json.dumps(out))
"""


def _pip(py: Path, *args, **kw):
    """This interpreter's pip acting on the environment of ``py`` (``pip --python``; the venv has no pip)."""
    return _run([sys.executable, "-m", "pip", "--python", py, *args], **kw)


@pytest.fixture(scope="module")
def venv(wheel, tmp_path_factory) -> Path:
    """A fresh venv with casadi, numpy and the wheel only (no SymPy)."""
    venv = tmp_path_factory.mktemp("wheel_venv") / "venv"
    env = _clean_env()
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], env=env)
    py = venv / "bin" / "python"
    _pip(py, "install", "-q", "--no-deps", "casadi==3.7.2", f"numpy=={np.__version__}", wheel, env=env)
    return venv


def test_wheel_installs_and_runs_without_sympy(venv, tmp_path):
    env = _clean_env()
    py = venv / "bin" / "python"
    run_dir = tmp_path / "elsewhere"  # not the repository: nothing may come from the source tree
    run_dir.mkdir()
    proc = _run([py, "-c", CHECK], cwd=run_dir, env=env)
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    assert not res["has_sympy"], "the fresh venv should not have SymPy"
    assert not res["sympy_imported"]
    assert str(venv) in res["runtime_file"], res["runtime_file"]
    assert str(venv) in res["generated_root"] and res["generated_root"].endswith("fjm_runtime/generated"), res
    assert res["models"] == sorted(MODELS + COMPLETE)
    m = fjm_runtime.load("planar3")
    x = np.linspace(-0.5, 0.6, m.nx)
    assert (res["n"], res["nx"]) == (3, 12)
    np.testing.assert_allclose(res["alpha"], m.alpha(x, m.default_params), rtol=1e-12, atol=0)
    np.testing.assert_allclose(res["beta"], m.beta(x, m.default_params), rtol=1e-12, atol=0)
    np.testing.assert_allclose(res["f7"], fjm_runtime.load("planar7").f(np.full(28, 0.1)), rtol=1e-12, atol=1e-300)


@pytest.mark.exhaustive  # ~7 s: .ci/run runs it after make test (make test stays under 5 minutes)
def test_installed_derive_needs_out_and_fjm_generated(venv, tmp_path):
    """``fjm derive`` from the installed wheel: without SymPy it names the extra; with SymPy but
    without ``--out`` it is a usage error (no ``site-packages/generated``); with ``--out DIR`` and
    ``FJM_GENERATED=DIR`` load() reads the derived model. SymPy (sympy==1.14.0 and mpmath of this
    interpreter, linked: no second download and install) goes into a separate directory on
    PYTHONPATH, so the venv itself stays SymPy-free for the test above."""
    env = _clean_env()
    fjm, py = venv / "bin" / "fjm", venv / "bin" / "python"
    run_dir = tmp_path / "elsewhere"
    run_dir.mkdir()

    proc = subprocess.run([str(fjm), "derive", "--models", "link1"], cwd=run_dir, env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "pip install" in proc.stderr and "sympy" in proc.stderr, proc.stderr

    extra = tmp_path / "derive-extra"
    extra.mkdir()
    assert importlib.metadata.version("sympy") == "1.14.0"  # the pin of the derive extra (pyproject.toml)
    for name in ("sympy", "mpmath"):  # this interpreter's installed packages, linked (with their bytecode)
        (extra / name).symlink_to(importlib.util.find_spec(name).submodule_search_locations[0],
                                  target_is_directory=True)
    env_sympy = dict(env, PYTHONPATH=str(extra))
    site = Path(_run([py, "-c", "import derive, pathlib; print(pathlib.Path(derive.__file__).parent.parent)"],
                     env=env_sympy, cwd=run_dir).stdout.strip())
    assert str(venv) in str(site), site
    proc = subprocess.run([str(fjm), "derive", "--models", "link1"], cwd=run_dir, env=env_sympy,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "--out DIR" in proc.stderr and "FJM_GENERATED=DIR" in proc.stderr, proc.stderr
    assert not (site / "generated").exists() and not (site / "build").exists()

    out = tmp_path / "models"
    _run([fjm, "derive", "--models", "link1", "--out", out], cwd=run_dir, env=env_sympy)
    assert (out / "link1" / "manifest.json").is_file()
    for f in sorted((REPO / "generated" / "link1").iterdir()):
        assert (out / "link1" / f.name).read_bytes() == f.read_bytes(), f"{f.name} differs from generated/link1"
    check = ("import json, fjm_runtime; m = fjm_runtime.load('link1'); "
             "print(json.dumps([str(m.directory), fjm_runtime.available_models()]))")
    directory, models = json.loads(_run([py, "-c", check], cwd=run_dir,
                                        env=dict(env, FJM_GENERATED=str(out))).stdout.strip().splitlines()[-1])
    # FJM_GENERATED adds its models: the derived link1 wins, the built-in models stay
    assert directory == str(out / "link1") and "link1" in models and "planar2" in models
