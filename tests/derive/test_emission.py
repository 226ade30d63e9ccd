"""Emission layer: CSE preserves values, unbound symbols are refused, LDL^T solves are exact."""

import casadi as ca
import numpy as np
import pytest
import sympy as sp

from derive.emit.functions import QUANTITIES, build_functions
from derive.emit.ldl import ldl_factor, ldl_solve, spd_inverse, symmetric_inverse
from derive.emit.sx import SympyToSX, skew_congruence
from derive.core.linearize import linearize
from derive.registry import build


@pytest.mark.parametrize("name", ["link1", "planar3"])
def test_cse_equals_no_cse(name):
    lin = linearize(build(name))
    with_cse = build_functions(lin)
    lin = linearize(build(name))
    without = build_functions(lin, cse=False)
    rng = np.random.default_rng(0)
    p = [q.default for q in lin.model.params]
    for _ in range(3):
        x = rng.uniform(-1, 1, 4 * lin.model.n)
        for q, _ in QUANTITIES:
            a, b = np.array(with_cse[q](x, p)), np.array(without[q](x, p))
            np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13, err_msg=q)


def test_unbound_symbol_is_refused_with_its_name():
    x = ca.SX.sym("x")
    conv = SympyToSX({sp.Symbol("a"): x})
    with pytest.raises(ValueError, match="free symbol b is not bound"):
        conv(sp.Symbol("a") + sp.Symbol("b"))


def test_unsupported_node_is_refused():
    conv = SympyToSX({sp.Symbol("a"): ca.SX.sym("a")})
    with pytest.raises(ValueError, match="cannot emit"):
        conv(sp.log(sp.Symbol("a")))


def test_friction_nodes_evaluate_as_sympy_does():
    """tanh and exp (the motor friction of derive/core/friction.py) convert to the same numbers."""
    a = sp.Symbol("a")
    x = ca.SX.sym("x")
    e = (0.8 + 0.4 * sp.exp(-(a / 0.3) ** 2)) * sp.tanh(a / 0.05)
    fn = ca.Function("e", [x], [SympyToSX({a: x})(e)])
    for v in (-1.3, -0.01, 0.0, 0.02, 2.5):
        assert abs(float(fn(v)) - float(e.subs(a, v))) < 1e-15


def test_ldl_solve_and_inverse_match_numpy():
    rng = np.random.default_rng(1)
    for n in (1, 3, 7):
        B = rng.normal(size=(n, n))
        A = B @ B.T + n * np.eye(n)
        b = rng.normal(size=n)
        factors = ldl_factor(ca.SX(ca.DM(A)))
        x = np.array(ca.evalf(ldl_solve(factors, ca.SX(ca.DM(b))))).ravel()
        np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-12)
        Ainv = np.array(ca.evalf(spd_inverse(factors)))
        np.testing.assert_allclose(Ainv, np.linalg.inv(A), rtol=1e-11, atol=1e-13)
        np.testing.assert_allclose(np.array(ca.evalf(symmetric_inverse(factors))), np.linalg.inv(A),
                                   rtol=1e-11, atol=1e-13)


def test_skew_congruence_is_W_M_W_and_costs_less_than_the_dense_products():
    from derive.emit.functions import operation_count
    rng = np.random.default_rng(2)
    for n in (1, 2, 5):
        W = rng.normal(size=(n, n))
        W = W + W.T
        M = rng.normal(size=(n, n))
        M = M - M.T
        Z = np.array(ca.evalf(skew_congruence(ca.SX(ca.DM(W)), ca.SX(ca.DM(M)))))
        np.testing.assert_allclose(Z, W @ M @ W, rtol=1e-12, atol=1e-12)
    w, m = ca.SX.sym("W", 7, 7), ca.SX.sym("M", 7, 7)
    dense = operation_count(ca.Function("d", [w, m], [ca.mtimes(w, ca.mtimes(m, w))]))
    skew = operation_count(ca.Function("s", [w, m], [skew_congruence(w, m)]))
    assert skew < 0.8 * dense, (skew, dense)


def test_derivative_shortcuts_equal_plain_differentiation():
    """Program rules (d cos(a) = -sin(a) da ...) == differentiating the definitions."""
    from derive.core.program import Program
    fast = build_functions(linearize(build("planar3")))
    Program.use_rules = False
    try:
        plain = build_functions(linearize(build("planar3")))
    finally:
        Program.use_rules = True
    rng = np.random.default_rng(5)
    p = [q.default for q in build("planar3").params]
    for _ in range(3):
        x = rng.uniform(-1.5, 1.5, 12)
        for q, _ in QUANTITIES:
            np.testing.assert_allclose(np.array(fast[q](x, p)), np.array(plain[q](x, p)),
                                       rtol=1e-12, atol=1e-12, err_msg=q)
    assert sum(int(f.n_instructions()) for f in fast.values()) < sum(int(f.n_instructions()) for f in plain.values())
