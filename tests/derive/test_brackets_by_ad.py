"""The emitted bracket matrix (CasADi AD from f and g) against the symbolic brackets with D^-1 implicit.

Two independent constructions of ``[g, ad_f g, ad_f^2 g, ad_f^3 g]``: the SymPy derivation
(``brackets_implicit``, entries of D^-1 as symbols, bound to a numeric inverse here) and the emitted
Function (forward-mode AD over the SX of f). Both must agree at random states and parameters.
"""
import casadi as ca
import numpy as np
import pytest

from derive.emit.functions import build_functions
from derive.emit.ldl import ldl_factor, ldl_solve, spd_inverse
from derive.emit.sx import SympyToSX
from derive.core.linearize import linearize
from derive.registry import build


@pytest.mark.parametrize("name", ["link1", "planar2", "elbow3"])
def test_ad_by_ad_equals_symbolic_brackets(name):
    m = build(name)
    lin = linearize(m, symbolic_brackets=True)
    x = ca.SX.sym("x", 4 * m.n)
    p = ca.SX.sym("p", len(m.params))
    bind = {s: x[i] for i, s in enumerate(m.state)}
    bind.update({s: p[j] for j, s in enumerate(m.param_symbols)})
    lazy = {}

    def fac():
        lazy.setdefault("f", ldl_factor(conv(m.D)))
        return lazy["f"]

    implicit = {}
    for i in range(m.n):
        implicit[lin.Y3[i]] = lambda i=i: ldl_solve(fac(), conv(lin.rhs3))[i]
        for j in range(i, m.n):
            implicit[lin.W[i, j]] = lambda i=i, j=j: spd_inverse(fac())[i, j]
    conv = SympyToSX(bind, dict(m.program.definitions), implicit)
    symbolic = ca.Function("ad_sym", [x, p], [conv(lin.outputs["ad"])])
    emitted = build_functions(linearize(build(name)))["ad"]  # a fresh model: its own program
    rng = np.random.default_rng(11)
    p0 = np.array([q.default for q in m.params])
    for _ in range(3):
        xs = rng.uniform(-1.2, 1.2, 4 * m.n)
        ps = p0 * rng.uniform(0.7, 1.3, p0.size)
        ref = np.array(symbolic(xs, ps))
        got = np.array(emitted(xs, ps))
        assert np.max(np.abs(got - ref)) <= 1e-10 * max(1.0, np.max(np.abs(ref)))
        assert np.linalg.matrix_rank(got) == 4 * m.n


def test_linearize_skips_symbolic_brackets_beyond_one_joint():
    assert "ad" not in linearize(build("planar2")).outputs
    assert "ad" in linearize(build("link1")).outputs  # its report prints them beside the paper's
