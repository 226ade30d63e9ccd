"""``FJM_GENERATED=DIR`` adds the models of DIR to the built-in ones (README: Model files).

A copy of generated/link1 with one changed default (K = 123) and a copy renamed to a user model
are put in a temporary directory; a fresh interpreter with the variable set must find both (the
user's link1 wins over the built-in one) and every built-in model still; without it the
repository's models again. A missing directory is an error naming the variable and the path.
"""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

from support.paths import REPO  # noqa: E402

PROBE = r"""
import json, numpy as np, fjm_runtime
from fjm_runtime.model import available_models
m = fjm_runtime.load("link1")
out = {"available": available_models(), "K": m.default_params["K"],
       "beta": float(m.beta(np.zeros(4))[0, 0]), "directory": str(m.directory)}
try:
    fjm_runtime.load("planar2")
    out["planar2"] = "loaded"
except ValueError as exc:
    out["planar2"] = str(exc)
print(json.dumps(out))
"""


def probe(env_value):
    env = {k: v for k, v in os.environ.items() if k != "FJM_GENERATED"}
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    if env_value is not None:
        env["FJM_GENERATED"] = str(env_value)
    proc = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, cwd=REPO.parent)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_load_finds_models_in_the_directory_named_by_FJM_GENERATED(tmp_path):
    root = tmp_path / "models"
    shutil.copytree(REPO / "generated" / "link1", root / "link1")
    manifest_path = root / "link1" / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    for par in manifest["parameters"]:
        if par["name"] == "K":
            par["default"] = 123.0
    manifest_path.write_text(json.dumps(manifest))
    shutil.copytree(REPO / "generated" / "link1", root / "mylink")

    got = probe(root)
    repo = probe(None)
    assert got["available"] == sorted(repo["available"] + ["mylink"])
    assert got["K"] == 123.0 and Path(got["directory"]).resolve() == (root / "link1").resolve()
    assert abs(got["beta"] - 1.0 * 2.0 / 123.0) < 1e-15  # the default comes from the copied manifest
    assert got["planar2"] == "loaded"  # the built-in models stay available

    # without the variable: the repository's models, K = 150
    assert repo["K"] == 150.0 and "planar2" in repo["available"] and repo["planar2"] == "loaded"


def test_a_user_directory_without_link1_keeps_the_built_in_link1(tmp_path):
    root = tmp_path / "models"
    shutil.copytree(REPO / "generated" / "link1", root / "mylink")
    got = probe(root)
    assert "mylink" in got["available"] and "link1" in got["available"]
    assert got["K"] == 150.0 and Path(got["directory"]).resolve() != (root / "link1").resolve()


MISSING = r"""
import fjm_runtime
try:
    fjm_runtime.load("link1")
except ValueError as exc:
    print(type(exc).__name__ + ": " + str(exc))
"""


def test_a_missing_FJM_GENERATED_directory_names_the_variable_and_the_path(tmp_path):
    missing = tmp_path / "no-such-dir"
    env = {k: v for k, v in os.environ.items() if k != "FJM_GENERATED"}
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env["FJM_GENERATED"] = str(missing)
    proc = subprocess.run([sys.executable, "-c", MISSING], env=env, capture_output=True, text=True, cwd=REPO.parent)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout.strip()
    assert out.startswith("FjmValueError: ") and "FJM_GENERATED" in out and str(missing) in out, out
    assert "make derive" not in out


def test_a_missing_model_directory_is_a_value_error_naming_the_path(tmp_path):
    import pytest
    import fjm_runtime
    from fjm_runtime import FjmValueError
    from fjm_runtime.model import Model
    missing = tmp_path / "nonexist"
    for make in (lambda: fjm_runtime.load(str(missing)), lambda: Model(missing)):
        with pytest.raises(FjmValueError, match=str(missing)):
            make()
    with pytest.raises(FjmValueError, match="/nonexist"):
        fjm_runtime.load("/nonexist")
    (missing).mkdir()
    with pytest.raises(FjmValueError, match="manifest.json"):
        Model(missing)
    # a model directory by path loads like the name
    assert fjm_runtime.load(str(REPO / "generated" / "link1")).param_names == fjm_runtime.load("link1").param_names
