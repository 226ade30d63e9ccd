"""User model files: a TOML description of a planar chain derives and emits
exactly like the built-in planar<n>, and every bad file is rejected with the key and its line."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Dict

import numpy as np
import pytest

from derive.__main__ import derive_into, main as derive_main  # noqa: E402
from derive.model_file import load_model_file, parse_model_text
from derive.model_file.schema import ModelFileError
from derive.model_file.toml_keys import locate_keys
from derive.planar.planar import make_planar  # noqa: E402
from fjm_runtime.model import Model, load  # noqa: E402

from support.paths import REPO  # noqa: E402
EXAMPLE = REPO / "examples" / "arm.toml"
QUANTITIES = ("f", "g", "ad", "T", "alpha", "beta", "energy", "inertia")


def tree_bytes(root: Path) -> Dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def quiet(*args, **kwargs):
    pass


@pytest.fixture(scope="module")
def derived(tmp_path_factory):
    out = tmp_path_factory.mktemp("user") / "models"
    assert derive_main(["--model-file", str(EXAMPLE), "--out", str(out)]) == 0
    return out


# ---- valid files ------------------------------------------------------------------------------

def test_example_parses():
    spec = load_model_file(EXAMPLE)
    assert (spec.name, spec.links) == ("arm3", 3)
    assert spec.defaults["m1"] == 4.0 and spec.defaults["K1"] == 300.0 and spec.defaults["l1"] == 0.6
    assert "Jm2" not in spec.defaults  # not in the file: keeps the planar3 default
    assert spec.units["I2"] == "kg m^2" and spec.units["g0"] == "m/s^2"


def test_example_derives_and_equals_builtin_planar3(derived):
    user = Model(derived / "arm3")
    builtin = load("planar3")
    spec = load_model_file(EXAMPLE)
    assert user.name == "arm3" and user.n == 3 and user.nx == 12
    assert user.param_names == builtin.param_names
    expected_defaults = dict(builtin.default_params, **spec.defaults)
    assert user.default_params == expected_defaults
    assert user.manifest["description"] == spec.description
    assert [p["unit"] for p in user.manifest["parameters"]] == \
        [p["unit"] for p in builtin.manifest["parameters"]]
    rng = np.random.default_rng(6)
    for _ in range(25):
        x = rng.uniform(-2.0, 2.0, user.nx)
        for p in (None, dict(expected_defaults, K2=123.0, g0=9.81)):
            p_builtin = expected_defaults if p is None else p
            for q in QUANTITIES:
                a = np.asarray(getattr(user, q)(x, p), dtype=float)
                b = np.asarray(getattr(builtin, q)(x, p_builtin), dtype=float)
                np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12, err_msg=q)


def test_derived_files_name_the_model(derived):
    files = sorted(p.name for p in (derived / "arm3").iterdir())
    assert "arm3.c" in files and "arm3.h" in files and "manifest.json" in files
    header = (derived / "arm3" / "arm3.h").read_text()
    assert "arm3_alpha" in header and "planar3" not in header


def test_model_file_is_emitted_exactly_like_make_planar(derived, tmp_path):
    """Same bytes as the registry's planar chain with the same name, defaults and description."""
    spec = load_model_file(EXAMPLE)
    direct = tmp_path / "direct"
    derive_into(direct, ["arm3"], log=quiet, builders={"arm3": lambda: make_planar(
        3, name="arm3", defaults=spec.defaults, description=spec.description)})
    assert tree_bytes(direct) == tree_bytes(derived)


def test_deterministic_across_runs_and_hash_seeds(derived, tmp_path):
    """`fjm derive` in a fresh process with another PYTHONHASHSEED gives the same bytes."""
    out = tmp_path / "again"
    env = dict(os.environ, PYTHONHASHSEED="4242",
               PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-m", "fjm_runtime.cli.main", "derive", "--model-file", str(EXAMPLE),
                           "--out", str(out)], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr + proc.stdout
    assert tree_bytes(out) == tree_bytes(derived)


def test_minimal_file_gets_planar_defaults(tmp_path):
    path = tmp_path / "two.toml"
    path.write_text('[model]\nname = "two"\nlinks = 2\n')
    assert derive_main(["--model-file", str(path), "--out", str(tmp_path / "out")]) == 0
    user, builtin = Model(tmp_path / "out" / "two"), load("planar2")
    assert user.default_params == builtin.default_params
    x = np.random.default_rng(1).normal(size=8)
    for q in QUANTITIES:
        np.testing.assert_allclose(getattr(user, q)(x), getattr(builtin, q)(x), rtol=1e-12, atol=1e-12)


def test_equivalent_spellings_parse_the_same():
    base = '[model]\nname = "a"\nlinks = 1\n'
    forms = [
        base + "[parameters]\nm1 = 2\nI1 = 0.2\n",
        base + '[parameters]\nm1 = { default = 2.0, unit = "kg" }\nI1 = { default = 0.2, unit = "kg*m^2" }\n',
        base + '[parameters.m1]\ndefault = 2.0\nunit = " kg "\n[parameters.I1]\ndefault = 0.2\nunit = "kg·m²"\n',
        'parameters.m1.default = 2.0\nparameters."I1" = 0.2\n' + base,
        base + "[parameters]\nm1.default = 2e0\nm1.unit = 'kg'\nI1.default = 0.2\n",
    ]
    for text in forms:
        spec = parse_model_text(text)
        assert spec.defaults == {"m1": 2.0, "I1": 0.2}, text
        assert all(type(v) is float for v in spec.defaults.values())


def test_accepted_unit_spellings():
    for key, unit in [("K1", "N m/rad"), ("K1", "N*m/rad"), ("K1", "Nm/rad"), ("K1", "N m rad^-1"),
                      ("Bm1", "N m s/rad"), ("Bm1", "N·m·s/rad"), ("g0", "m/s^2"), ("g0", "m s^-2"),
                      ("g0", "m/s²"), ("Jm1", "kg m^2"), ("l1", "m"), ("r1", "m")]:
        text = f'[model]\nname = "a"\nlinks = 1\n[parameters]\n{key} = {{ default = 0.7, unit = "{unit}" }}\n'
        assert parse_model_text(text).defaults[key] == 0.7, unit


# ---- key locations ----------------------------------------------------------------------------

def test_locate_keys_handles_tables_dotted_quoted_inline_and_multiline():
    text = textwrap.dedent('''\
        # m1 = 1 in a comment
        top.a = 1                          # line 2
        s = """
        [parameters]
        m1 = 5
        """
        lit = \'\'\'x = 1
        [model]\'\'\'
        arr = [
          1, # m2 = 3
          "]",
          { k = 1 },
        ]
        [ parameters . "m1" ]              # line 14
        default = 2.0                      # line 15
        [model]
        name = "x"                         # line 17
        [parameters]
        'K1' = { default = 1.0, unit = "N m/rad" }
        m2.default = 3                     # line 20
        "weird key" = 1
        ''').replace("\n", "\r\n")
    lines = locate_keys(text)
    assert lines[("top",)] == 2 and lines[("top", "a")] == 2
    assert lines[("s",)] == 3 and lines[("lit",)] == 7 and lines[("arr",)] == 9
    assert lines[("parameters",)] == 14 and lines[("parameters", "m1")] == 14
    assert lines[("parameters", "m1", "default")] == 15
    assert lines[("model",)] == 16 and lines[("model", "name")] == 17
    assert lines[("parameters", "K1")] == 19 and lines[("parameters", "K1", "unit")] == 19
    assert lines[("parameters", "m2")] == 20 and lines[("parameters", "m2", "default")] == 20
    assert lines[("parameters", "weird key")] == 21
    assert ("m1",) not in lines and ("parameters", "m2", "k") not in lines and ("x",) not in lines


# ---- error paths ------------------------------------------------------------------------------

HEAD = '[model]\nname = "arm"\nlinks = 3\n'  # lines 1-3

ERRORS = [
    # (id, text, key (None: syntax error), line, fragment of the message)
    ("syntax-value", HEAD + "[parameters]\nm1 = 2.0 kg\n", None, 5, "TOML syntax error"),
    ("syntax-string", '[model]\nname = "arm\nlinks = 3\n', None, 2, "TOML syntax error"),
    ("syntax-duplicate", HEAD + "links = 4\n", None, 4, "TOML syntax error"),
    ("syntax-header", HEAD + "[parameters\nm1 = 1\n", None, 4, "TOML syntax error"),
    ("unknown-top", HEAD + "\n[solver]\ntol = 1\n", "solver", 5, "unknown key"),
    ("unknown-top-name", 'name = "arm"\n' + HEAD, "name", 1, "under [model]"),
    ("unknown-model-key", HEAD + "nlinks = 3\n", "model.nlinks", 4, "unknown key"),
    ("unknown-param", HEAD + "[parameters]\nm1 = 1.0\nm4 = 1.0\n", "parameters.m4", 6, "3-link chain"),
    ("unknown-param-typo", HEAD + "[parameters]\nJm_1 = 1.0\n", "parameters.Jm_1", 5, "unknown parameter"),
    ("unknown-param-key", HEAD + '[parameters.m1]\ndefault = 1.0\nunits = "kg"\n',
     "parameters.m1.units", 6, "did you mean 'unit'"),
    ("type-links-str", '[model]\nname = "arm"\nlinks = "3"\n', "model.links", 3, "expected an integer"),
    ("type-links-float", '[model]\nname = "arm"\nlinks = 3.0\n', "model.links", 3, "expected an integer"),
    ("type-links-bool", '[model]\nname = "arm"\nlinks = true\n', "model.links", 3, "got boolean"),
    ("type-name", '[model]\nname = 3\nlinks = 3\n', "model.name", 2, "expected a string"),
    ("type-model", 'model = "arm"\n', "model", 1, "expected a table"),
    ("type-params", 'parameters = [1, 2]\n' + HEAD, "parameters", 1, "expected a table"),
    ("type-value", HEAD + '[parameters]\nm1 = "2.0"\n', "parameters.m1", 5, "expected a number"),
    ("type-value-array", HEAD + '[parameters]\n\nm1 = [\n  1.0,\n]\n', "parameters.m1", 6, "got an array"),
    ("type-default", HEAD + '[parameters]\nK1 = { default = "150", unit = "N m/rad" }\n',
     "parameters.K1.default", 5, "expected a number"),
    ("type-unit", HEAD + '[parameters]\nK1 = { default = 150, unit = 1 }\n', "parameters.K1.unit", 5,
     "expected a string"),
    ("type-description", HEAD + "description = 1\n", "model.description", 4, "expected a string"),
    ("links-zero", '[model]\nname = "arm"\nlinks = 0\n', "model.links", 3, "out of range"),
    ("links-eight", '[model]\nname = "arm"\n\nlinks = 8\n', "model.links", 4, "expected 1..7"),
    ("links-negative", '[model]\nname = "arm"\nlinks = -2\n', "model.links", 3, "out of range"),
    ("mass-negative", HEAD + "[parameters]\nm2 = -1.0\n", "parameters.m2", 5, "must be > 0"),
    ("length-zero", HEAD + "[parameters]\nl3 = 0\n", "parameters.l3", 5, "must be > 0"),
    ("inertia-zero", HEAD + "[parameters.I1]\ndefault = 0.0\n", "parameters.I1.default", 5, "must be > 0"),
    ("stiffness-negative", HEAD + "[parameters]\nK1 = -150\n", "parameters.K1", 5, "must be > 0"),
    ("motor-inertia-zero", HEAD + "[parameters]\nJm2 = 0.0\n", "parameters.Jm2", 5, "must be > 0"),
    ("com-zero", HEAD + "[parameters]\nr1 = 0.0\n", "parameters.r1", 5, "must be > 0"),
    ("damping-negative", HEAD + "[parameters]\nBm1 = -0.1\n", "parameters.Bm1", 5, "must be >= 0"),
    ("gravity-negative", HEAD + "[parameters]\ng0 = -9.8\n", "parameters.g0", 5, "must be >= 0"),
    ("nan", HEAD + "[parameters]\nm1 = nan\n", "parameters.m1", 5, "not finite"),
    ("inf", HEAD + "[parameters]\nK2 = inf\n", "parameters.K2", 5, "not finite"),
    ("dotted-top-level", "parameters.m1 = -2.0\n" + HEAD, "parameters.m1", 1, "must be > 0"),
    ("dotted-in-table", HEAD + "[parameters]\nm1.default = -2.0\n", "parameters.m1.default", 5, "> 0"),
    ("r-greater-l", HEAD + "[parameters]\nl2 = 0.8\nr2 = 0.9\n", "parameters.r2", 6, "r2 <= l2"),
    ("r-greater-default-l", HEAD + "[parameters]\nr2 = 1.5\n", "parameters.r2", 5, "(default)"),
    ("l-less-default-r", HEAD + "[parameters]\nl2 = 0.3\n", "parameters.l2", 5, "set r2 too"),
    ("unit-grams", HEAD + '[parameters]\nm1 = { default = 2000.0, unit = "g" }\n', "parameters.m1.unit", 5,
     "SI units"),
    ("unit-degrees", HEAD + '[parameters.K1]\ndefault = 2.6\nunit = "N m/deg"\n', "parameters.K1.unit", 6,
     "'N m/rad'"),
    ("unit-wrong-quantity", HEAD + '[parameters]\nl1 = { default = 1.0, unit = "kg" }\n',
     "parameters.l1.unit", 5, "'m'"),
    ("missing-model", "[parameters]\nm1 = 1.0\n", "model", 1, "missing required table"),
    ("missing-links", '\n[model]\nname = "arm"\n', "model.links", 2, "missing required key"),
    ("missing-name", '[parameters]\nm1 = 1.0\n[model]\nlinks = 2\n', "model.name", 3, "missing required key"),
    ("missing-default", HEAD + '[parameters]\n\n[parameters.m1]\nunit = "kg"\n', "parameters.m1.default",
     6, "missing required key"),
    ("name-invalid", '[model]\nname = "3-arm"\nlinks = 3\n', "model.name", 2, "C identifier"),
    ("name-builtin", '[model]\nname = "planar3"\nlinks = 3\n', "model.name", 2, "built-in"),
    ("name-builtin-case", '[model]\nname = "Link1"\nlinks = 1\n', "model.name", 2, "built-in"),
    ("name-reserved", '[model]\nname = "casadi_arm"\nlinks = 1\n', "model.name", 2, "reserved"),
    ("description-comment", HEAD + 'description = "ends a C comment */ here"\n', "model.description", 4,
     "C comments"),
    ("description-newline", HEAD + 'description = """two\nlines"""\n', "model.description", 4, "one"),
]


@pytest.mark.parametrize("text,key,line,fragment", [e[1:] for e in ERRORS], ids=[e[0] for e in ERRORS])
def test_bad_file_names_key_and_line(text, key, line, fragment):
    with pytest.raises(ModelFileError) as info:
        parse_model_text(text, source="arm.toml")
    err = info.value
    msg = str(err)
    assert isinstance(err, ValueError)
    assert err.line == line, msg
    assert fragment in msg, msg
    if key is None:  # syntax errors carry tomllib's line and column
        assert err.column is not None and msg.startswith(f"arm.toml:{line}:{err.column}: "), msg
    else:
        assert err.key == key, msg
        assert msg.startswith(f"arm.toml:{line}: {key}: "), msg


def test_not_utf8(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_bytes(b'[model]\nname = "arm"\ndescription = "caf\xe9"\n')
    with pytest.raises(ModelFileError, match=r"bad\.toml:3: not UTF-8"):
        load_model_file(path)


# ---- command line -----------------------------------------------------------------------------

def test_cli_bad_file_exits_2_and_leaves_out_untouched(tmp_path, capsys):
    out = tmp_path / "out"
    (out / "keep").mkdir(parents=True)
    (out / "keep" / "manifest.json").write_text("{}\n")
    bad = tmp_path / "bad.toml"
    bad.write_text(HEAD + "[parameters]\nr2 = 2.0\n")
    assert derive_main(["--model-file", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}:5: parameters.r2:" in err
    assert tree_bytes(out) == {"keep/manifest.json": b"{}\n"}


def test_cli_keeps_other_models_in_out(tmp_path):
    out = tmp_path / "out"
    (out / "keep").mkdir(parents=True)
    (out / "keep" / "manifest.json").write_text("{}\n")
    path = tmp_path / "one.toml"
    path.write_text('[model]\nname = "one"\nlinks = 1\n')
    assert derive_main(["--model-file", str(path), "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["keep", "one"]
    assert not list(tmp_path.glob(".out-tmp-*"))


def test_cli_model_file_needs_out_and_existing_file(tmp_path, capsys):
    with pytest.raises(SystemExit) as info:
        derive_main(["--model-file", str(EXAMPLE)])
    assert info.value.code == 2 and "--out" in capsys.readouterr().err
    assert derive_main(["--model-file", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "o")]) == 2
    assert "nope.toml" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_fjm_derive_without_sympy_says_how_to_install():
    code = ("import sys; sys.modules['sympy'] = None\n"
            "from fjm_runtime.cli.main import main\n"
            "sys.exit(main(['derive', '--model-file', 'arm.toml', '--out', 'x']))\n")
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert ".[derive]" in proc.stderr and "sympy" in proc.stderr


def test_runtime_cli_does_not_import_sympy():
    code = ("import sys, fjm_runtime, fjm_runtime.cli.main\n"
            "assert 'sympy' not in sys.modules and 'derive' not in sys.modules\n")
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
