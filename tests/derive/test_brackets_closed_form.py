"""The closed-form bracket matrix (derive/emit/brackets.py) against the generic AD construction.

Three independent checks of ``[g, ad_f g, ad_f^2 g, ad_f^3 g]``:

- the emitted SX (closed form) against :func:`derive.emit.functions.ad_by_ad`, forward-mode AD of
  ``ad_f v = (df/dx) v - (dv/dx) f`` over the SX of ``f``, on spatial chains, a tree and planar chains,
  with motor damping switched on (the constant blocks carry ``B_m``);
- the C file's twin (columns mapped in a loop) against the SX;
- the physics identity the third bracket rests on: ``D' - dh/ddq = C^T - C`` is skew-symmetric.
"""
import casadi as ca
import numpy as np
import pytest

from derive.emit.brackets import bracket_twin, coriolis_difference_along
from derive.emit.dynamics import programme
from derive.emit.functions import ad_by_ad, build_functions
from derive.emit.ldl import ldl_factor, ldl_solve
from derive.emit.sx import SympyToSX
from derive.core.linearize import linearize
from derive.registry import build

MODELS = ["link1", "planar3", "elbow3", "panda", "baxter"]


def _draw(m, rng):
    """A random state and parameters near the defaults, every motor damping > 0."""
    p = np.array([q.default for q in m.params]) * rng.uniform(0.7, 1.3, len(m.params))
    for i, name in enumerate(m.param_names):
        if name.startswith("Bm") or name == "B_m":
            p[i] = rng.uniform(0.1, 0.6)
    return rng.uniform(-1.2, 1.2, 4 * m.n), p


def _generic_brackets(m, lin) -> ca.Function:
    """``ad_by_ad`` over the SX of ``f`` (the link acceleration by an LDL^T solve)."""
    n = m.n
    x, p = ca.SX.sym("x", 4 * n), ca.SX.sym("p", len(m.params))
    bind = {s: x[i] for i, s in enumerate(m.state)}
    bind.update({s: p[j] for j, s in enumerate(m.param_symbols)})
    lazy = {}

    def y3(i):
        if "y3" not in lazy:
            lazy["y3"] = ldl_solve(factors, conv(lin.rhs3))
        return lazy["y3"][i]

    conv = SympyToSX(bind, dict(m.program.definitions), {lin.Y3[i]: (lambda i=i: y3(i)) for i in range(n)})
    factors = ldl_factor(conv(m.D))
    f_sx = conv(lin.outputs["f"])
    ad = ad_by_ad(x, conv(m.D), conv(lin.rhs3), f_sx[3 * n:], conv(lin.outputs["g"]), factors)
    return ca.Function("ad_generic", [x, p], [ad])


@pytest.fixture(scope="module", params=MODELS)
def model_and_functions(request):
    m = build(request.param)
    lin = linearize(m)
    return m, lin, build_functions(lin)


def test_closed_form_equals_generic_ad(model_and_functions):
    m, lin, fns = model_and_functions
    generic = _generic_brackets(m, lin)
    rng = np.random.default_rng(5)
    for _ in range(3):
        x, p = _draw(m, rng)
        ref = np.array(generic(x, p))
        got = np.array(fns["ad"](x, p))
        assert np.max(np.abs(got - ref)) <= 1e-11 * np.max(np.abs(ref)), m.name
        assert np.linalg.matrix_rank(got) == 4 * m.n


def test_c_twin_equals_casadi(model_and_functions):
    m, _, fns = model_and_functions
    twin = bracket_twin(m, fns["inertia"])
    assert twin.name() == fns["ad"].name() and twin.name_in() == fns["ad"].name_in()
    rng = np.random.default_rng(6)
    for _ in range(3):
        x, p = _draw(m, rng)
        ref = np.array(fns["ad"](x, p))
        assert np.max(np.abs(np.array(twin(x, p)) - ref)) <= 1e-12 * np.max(np.abs(ref)), m.name


def test_coriolis_difference_is_skew_and_matches_matrix(model_and_functions):
    """``D' - dh/ddq = C^T - C`` (skew), and the column form equals the matrix form."""
    m, _, _ = model_and_functions
    n = m.n
    q, dq, v, p = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("v", n), ca.SX.sym("p", len(m.params))
    D, h, _ = programme(m)(q, dq, ca.SX.zeros(n), p)
    matrix = ca.Function("M", [q, dq, p], [ca.jtimes(D, q, dq) - ca.jacobian(h, dq)])
    along = ca.Function("Mv", [q, dq, v, p], [coriolis_difference_along(m, q, dq, v, p)])
    rng = np.random.default_rng(7)
    for _ in range(3):
        x, pv = _draw(m, rng)
        M = np.array(matrix(x[:n], x[n:2 * n], pv))
        scale = max(1.0, np.max(np.abs(M)))
        assert np.max(np.abs(M + M.T)) <= 1e-12 * scale, m.name
        vv = rng.normal(size=n)
        assert np.max(np.abs(np.array(along(x[:n], x[n:2 * n], vv, pv)).ravel() - M @ vv)) <= 1e-12 * scale * np.abs(vv).max()
