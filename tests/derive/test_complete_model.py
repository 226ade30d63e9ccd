"""The complete elastic model: the reduced limit, link1's S = 0, energy balance, the bracket test.

* With every spin coupling and carried inertia zero (rotor mass and transverse
  inertia 0, built at derive time; N = 1e14 at run time) the complete model's
  f and g equal the reduced model's (elbow3, planar2) to 1e-12.
* link1_complete: S = 0 and f, g are link1's exactly (its rotor rides on the base).
* Energy balance: dE/dt along f + g u equals dq_m . u - B_m dq_m^2 (the gyroscopic
  terms do no work), by CasADi AD of the emitted energy.
* The paper's bracket test (rank of [g, .., ad_f^3 g], involutivity of the first
  three) on emitted f and g: static FL holds for link1_complete, fails for
  planar2_complete (constant S) and panda_complete; the same routine finds the
  reduced planar2 involutive (so it can tell the two apart).
"""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

import fjm_runtime
from derive.emit.complete import build_complete_functions
from derive.emit.report import complete_brackets, static_fl_verdict
from derive.core.linearize import linearize
from derive.model_file import load_model_file
from derive.planar.planar import make_planar
from derive.registry import ROBOTS
from derive.core.rotors import Rotors
from fjm_runtime.validation import FjmValueError

from support.numerics import random_state

BIG = 1e14


def _limit_model(name):
    zero = lambda n: Rotors((BIG,) * n, (0.0,) * n, (0.0,) * n)
    if name == "planar2":
        m = make_planar(2, name="planar2_limit", rotors=zero(2), reduced_model="planar2")
    else:
        spec = load_model_file(ROBOTS / name / f"{name}.toml", builtin=True)
        m = replace(spec, name=f"{name}_limit", rotors=zero(len(spec.joints)), reduced_model=name).build()
    return build_complete_functions(linearize(m))


@pytest.mark.parametrize("name", ["planar2", "elbow3"])
def test_zero_coupling_is_the_reduced_model(name):
    fns = _limit_model(name)
    red = fjm_runtime.load(name)
    rng = np.random.default_rng(3)
    for _ in range(5):
        p = {k: v * rng.uniform(0.7, 1.4) for k, v in red.default_params.items()}
        pc = np.array([p[k] for k in red.param_names] + [BIG] * red.n)
        x = random_state(red, rng)
        for q, ref in (("f", red.f(x, p)), ("g", red.g(x, p))):
            val = np.array(fns[q](x, pc)).reshape(ref.shape, order="F")
            assert np.max(np.abs(val - ref)) <= 1e-12 * np.max(np.abs(ref)), q
    # and at a finite gear ratio the coupling is really there
    pc[-red.n:] = 10.0
    assert np.max(np.abs(np.array(fns["g"](x, pc))[:red.n * 2])) > 1e-6


def test_link1_complete_has_no_coupling():
    mc, m = fjm_runtime.load("link1_complete"), fjm_runtime.load("link1")
    rng = np.random.default_rng(5)
    for _ in range(5):
        x = random_state(m, rng)
        p = dict(m.default_params)
        assert np.all(mc.coupling(x) == 0)
        assert np.array_equal(mc.f(x, {**p, "N1": rng.uniform(1, 100)}), m.f(x, p))
        assert np.array_equal(mc.g(x), m.g(x))


@pytest.mark.parametrize("name", ["planar2_complete", "panda_complete"])
def test_energy_balance(name):
    m = fjm_runtime.load(name)
    p = {**m.default_params, **{f"Bm{i}": 0.3 for i in range(1, m.n + 1)}}
    pv = m.params_array(p)
    xs = ca.SX.sym("x", m.nx)
    dE = ca.Function("dE", [xs], [ca.gradient(m.functions["energy"](xs, pv), xs)])
    rng = np.random.default_rng(11)
    for _ in range(4):
        x = random_state(m, rng)
        x[3 * m.n:] *= 30  # rotors spin fast
        u = rng.uniform(-5, 5, m.n)
        power = float(np.array(dE(x)).ravel() @ m.xdot(x, u, p))
        dqm = x[3 * m.n:]
        expected = dqm @ u - 0.3 * dqm @ dqm
        assert abs(power - expected) <= 1e-9 * max(1.0, abs(expected) + abs(dqm @ u))


def test_complete_model_refuses_static_fl_quantities():
    m = fjm_runtime.load("panda_complete")
    assert m.inertia(np.zeros(m.nx)).shape == (2 * m.n, 2 * m.n)
    for call in (lambda: m.T(np.zeros(m.nx)), lambda: m.alpha(np.zeros(m.nx)), lambda: m.controls):
        with pytest.raises(FjmValueError, match="reduced model 'panda'"):
            call()


def _verdict(name, samples):
    m = fjm_runtime.load(name)
    p = m.params_array()
    rows = complete_brackets(m.functions["f"], m.functions["g"], m.n, p, samples=samples, seed=1)
    return m.n, rows


def test_brackets_link1_complete_static_fl_exists():
    n, rows = _verdict("link1_complete", 3)
    assert static_fl_verdict(rows, n)


def test_brackets_planar2_reduced_involutive_complete_not():
    n, rows = _verdict("planar2", 3)
    assert static_fl_verdict(rows, n)
    n, rows = _verdict("planar2_complete", 3)
    assert all(r["rank4"] == 4 * n and r["rank3"] == 3 * n for r in rows)
    assert all(r["rank3_closed"] > 3 * n for r in rows)  # not involutive: no static FL
    assert all(r["gap"][1] > 1e3 * 1e-8 for r in rows)  # far from the threshold


@pytest.mark.slow
def test_brackets_panda_complete_not_involutive():
    n, rows = _verdict("panda_complete", 1)
    assert rows[0]["rank4"] == 4 * n and rows[0]["rank3"] == 3 * n
    assert rows[0]["rank3_closed"] > 3 * n
