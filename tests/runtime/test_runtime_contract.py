"""The runtime contract of the README's Python API section: load(), shapes, p as array or dict, errors."""

import subprocess
import sys

import numpy as np
import pytest

import fjm_runtime
from support.numerics import ALL_MODELS


@pytest.mark.parametrize("name", ALL_MODELS)
def test_shapes_and_param_forms(name):
    m = fjm_runtime.load(name)
    n = m.n
    assert m.nx == 4 * n
    assert isinstance(m.param_names, tuple) and len(m.param_names) == len(m.default_params)
    assert list(m.default_params) == list(m.param_names)
    x = np.linspace(-0.5, 0.5, m.nx)
    p_arr = np.array([m.default_params[k] for k in m.param_names])
    shapes = {"f": (4 * n,), "g": (4 * n, n), "ad": (4 * n, 4 * n), "T": (4 * n,),
              "alpha": (n,), "beta": (n, n)}
    for q, shape in shapes.items():
        a = getattr(m, q)(x, p_arr)
        b = getattr(m, q)(x, m.default_params)
        c = getattr(m, q)(list(x), {})  # empty dict -> all defaults
        assert isinstance(a, np.ndarray) and a.shape == shape, q
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)


def test_link1_defaults_are_the_papers_table_1():
    m = fjm_runtime.load("link1")
    assert m.param_names == ("J_l", "J_m", "K", "M", "g0", "L", "B_m")
    assert m.default_params == {"J_l": 1.0, "J_m": 2.0, "K": 150.0, "M": 1.0, "g0": 9.8, "L": 1.0, "B_m": 0.0}


def test_planar_parameter_names_follow_the_group_order():
    m = fjm_runtime.load("planar3")
    groups = ["m", "l", "r", "I", "K", "Jm", "Bm"]
    assert m.param_names == tuple(f"{g}{i}" for g in groups for i in (1, 2, 3)) + ("g0",)


def test_dict_params_override_only_given_keys():
    m = fjm_runtime.load("link1")
    x = np.array([0.3, 0.1, 0.2, 0.0])
    assert m.beta(x, {"K": 100.0})[0, 0] == pytest.approx(1.0 * 2.0 / 100.0)


@pytest.mark.parametrize("bad, fragment", [
    ("planar8", "available models"),
    ("", "available models"),
    ("LINK1", "link1"),
])
def test_unknown_model_lists_available(bad, fragment):
    with pytest.raises(ValueError, match=fragment):
        fjm_runtime.load(bad)


def assert_message(exc_info, fragments):
    """The message names the argument, the bad value and the expectation (each fragment present)."""
    msg = str(exc_info.value)
    missing = [f for f in fragments if f not in msg]
    assert not missing, f"message lacks {missing}: {msg}"


@pytest.mark.parametrize("x, fragments", [
    (np.zeros(3), ["x", "(3,)", "(4,)"]),
    (np.zeros((2, 4)), ["x", "(2, 4)", "(4,)"]),
    (np.array([0, np.nan, 0, 0]), ["x", "entry 1", "nan", "finite"]),
    (np.array([0, 0, np.inf, 0]), ["x", "entry 2", "inf", "finite"]),
    ("abc", ["x", "'abc'", "numeric"]),
])
def test_bad_state_is_named(x, fragments):
    m = fjm_runtime.load("link1")
    with pytest.raises(ValueError) as info:
        m.alpha(x, None)
    assert_message(info, fragments)


@pytest.mark.parametrize("p, fragments", [
    (np.ones(6), ["p", "(6,)", "(7,)"]),
    ({"k": 1.0}, ["p", "'k'", "unknown", "'K'"]),
    ({"K": float("nan")}, ["p", "'K'", "nan", "finite"]),
    ({"K": -1.0}, ["p", "'K'", "-1.0", "> 0"]),
    ({"J_m": 0.0}, ["p", "'J_m'", "0.0", "> 0"]),
    ({"B_m": -0.1}, ["p", "'B_m'", "-0.1", ">= 0"]),
    ({"K": "stiff"}, ["p", "'K'", "'stiff'", "number"]),
])
def test_bad_params_are_named(p, fragments):
    m = fjm_runtime.load("link1")
    with pytest.raises(ValueError) as info:
        m.f(np.zeros(4), p)
    assert_message(info, fragments)


def test_centre_of_mass_must_lie_on_the_link():
    m = fjm_runtime.load("planar2")
    with pytest.raises(ValueError) as info:
        m.f(np.zeros(8), {"r2": 1.5})
    assert_message(info, ["p", "'r2'", "1.5", "l2", "1.0"])


def test_runtime_never_imports_sympy():
    code = ("import sys, numpy as np, fjm_runtime as f; m = f.load('planar7'); "
            "m.alpha(np.full(28, 0.1), m.default_params); m.ad(np.full(28, 0.1)); "
            "import fjm_runtime.sim.simulate; "
            "assert 'sympy' not in sys.modules, 'sympy imported'")
    subprocess.run([sys.executable, "-c", code], check=True)
