"""``load`` takes the path a user has of a derived model: the model directory, the ``fjm derive --out``
directory holding it, its manifest.json, or a bare folder name in the working directory; a model file,
a URDF and a folder of several models are refused in one line saying what to give instead."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.cli.main import main as fjm_main
from fjm_runtime.model import command_name
from fjm_runtime.validation import FjmValueError

from support.paths import GENERATED


@pytest.fixture()
def out(tmp_path):
    """``tmp_path/out/mylink``: a copy of the built-in link1, as ``fjm derive --out out`` leaves a model."""
    shutil.copytree(GENERATED / "link1", tmp_path / "out" / "mylink")
    return tmp_path / "out"


def _same_dynamics(m):
    ref = fjm_runtime.load("link1")
    x = np.array([0.3, -0.2, 0.31, 0.1])
    assert m.n == 1 and m.param_names == ref.param_names
    np.testing.assert_array_equal(m.f(x), ref.f(x))
    np.testing.assert_array_equal(m.g(x), ref.g(x))


@pytest.mark.parametrize("given", ["out", "out/", "out/mylink", "out/mylink/manifest.json"])
def test_every_path_a_user_has_loads_the_model(out, given, monkeypatch):
    monkeypatch.chdir(out.parent)
    m = fjm_runtime.load(given)
    assert m.directory == (out / "mylink").resolve()
    _same_dynamics(m)
    assert command_name(m) == str((out / "mylink").resolve())   # no name finds it: its path
    assert command_name(fjm_runtime.load("link1")) == "link1"


def test_a_bare_folder_name_in_the_working_directory_loads(out, monkeypatch):
    monkeypatch.chdir(out)
    _same_dynamics(fjm_runtime.load("mylink"))


def test_a_folder_of_several_models_names_them(out):
    shutil.copytree(GENERATED / "link1", out / "other")
    with pytest.raises(FjmValueError) as e:
        fjm_runtime.load(str(out))
    msg = str(e.value)
    assert "\n" not in msg and "2 models (mylink, other)" in msg and str(out / "mylink") in msg


@pytest.mark.parametrize("suffix, word", [(".toml", "model file"), (".urdf", "URDF")])
def test_a_model_file_or_urdf_says_derive_it_first(tmp_path, suffix, word):
    f = tmp_path / f"arm{suffix}"
    f.write_text("")
    with pytest.raises(FjmValueError) as e:
        fjm_runtime.load(str(f))
    msg = str(e.value)
    assert "\n" not in msg and word in msg and "fjm derive --model-file" in msg and "DIR/<name>" in msg


def test_unknown_model_lists_the_built_ins_and_says_a_path_works(capsys):
    assert fjm_main(["simulate", "myarm"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "unknown model 'myarm'" in err and "link1" in err and "panda" in err
    assert "path of a derived model directory" in err and "--out DIR" in err


def test_simulate_runs_on_the_derive_output_directory(out, capsys):
    assert fjm_main(["simulate", str(out), "--duration", "0.05", "--quiet", "--json"]) == 0
    import json
    rep = json.loads(capsys.readouterr().out)
    assert rep["settings"]["model"] == "link1" and not rep["diverged"]
    assert np.isfinite(rep["rms_second_half"][0])
