"""Property-based tests (Hypothesis) of the runtime's input validation.

Every bad ``x`` / ``p`` / ``u`` / model name must raise :class:`FjmValueError`
(a ``ValueError``) whose message names the offending argument (and, for
parameters, the parameter), the bad value and what was expected; every valid
input must evaluate without raising.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

import fjm_runtime
from fjm_runtime import FjmValueError

MODELS = {name: fjm_runtime.load(name) for name in ("link1", "planar2", "planar3")}
QUANTITIES = ("f", "g", "ad", "T", "alpha", "beta")

PROPS = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])

model_st = st.sampled_from(sorted(MODELS))
quantity_st = st.sampled_from(QUANTITIES)
finite = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False)
non_finite = st.sampled_from([math.nan, math.inf, -math.inf])


def names_arg(message: str, arg: str) -> bool:
    """True if ``arg`` appears in ``message`` as a word (``x:``, ``p['m1']``, ...)."""
    return re.search(rf"(^|[^A-Za-z0-9_]){re.escape(arg)}([^A-Za-z0-9_]|$)", message) is not None


def call(model, quantity, x, p):
    return getattr(model, quantity)(x, p)


def expect_error(fn, *args, arg: str, also=()):
    with pytest.raises(FjmValueError) as info:
        fn(*args)
    msg = str(info.value)
    assert isinstance(info.value, ValueError)
    assert names_arg(msg, arg), f"message does not name {arg!r}: {msg}"
    for word in also:
        assert word in msg, f"message does not mention {word!r}: {msg}"
    return msg


# --- physical parameter sets ------------------------------------------------------------------

# The physical range follows from what a parameter IS (its SI unit in the manifest), as the
# README states it: masses, lengths, inertias and stiffnesses > 0; damping and gravity >= 0.
RANGE_BY_UNIT = {"kg": "positive", "m": "positive", "kg m^2": "positive", "N m/rad": "positive",
                 "N m s/rad": "non-negative", "m/s^2": "non-negative"}


def physical_range(model, name: str) -> str:
    unit = {q["name"]: q["unit"] for q in model.manifest["parameters"]}[name]
    if unit not in RANGE_BY_UNIT:  # pragma: no cover - a new kind of parameter: make the test say so
        raise AssertionError(f"test does not know the physical range of {name!r} [{unit}]")
    return RANGE_BY_UNIT[unit]


def positive_names(model):
    return [k for k in model.param_names if physical_range(model, k) == "positive"]


def non_negative_names(model):
    return [k for k in model.param_names if physical_range(model, k) == "non-negative"]


@st.composite
def valid_params(draw, model):
    """A physically valid parameter dict for ``model`` (all keys)."""
    p = {}
    for name in model.param_names:
        low = 1e-2 if physical_range(model, name) == "positive" else 0.0
        p[name] = draw(st.floats(min_value=low, max_value=1e2))
    for name in model.param_names:  # centre of mass on the link: r_i <= l_i
        if re.fullmatch(r"r\d+", name):
            frac = draw(st.floats(min_value=1e-3, max_value=1.0))
            p[name] = p["l" + name[1:]] * frac
    return p


# --- valid inputs never raise -----------------------------------------------------------------

@PROPS
@given(data=st.data(), name=model_st, quantity=quantity_st)
def test_valid_inputs_never_raise(data, name, quantity):
    m = MODELS[name]
    x = np.array(data.draw(st.lists(finite, min_size=m.nx, max_size=m.nx)))
    p = data.draw(valid_params(m))
    as_array = data.draw(st.booleans())
    if as_array:
        pv = np.array([p[k] for k in m.param_names])
    else:  # a dict may omit keys: they take their defaults
        keep = data.draw(st.sets(st.sampled_from(m.param_names)))
        pv = {k: v for k, v in p.items() if k in keep}
        if name != "link1":  # defaults mixed in must still have r_i <= l_i
            full = {**m.default_params, **pv}
            assume(all(full[f"r{i}"] <= full[f"l{i}"] for i in range(1, m.n + 1)))
    out = np.asarray(call(m, quantity, x, pv))
    expected = {"f": (m.nx,), "g": (m.nx, m.n), "ad": (m.nx, m.nx), "T": (m.nx,),
                "alpha": (m.n,), "beta": (m.n, m.n)}[quantity]
    assert out.shape == expected


@PROPS
@given(data=st.data(), name=model_st)
def test_valid_u_never_raises(data, name):
    m = MODELS[name]
    x = data.draw(st.lists(finite, min_size=m.nx, max_size=m.nx))
    u = data.draw(st.lists(finite, min_size=m.n, max_size=m.n))
    assert m.xdot(x, u).shape == (m.nx,)


# --- x --------------------------------------------------------------------------------------

@PROPS
@given(data=st.data(), name=model_st, quantity=quantity_st)
def test_x_wrong_length(data, name, quantity):
    m = MODELS[name]
    n = data.draw(st.integers(min_value=0, max_value=4 * m.nx).filter(lambda k: k != m.nx))
    x = data.draw(st.lists(finite, min_size=n, max_size=n))
    msg = expect_error(call, m, quantity, x, None, arg="x", also=(f"({m.nx},)",))
    assert f"({n},)" in msg, msg  # the shape that was given


@PROPS
@given(data=st.data(), name=model_st)
def test_x_wrong_ndim(data, name):
    m = MODELS[name]
    shape = data.draw(st.lists(st.integers(min_value=2, max_value=5), min_size=2, max_size=3))
    x = np.zeros(shape)
    expect_error(m.alpha, x, None, arg="x", also=(f"({m.nx},)",))


@PROPS
@given(data=st.data(), name=model_st, quantity=quantity_st, bad=non_finite)
def test_x_non_finite(data, name, quantity, bad):
    m = MODELS[name]
    x = data.draw(st.lists(finite, min_size=m.nx, max_size=m.nx))
    i = data.draw(st.integers(min_value=0, max_value=m.nx - 1))
    x[i] = bad
    msg = expect_error(call, m, quantity, x, None, arg="x", also=("finite",))
    assert str(bad) in msg, msg


@PROPS
@given(name=model_st, junk=st.one_of(st.text(alphabet="abc xyz", min_size=1, max_size=5), st.none(),
                                     st.just({"a": 1}), st.just([1.0, 2.0])))
def test_x_not_numeric(name, junk):
    m = MODELS[name]
    expect_error(m.alpha, [junk] * m.nx, None, arg="x")


@PROPS
@given(name=model_st, number=finite)
def test_x_numeric_strings_rejected(name, number):
    """Strings are not numbers: ``p={'m1': '1.0'}`` is rejected, so ``x=['1.0', ...]`` must be too."""
    m = MODELS[name]
    expect_error(m.alpha, [repr(number)] * m.nx, None, arg="x")
    p = [repr(m.default_params[k]) for k in m.param_names]
    expect_error(m.alpha, np.zeros(m.nx), p, arg="p")


@PROPS
@given(data=st.data(), name=model_st, quantity=quantity_st, imag=st.floats(min_value=-1e3, max_value=1e3,
                                                                          allow_nan=False, allow_infinity=False))
def test_complex_x_and_p_rejected(data, name, quantity, imag):
    """A complex ``x`` or ``p`` is refused (even with a zero imaginary part): the imaginary part is never dropped."""
    m = MODELS[name]
    x = np.array(data.draw(st.lists(finite, min_size=m.nx, max_size=m.nx)), dtype=complex)
    i = data.draw(st.integers(min_value=0, max_value=m.nx - 1))
    x[i] += 1j * imag
    msg = expect_error(call, m, quantity, x, None, arg="x", also=("real",))
    assert "complex" in msg, msg
    p = m.params_array().astype(complex)
    msg = expect_error(call, m, quantity, np.zeros(m.nx), p, arg="p", also=("real",))
    k = data.draw(st.sampled_from(m.param_names))
    expect_error(call, m, quantity, np.zeros(m.nx), {k: complex(m.default_params[k], imag)}, arg="p",
                 also=(k, "real"))


def test_complex_x_example():
    m = MODELS["link1"]
    with pytest.raises(FjmValueError, match=r"x: expected a real array of shape \(4,\)"):
        m.alpha(np.array([1j, 0, 0, 0]), m.default_params)


# --- p as an array ---------------------------------------------------------------------------

@PROPS
@given(data=st.data(), name=model_st)
def test_p_array_wrong_length(data, name):
    m = MODELS[name]
    k = len(m.param_names)
    n = data.draw(st.integers(min_value=0, max_value=3 * k).filter(lambda j: j != k))
    p = data.draw(st.lists(st.floats(min_value=0.1, max_value=10), min_size=n, max_size=n))
    expect_error(m.f, np.zeros(m.nx), p, arg="p", also=(f"({k},)",))


@PROPS
@given(data=st.data(), name=model_st, bad=non_finite)
def test_p_array_non_finite(data, name, bad):
    m = MODELS[name]
    p = np.array([m.default_params[k] for k in m.param_names])
    i = data.draw(st.integers(min_value=0, max_value=len(p) - 1))
    p[i] = bad
    msg = expect_error(m.f, np.zeros(m.nx), p, arg="p", also=("finite",))
    assert str(bad) in msg, msg


# --- p as a dict -----------------------------------------------------------------------------

@PROPS
@given(data=st.data(), name=model_st)
def test_p_dict_unknown_key(data, name):
    m = MODELS[name]
    key = data.draw(st.text(alphabet="abcdefgxyzKLMr_0123456789", min_size=1, max_size=6)
                    .filter(lambda s: s not in m.param_names))
    p = {key: 1.0}
    if data.draw(st.booleans()):
        p[data.draw(st.sampled_from(m.param_names))] = 1.0
    msg = expect_error(m.alpha, np.zeros(m.nx), p, arg="p", also=(repr(key),))
    assert "expected" in msg


@PROPS
@given(data=st.data(), name=model_st, bad=non_finite)
def test_p_dict_non_finite(data, name, bad):
    m = MODELS[name]
    key = data.draw(st.sampled_from(m.param_names))
    msg = expect_error(m.alpha, np.zeros(m.nx), {key: bad}, arg="p", also=("finite",))
    assert str(bad) in msg, msg
    assert key in msg, f"the message should name the parameter {key!r}: {msg}"


@PROPS
@given(data=st.data(), name=model_st, junk=st.one_of(st.text(max_size=4), st.none(), st.lists(finite, max_size=2)))
def test_p_dict_not_a_number(data, name, junk):
    m = MODELS[name]
    key = data.draw(st.sampled_from(m.param_names))
    expect_error(m.alpha, np.zeros(m.nx), {key: junk}, arg="p", also=(key,))


@PROPS
@given(data=st.data(), name=model_st)
def test_p_non_positive(data, name):
    """Masses, lengths, inertias, stiffnesses, motor inertias <= 0 are rejected, naming the parameter."""
    m = MODELS[name]
    key = data.draw(st.sampled_from(positive_names(m)))
    value = data.draw(st.floats(max_value=0.0, min_value=-1e6))
    as_array = data.draw(st.booleans())
    p = {**m.default_params, key: value}
    pv = np.array([p[k] for k in m.param_names]) if as_array else {key: value}
    msg = expect_error(m.beta, np.zeros(m.nx), pv, arg="p", also=(key, "> 0"))
    assert str(value) in msg, msg  # the bad value


@PROPS
@given(data=st.data(), name=model_st)
def test_p_negative_damping_or_gravity(data, name):
    m = MODELS[name]
    key = data.draw(st.sampled_from(non_negative_names(m)))
    value = data.draw(st.floats(max_value=-1e-9, min_value=-1e6))
    expect_error(m.f, np.zeros(m.nx), {key: value}, arg="p", also=(key, str(value), ">= 0"))


def test_every_parameter_has_a_known_physical_range():
    """The unit table above covers every parameter; the README's groups come out as stated."""
    m = MODELS["link1"]
    assert positive_names(m) == ["J_l", "J_m", "K", "M", "L"]
    assert non_negative_names(m) == ["g0", "B_m"]
    for name in ("planar2", "planar3"):
        model = MODELS[name]
        assert len(positive_names(model)) + len(non_negative_names(model)) == len(model.param_names)
        assert {k.rstrip("0123456789") for k in non_negative_names(model)} == {"Bm", "g"}


@PROPS
@given(data=st.data(), name=st.sampled_from(["planar2", "planar3"]))
def test_p_centre_of_mass_beyond_link(data, name):
    m = MODELS[name]
    i = data.draw(st.integers(min_value=1, max_value=m.n))
    length = data.draw(st.floats(min_value=0.1, max_value=10))
    excess = data.draw(st.floats(min_value=1e-6, max_value=10))
    p = {f"l{i}": length, f"r{i}": length * (1 + excess)}
    expect_error(m.alpha, np.zeros(m.nx), p, arg="p", also=(f"r{i}", f"l{i}", str(p[f"r{i}"]), str(length)))


# --- u and model names -----------------------------------------------------------------------

@PROPS
@given(data=st.data(), name=model_st)
def test_u_wrong_length_or_non_finite(data, name):
    m = MODELS[name]
    if data.draw(st.booleans()):
        n = data.draw(st.integers(min_value=0, max_value=3 * m.n + 2).filter(lambda k: k != m.n))
        u = data.draw(st.lists(finite, min_size=n, max_size=n))
        expect_error(m.xdot, np.zeros(m.nx), u, arg="u", also=(f"({m.n},)",))
    else:
        u = [0.0] * m.n
        u[data.draw(st.integers(min_value=0, max_value=m.n - 1))] = data.draw(non_finite)
        expect_error(m.xdot, np.zeros(m.nx), u, arg="u", also=("finite",))


@PROPS
@given(name=st.one_of(st.text(max_size=12), st.integers(), st.none()))
@example(name="/")  # a path separator: a model directory, not a name (found by hypothesis)
@example(name="no_such_model")
def test_unknown_model_lists_available(name):
    assume(name not in fjm_runtime.available_models())
    with pytest.raises(ValueError) as info:
        fjm_runtime.load(name)
    msg = str(info.value)
    if isinstance(name, str) and (os.sep in name or (os.altsep and os.altsep in name)):
        # a name with a path separator is a model directory (fjm_runtime.load): the error names it
        assert "manifest.json" in msg and repr(str(Path(name).resolve()) if Path(name).is_dir() else name) in msg, msg
        return
    for known in ("link1", "planar1", "planar7"):
        assert known in msg, msg
