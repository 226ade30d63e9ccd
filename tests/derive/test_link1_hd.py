"""link1_hd: the single link with a cubic spring psi(phi) = k1 phi + k3 phi^3 (derive/core/spring.py).

Checks from first principles, on the in-memory Functions of one derivation (no files):
Lie identities by central differences (y_{k+1} = L_f y_k, L_g y_k = 0, L_g L_f^3 h = 1/beta,
alpha = -beta L_f^4 h), dT/dx against differences, the brackets' definition, the energy balance,
the torque-coordinate laws at the measurement a state implies, the inverse spring map, the
k3 = 0 limit against the generated link1, the paper's rank/involutivity result, the spring
validation, and a byte-identical derive (two hash seeds, and the committed generated/link1_hd).
The motor friction F(dq_m) (Coulomb + Stribeck, tanh-regularized: derive/core/friction.py) is on in
every random draw, with velocity scales wide enough that its curvature shows in the differences.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
import sympy as sp

import fjm_runtime
from derive.emit.spring import build_spring_functions
from derive.core.lie import lie_derivative
from derive.core.friction import FrictionError, MotorFriction, check_friction
from derive.core.spring import LINK1_HD_RANGE, check_spring, linearize_spring, make_link1_hd
from derive.core.spring_laws import CubicSpring, SpringError, spring_functions

REPO = Path(__file__).resolve().parents[2]
NAMES = ("J_l", "J_m", "k1", "k3", "M", "g0", "L", "B_m", "F_c", "F_s", "v_s", "v_c")
NP = len(NAMES)
NO_FRICTION = [0.0, 0.0, 0.1, 0.01]  # F_c, F_s, v_s, v_c: the defaults (no friction)
H = 1e-6  # central-difference step


@pytest.fixture(scope="module")
def derived():
    lin = linearize_spring(make_link1_hd())
    fns = build_spring_functions(lin)
    return lin, {k: _numpy(f) for k, f in fns.items()}, fns


def _numpy(fn):
    """``fn`` returning a NumPy array (one output) or a list of them."""
    def call(*args):
        out = fn(*args)
        return out.full() if fn.n_out() == 1 else [v.full() for v in out]
    return call


def _s(v) -> float:
    """The scalar of a (1,)/(1, 1) array."""
    return float(np.asarray(v).reshape(-1)[0])


def friction(v, p):
    """The motor friction written out here (not the derivation's): (F_c + (F_s - F_c) e^{-(v/v_s)^2}) tanh(v/v_c)."""
    F_c, F_s, v_s, v_c = p[8:12]
    return (F_c + (F_s - F_c) * np.exp(-(v / v_s) ** 2)) * np.tanh(v / v_c)


def _points(rng, count=6, damping=True):
    """States with the deflection inside the declared range, parameters defaults x U(0.7, 1.3), and
    friction F_c in [0, 1.5], F_s in [0, 2] N m, v_s, v_c in [0.3, 1.5] rad/s (curved over |dq_m| <= 3)."""
    base = np.array([1.0, 2.0, 75.0, 2500.0, 1.0, 9.8, 1.0, 0.0])
    for _ in range(count):
        q, dq, dqm = rng.uniform(-np.pi, np.pi), rng.uniform(-3, 3), rng.uniform(-3, 3)
        phi = rng.uniform(-LINK1_HD_RANGE, LINK1_HD_RANGE)
        p = base * rng.uniform(0.7, 1.3, 8)
        p[7] = rng.uniform(0.0, 0.5) if damping else 0.0
        fr = [rng.uniform(0.0, 1.5), rng.uniform(0.0, 2.0), rng.uniform(0.3, 1.5), rng.uniform(0.3, 1.5)]
        yield np.array([q, dq, q + phi, dqm]), np.concatenate([p, fr])


def _along(fn, x, v, p):
    """Central difference of fn(x, p) along v."""
    return (fn(x + H * v, p) - fn(x - H * v, p)) / (2 * H)


def _close(a, b, rtol):
    a, b = np.asarray(a, float).ravel(), np.asarray(b, float).ravel()
    return np.max(np.abs(a - b)) <= rtol * max(1.0, np.max(np.abs(b)))


def test_lie_identities_by_differences(derived):
    """y_{k+1} = L_f y_k, L_g y_k = 0 (k = 1..3), L_g y4 = 1/beta, L_f y4 = -alpha/beta."""
    _, F, _ = derived
    rng = np.random.default_rng(1)
    for x, p in _points(rng):
        f, g, T = F["f"](x, p).ravel(), F["g"](x, p).ravel(), F["T"](x, p).ravel()
        dT_f, dT_g = _along(F["T"], x, f, p).ravel(), _along(F["T"], x, g, p).ravel()
        assert _close(dT_f[:3], T[1:], 1e-7), (dT_f[:3], T[1:])
        assert np.max(np.abs(dT_g[:3])) < 1e-7 * max(1, np.max(np.abs(T)))
        beta, alpha = _s(F["beta"](x, p)), _s(F["alpha"](x, p))
        assert _close(dT_g[3], 1.0 / beta, 1e-7)
        assert _close(dT_f[3], -alpha / beta, 1e-7)


def test_jacobian_of_T_matches_differences(derived):
    _, F, fns = derived
    xs, ps = ca.SX.sym("x", 4), ca.SX.sym("p", NP)
    jac = ca.Function("dT", [xs, ps], [ca.jacobian(fns["T"](xs, ps), xs)])
    rng = np.random.default_rng(2)
    for x, p in _points(rng, 4):
        fd = np.column_stack([_along(F["T"], x, e, p).ravel() for e in np.eye(4)])
        assert _close(fd, jac(x, p).full(), 1e-7)


def test_brackets_are_the_papers_definition(derived):
    """ad_f^{k+1} g = (df/dx) v - (dv/dx) f column by column, v = ad_f^k g (central differences)."""
    _, F, _ = derived
    rng = np.random.default_rng(3)
    for x, p in _points(rng, 4):
        ad, f = F["ad"](x, p), F["f"](x, p).ravel()
        col = lambda k: (lambda xx, pp: F["ad"](xx, pp)[:, k])  # noqa: E731
        for k in range(3):
            v = ad[:, k]
            expect = _along(F["f"], x, v, p).ravel() - _along(col(k), x, f, p).ravel()
            assert _close(ad[:, k + 1], expect, 1e-7), k


def test_energy_balance(derived):
    """dE/dt = -(B_m dq_m + F(dq_m)) dq_m + u dq_m: L_f E = -(B_m dq_m + F(dq_m)) dq_m and L_g E = dq_m
    (the spring potential is psi's integral; friction only dissipates)."""
    _, F, _ = derived
    rng = np.random.default_rng(4)
    for x, p in _points(rng, 4):
        LfE = _s(_along(F["energy"], x, F["f"](x, p).ravel(), p))
        LgE = _s(_along(F["energy"], x, F["g"](x, p).ravel(), p))
        scale = 1 + abs(_s(F["energy"](x, p)))
        assert abs(LfE + (p[7] * x[3] + friction(x[3], p)) * x[3]) < 1e-7 * scale
        assert abs(LgE - x[3]) < 1e-7 * scale


def test_torque_coordinates_equal_the_state_law(derived):
    """At m = [q; dq; psi(phi); psi'(phi)(dq_m - dq); dq_m] the torque laws equal T, alpha, beta."""
    _, F, _ = derived
    rng = np.random.default_rng(5)
    for x, p in _points(rng):
        psi, dpsi, _ = F["spring"](x[2] - x[0], p)
        m = np.array([x[0], x[1], _s(psi), _s(dpsi) * (x[3] - x[1]), x[3]])
        for name in ("T", "alpha", "beta"):
            assert _close(F[f"{name}_tau"](m, p), F[name](x, p), 1e-12), name


@pytest.mark.parametrize("k3", [2500.0, 0.0, -0.9 * 75.0 / (3 * LINK1_HD_RANGE ** 2)])
def test_spring_inverse(derived, k3):
    """psi^-1(psi(phi)) = phi over the declared range (twice it when hardening or linear), psi by differences."""
    _, F, _ = derived
    p = np.array([1.0, 2.0, 75.0, k3, 1.0, 9.8, 1.0, 0.0, *NO_FRICTION])
    reach = 2 * LINK1_HD_RANGE if k3 >= 0 else LINK1_HD_RANGE
    for phi in np.linspace(-reach, reach, 41):
        tau = _s(F["spring"](phi, p)[0])
        assert abs(_s(F["spring_inverse"](tau, p)) - phi) <= 1e-14 * max(1.0, abs(phi)), (k3, phi)
        psi, dpsi, ddpsi = (_s(v) for v in F["spring"](phi, p))
        assert abs(psi - (75.0 * phi + k3 * phi ** 3)) < 1e-12 * (1 + abs(psi))
        assert _close(dpsi, (F["spring"](phi + H, p)[0] - F["spring"](phi - H, p)[0]) / (2 * H), 1e-7)
        assert _close(ddpsi, (F["spring"](phi + H, p)[1] - F["spring"](phi - H, p)[1]) / (2 * H), 1e-7)


def test_linear_limit_is_link1(derived):
    """k3 = 0, k1 = K, no friction: every function equals the generated link1's to 1e-12 (random states)."""
    _, F, _ = derived
    link1 = fjm_runtime.load("link1")
    rng = np.random.default_rng(6)
    for _ in range(8):
        x = rng.uniform(-2, 2, 4)
        J_l, J_m, K, M, g0, L, B_m = rng.uniform(0.5, 2, 7) * [1, 2, 150, 1, 9.8, 1, 0.3]
        p_hd = np.array([J_l, J_m, K, 0.0, M, g0, L, B_m, *NO_FRICTION])
        p_l1 = np.array([J_l, J_m, K, M, g0, L, B_m])
        for name in ("f", "g", "T", "alpha", "beta", "ad", "energy"):
            assert _close(F[name](x, p_hd), link1.functions[name](x, p_l1).full(), 1e-12), name
        m = np.concatenate([x[:2], rng.uniform(-20, 20, 2), x[3:]])
        for name in ("T_tau", "alpha_tau", "beta_tau"):
            assert _close(F[name](m, p_hd), link1.torque_functions[name](m, p_l1).full(), 1e-12), name


def test_papers_test_holds_while_stiffness_positive(derived):
    """det[g, ad_f g, ad_f^2 g, ad_f^3 g] = psi'^2 / (J_l^2 J_m^4) (symbolic and numeric); span involutive."""
    lin, F, _ = derived
    chk = lin.outputs["check"]
    J_l, J_m = sp.symbols("J_l J_m", real=True)
    m = lin.model
    dpsi = spring_functions(1)[1](m.qm[0] - m.q[0])
    assert sp.simplify(chk["controllability"] - dpsi ** 2 / (J_l ** 2 * J_m ** 4)) == 0
    assert [e for _, e in chk["involutive"]] == [0, 0, 0]
    rng = np.random.default_rng(7)
    for x, p in _points(rng, 3):
        stiffness = _s(F["spring"](x[2] - x[0], p)[1])
        assert _close(np.linalg.det(F["ad"](x, p)), stiffness ** 2 / (p[0] ** 2 * p[1] ** 4), 1e-10)


def test_abstract_derivation_equals_explicit_polynomial():
    """Deriving with psi and F abstract and substituting the laws = deriving with them written in."""
    model = make_link1_hd()
    lin = linearize_spring(model)
    q, dq, qm, dqm = model.state
    J_l, J_m, k1, k3, M, g0, L, B_m, F_c, F_s, v_s, v_c = model.param_symbols
    phi = qm - q
    psi = k1 * phi + k3 * phi ** 3
    fric = (F_c + (F_s - F_c) * sp.exp(-(dqm / v_s) ** 2)) * sp.tanh(dqm / v_c)
    f = sp.Matrix([dq, (psi - M * g0 * L * sp.sin(q)) / J_l, dqm, (-psi - B_m * dqm - fric) / J_m])
    g = sp.Matrix([0, 0, 0, 1 / J_m])
    y = [sp.Matrix([q])]
    for _ in range(4):
        y.append(lie_derivative(y[-1], f, model.state))
    b = lie_derivative(y[3], g, model.state)[0]
    assert sp.simplify(sp.Matrix(y[:4]) - lin.outputs["T"]).is_zero_matrix
    assert sp.simplify(lin.outputs["beta"][0] - 1 / b) == 0
    assert sp.simplify(lin.outputs["alpha"][0] + y[4][0] / b) == 0


def test_validation_names_joint_and_deflection():
    k1, k3 = sp.symbols("k1 k3")
    spring = CubicSpring(1, k1, k3, 0.25)
    check_spring("m", spring, {"k1": 75.0, "k3": -300.0})  # psi'(0.25) = 18.75 > 0: fine
    with pytest.raises(SpringError) as info:
        check_spring("link1_hd", spring, {"k1": 75.0, "k3": -500.0})  # psi'(0.25) = -18.75
    msg = str(info.value)
    assert "\n" not in msg and "link1_hd joint 1" in msg and "phi = 0.25 rad" in msg and "-18.75" in msg
    with pytest.raises(SpringError, match=r"joint 1: spring stiffness psi'\(phi\) = -1 N m/rad <= 0 at deflection phi = 0 rad"):
        check_spring("link1_hd", spring, {"k1": -1.0, "k3": 0.0})
    with pytest.raises(SpringError, match="k3 = nan N m/rad\\^3; expected a finite number"):
        check_spring("link1_hd", spring, {"k1": 75.0, "k3": float("nan")})


# exhaustive pass (.ci/run), to keep make test under 5 minutes: make check-generated derives link1_hd
# under two hash seeds on every CI run
@pytest.mark.slow
@pytest.mark.exhaustive
def test_derive_is_byte_identical(tmp_path):
    """Two derives of link1_hd (hash seeds 0 and 12345) give the same bytes as each other and as generated/."""
    trees = []
    for seed in ("0", "12345"):
        out = tmp_path / seed
        out.mkdir()
        env = {**os.environ, "PYTHONHASHSEED": seed}
        subprocess.run([sys.executable, "-m", "derive", "--models", "link1_hd", "--out", str(out),
                        "--timings", str(tmp_path / f"t{seed}.json")], cwd=REPO, env=env, check=True,
                       capture_output=True)
        trees.append(out / "link1_hd")
    committed = REPO / "generated" / "link1_hd"
    names = sorted(p.name for p in trees[0].iterdir())
    assert names == sorted(p.name for p in trees[1].iterdir()) == sorted(p.name for p in committed.iterdir())
    for name in names:
        ref = (trees[0] / name).read_bytes()
        assert ref == (trees[1] / name).read_bytes() == (committed / name).read_bytes(), name


def test_friction_validation_is_one_line_naming_joint_value_and_unit():
    F_c, F_s, v_s, v_c = sp.symbols("F_c F_s v_s v_c")
    fr = MotorFriction(1, F_c, F_s, v_s, v_c)
    good = {"F_c": 0.5, "F_s": 0.8, "v_s": 0.1, "v_c": 0.01}
    check_friction("m", fr, good)
    for name, bad, unit, expected in (("F_c", -0.1, "N m", ">= 0"), ("F_s", float("inf"), "N m", ">= 0"),
                                      ("v_s", 0.0, "rad/s", "> 0"), ("v_c", float("nan"), "rad/s", "> 0")):
        with pytest.raises(FrictionError) as info:
            check_friction("link1_hd", fr, {**good, name: bad})
        msg = str(info.value)
        assert "\n" not in msg and f"link1_hd joint 1: motor friction {name} = {bad!r} {unit}" in msg, msg
        assert f"expected a finite number {expected}" in msg


def test_friction_is_odd_dissipative_and_the_laws_feed_it_forward(derived):
    """The emitted f's motor row carries -F(dq_m)/J_m with F as written here (odd, F v >= 0, F -> F_s near
    rest and F_c far away), and alpha changes by exactly +F(dq_m) when friction is switched on."""
    _, F, _ = derived
    rng = np.random.default_rng(8)
    for x, p in _points(rng, 4):
        p0 = np.concatenate([p[:8], NO_FRICTION])
        drop = (_s(F["f"](x, p0)[3]) - _s(F["f"](x, p)[3])) * p[1]
        assert abs(drop - friction(x[3], p)) < 1e-12 * max(1.0, abs(drop))
        assert abs(_s(F["alpha"](x, p)) - _s(F["alpha"](x, p0)) - friction(x[3], p)) < 1e-9 * (
            1 + abs(_s(F["alpha"](x, p))))
        for v in (0.7, 2.0, 5.0):
            assert friction(v, p) > 0 and abs(friction(-v, p) + friction(v, p)) < 1e-15
    p = np.concatenate([np.ones(8), [1.0, 1.6, 0.05, 1e-4]])
    x = np.array([0.0, 0.0, 0.0, 0.0])
    for v, level in ((0.005, 1.6), (2.0, 1.0)):  # near rest the static level, far away the Coulomb one
        x[3] = v
        assert abs((_s(F["f"](x, np.concatenate([p[:8], NO_FRICTION]))[3]) - _s(F["f"](x, p)[3])) - level) < 2e-2
