"""Packaging: the wheel ships generated/ as package data and works without SymPy.

Builds the wheel from a copy of the source tree (so the repository gets no
``build/`` debris), checks that it holds every generated file of all eight
models byte for byte, installs it with ``--no-deps`` into a fresh venv that
has only casadi==3.7.2 and numpy (no SymPy), and there loads planar3 (and
every other model) from the installed package data, comparing the numbers with
this process. Takes ~30-60 s (venv + casadi install); part of ``make test``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.model import COMPLETE_QUANTITIES, QUANTITIES

from support.paths import REPO  # noqa: E402
pytestmark = pytest.mark.slow  # builds and installs a wheel: `pytest -m "not slow"` skips it
MODELS = ("link1", "planar1", "planar2", "planar3", "planar4", "planar5", "planar6", "planar7", "elbow3", "panda",
          "baxter")
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


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    src = tmp_path_factory.mktemp("wheel_src")
    for name in SOURCES:
        p = REPO / name
        if p.is_dir():
            shutil.copytree(p, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.so", "*.o"))
        elif p.is_file():
            shutil.copy2(p, src / name)
    dist = tmp_path_factory.mktemp("wheel_dist")
    _run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-w", str(dist), "-q"], env=_clean_env())
    wheels = sorted(dist.glob("fjm-*.whl"))
    assert len(wheels) == 1, wheels
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


@pytest.fixture(scope="module")
def venv(wheel, tmp_path_factory) -> Path:
    """A fresh venv with casadi, numpy and the wheel only (no SymPy)."""
    venv = tmp_path_factory.mktemp("wheel_venv") / "venv"
    env = _clean_env()
    _run([sys.executable, "-m", "venv", str(venv)], env=env)
    py = venv / "bin" / "python"
    _run([py, "-m", "pip", "install", "-q", "--no-deps", "casadi==3.7.2", f"numpy=={np.__version__}"], env=env)
    _run([py, "-m", "pip", "install", "-q", "--no-deps", str(wheel)], env=env)
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


def test_installed_derive_needs_out_and_fjm_generated(venv, tmp_path):
    """``fjm derive`` from the installed wheel: without SymPy it names the extra; with SymPy but
    without ``--out`` it is a usage error (no ``site-packages/generated``); with ``--out DIR`` and
    ``FJM_GENERATED=DIR`` load() reads the derived model. SymPy goes into a separate ``--target``
    directory on PYTHONPATH, so the venv itself stays SymPy-free for the test above."""
    env = _clean_env()
    fjm, py = venv / "bin" / "fjm", venv / "bin" / "python"
    run_dir = tmp_path / "elsewhere"
    run_dir.mkdir()

    proc = subprocess.run([str(fjm), "derive", "--models", "link1"], cwd=run_dir, env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "pip install" in proc.stderr and "sympy" in proc.stderr, proc.stderr

    extra = tmp_path / "derive-extra"
    _run([py, "-m", "pip", "install", "-q", "--no-deps", "--target", str(extra), "sympy==1.14.0", "mpmath"],
         env=env)
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
