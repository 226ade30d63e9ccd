"""``FJM_GENERATED=DIR`` makes ``fjm_runtime.load`` read models from DIR (README: Model files).

A copy of generated/link1 with one changed default (K = 123) and a copy renamed to a user model
are put in a temporary directory; a fresh interpreter with the variable set must find exactly
those, and without it the repository's models again.
"""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

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
    assert got["available"] == ["link1", "mylink"]
    assert got["K"] == 123.0 and Path(got["directory"]).resolve() == (root / "link1").resolve()
    assert abs(got["beta"] - 1.0 * 2.0 / 123.0) < 1e-15  # the default comes from the copied manifest
    assert "unknown model 'planar2'" in got["planar2"] and "link1, mylink" in got["planar2"]

    # without the variable: the repository's models, K = 150
    repo = probe(None)
    assert repo["K"] == 150.0 and "planar2" in repo["available"] and repo["planar2"] == "loaded"
