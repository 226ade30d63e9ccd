"""link1 against the paper's closed forms (B_m = 0), one test per erratum listed in the README."""

import numpy as np
import pytest
import sympy as sp

import fjm_runtime
from derive.core.lie import ad_iterates, lie_derivative
from support.numerics import directional

# A parameter set where J_l != J_m and J_m != 1, so every typo shows.
P = {"J_l": 1.0, "J_m": 2.0, "K": 130.0, "M": 1.0, "g0": 9.8, "L": 1.0, "B_m": 0.0}
STATES = np.array([[0.3, 0.2, 0.1, -0.4], [1.2, -0.7, 1.0, 0.3], [-2.0, 1.5, -1.9, 2.0]])


@pytest.fixture(scope="module")
def m():
    return fjm_runtime.load("link1")


def paper_brackets(Jl, Jm, K):
    """The bracket matrix as printed in section 2.2."""
    return np.array([
        [0, 0, 0, K / (Jl * Jm)],
        [0, 0, K / (Jl * Jm), 0],
        [0, 1 / Jm, 0, -K / Jm**2],
        [1 / Jm, 0, -K / Jm**2, 0],
    ])


def paper_a(x, Jl, Jm, K, MgL):
    """a(x) as printed (it is right)."""
    x1, x2, x3, _ = x
    return (MgL / Jl * np.sin(x1) * (x2**2 + MgL / Jl * np.cos(x1) + K / Jl)
            + K / Jl * (x1 - x3) * (K / Jl + K / Jm + MgL / Jl * np.cos(x1)))


def paper_T(x, Jl, K, MgL, factor):
    """T as printed, with the spring factor K/factor (printed: factor = J_m; correct: J_l)."""
    x1, x2, x3, x4 = x
    return np.array([x1, x2, -MgL / Jl * np.sin(x1) - K / factor * (x1 - x3),
                     -MgL / Jl * np.cos(x1) * x2 - K / factor * (x2 - x4)])


def test_erratum1_g_is_one_over_Jm(m):
    """Erratum 1: g = [0, 0, 0, 1/J_m], not [0, 0, 0, 1]."""
    for x in STATES:
        g = m.g(x, P).ravel()
        np.testing.assert_allclose(g, [0, 0, 0, 1 / P["J_m"]], rtol=0, atol=1e-15)
        assert abs(g[3] - 1.0) > 0.4  # the printed g would be wrong here
        # And g really is the input direction: x' changes by g u when u is added.
        u = 3.0
        np.testing.assert_allclose(m.xdot(x, [u], P) - m.f(x, P), g * u, atol=1e-12)


def test_erratum2_T3_T4_use_K_over_Jl_and_beta_is_JlJm_over_K(m):
    """Erratum 2: T3, T4 carry K/J_l (printed K/J_m); a(x) as printed; beta = J_l J_m / K."""
    Jl, Jm, K, MgL = P["J_l"], P["J_m"], P["K"], P["M"] * P["g0"] * P["L"]
    for x in STATES:
        T = m.T(x, P)
        np.testing.assert_allclose(T, paper_T(x, Jl, K, MgL, factor=Jl), rtol=1e-12, atol=1e-12)
        printed = paper_T(x, Jl, K, MgL, factor=Jm)
        assert np.max(np.abs(printed[2:] - T[2:])) > 1.0  # the typo is visible
        # The corrected T3 is L_f T2; the printed one is not.
        Lf_T2 = directional(lambda z: m.T(z, P)[1], x, m.f(x, P))
        assert abs(Lf_T2 - T[2]) < 1e-6 * max(1, abs(T[2]))
        assert abs(Lf_T2 - printed[2]) > 1.0
        beta = m.beta(x, P)[0, 0]
        assert beta == pytest.approx(Jl * Jm / K, rel=1e-14)
        a = paper_a(x, Jl, Jm, K, MgL)
        assert m.alpha(x, P)[0] == pytest.approx(-beta * a, rel=1e-12, abs=1e-12)


def test_erratum3_switching_gain_and_stiffness_are_distinct_quantities(m):
    """Erratum 3: the paper calls both the switching gain and the stiffness K.

    Numerically, with the paper's law ``u = alpha_hat + beta_hat nu``,
    ``nu = y4d' - (c1 e2 + c2 e3 + c3 e4) - k_s sat(s / delta)``:

    * changing only ``k_s`` leaves ``s``, ``alpha_hat``, ``beta_hat`` alone and moves
      ``nu`` by exactly ``-(k_s2 - k_s1) sat(s / delta)``;
    * the plant's (true) ``K`` does not enter the controller: the first torque of two
      runs that differ only in the plant stiffness is the same;
    * the nominal stiffness enters through ``T`` (``y3``, ``y4`` carry ``K / J_l``),
      ``alpha`` and ``beta = J_l J_m / K``, never through the switching term.
    """
    from fjm_runtime.control.laws import SlidingModeController
    from fjm_runtime.control.references import Sinusoid
    from fjm_runtime.sim.simulate import simulate

    assert "K" in m.param_names and "k_s" not in m.param_names
    Jl, Jm, MgL = P["J_l"], P["J_m"], P["M"] * P["g0"] * P["L"]
    lam, delta = 6.0, 3.0
    c1, c2, c3 = lam ** 3, 3 * lam ** 2, 3 * lam  # triple pole at -lam
    r = np.array([[0.2], [0.1], [-0.3], [0.05], [0.4]])  # y_d and its four derivatives
    k1, k2 = 40.0, 700.0
    inside = outside = 0
    # A state on the reference (e1 = e2 = e3 = 0) with e4 = 1: s = 1 lies inside the layer.
    x1, x2 = r[0, 0], r[1, 0]
    x_in = np.array([x1, x2, x1 + Jl / P["K"] * (r[2, 0] + MgL / Jl * np.sin(x1)),
                     x2 + Jl / P["K"] * (r[3, 0] + 1.0 + MgL / Jl * np.cos(x1) * x2)])
    for x in [*STATES, x_in]:
        samples = {}
        for k_s in (k1, k2):
            ctrl = SlidingModeController(m, P, lam=lam, k_s=k_s, delta=delta)
            cs = ctrl.evaluate(0.0, x, np.zeros(0), r)
            nu = (cs.u - m.alpha(x, P)) / m.beta(x, P)[0, 0]
            samples[k_s] = (cs, nu)
        (a, nu1), (b, nu2) = samples[k1], samples[k2]
        np.testing.assert_array_equal(a.s, b.s)          # k_s is not in the surface
        np.testing.assert_array_equal(a.y_hat, b.y_hat)  # nor in T
        s = a.s[0]
        sat = min(1.0, max(-1.0, s / delta))
        assert nu2[0] - nu1[0] == pytest.approx(-(k2 - k1) * sat, rel=1e-9, abs=1e-9)
        # and nu itself is the paper's formula with the errors written out here
        e = np.array([x[0], x[1], *paper_T(x, Jl, P["K"], MgL, factor=Jl)[2:]]) - r[:4, 0]
        assert s == pytest.approx(c1 * e[0] + c2 * e[1] + c3 * e[2] + e[3], rel=1e-9, abs=1e-9)
        w = r[4, 0] - (c1 * e[1] + c2 * e[2] + c3 * e[3])
        assert nu1[0] == pytest.approx(w - k1 * sat, rel=1e-9, abs=1e-9)
        inside += abs(s) < delta
        outside += abs(s) >= delta
    assert inside >= 1 and outside >= 1  # both the boundary layer and the saturated branch are exercised

    # The plant stiffness never reaches the controller: same first torque for K = 100 and K = 200.
    ctrl = SlidingModeController(m, P, lam=lam, k_s=k1, delta=delta)
    runs = [simulate(m, ctrl, Sinusoid(0.5, 1.0), duration=0.01, true_params={**P, "K": K}, backend="python")
            for K in (100.0, 200.0)]
    assert runs[0].u[0, 0] == runs[1].u[0, 0]
    assert runs[0].x[-1, 1] != runs[1].x[-1, 1]  # while the plants do differ

    # The nominal stiffness enters T, alpha and beta (closed forms of erratum 2), not the switching term.
    x = STATES[0]
    for K in (100.0, 200.0):
        p = {**P, "K": K}
        ctrl = SlidingModeController(m, p, lam=lam, k_s=k1, delta=delta)
        cs = ctrl.evaluate(0.0, x, np.zeros(0), r)
        np.testing.assert_allclose(cs.y_hat[:, 0], paper_T(x, Jl, K, MgL, factor=Jl), rtol=1e-12, atol=1e-12)
        assert m.beta(x, p)[0, 0] == pytest.approx(Jl * Jm / K, rel=1e-14)
        assert m.alpha(x, p)[0] == pytest.approx(-(Jl * Jm / K) * paper_a(x, Jl, Jm, K, MgL), rel=1e-12)
        nu = (cs.u[0] - m.alpha(x, p)[0]) / m.beta(x, p)[0, 0]
        e = cs.y_hat[:, 0] - r[:4, 0]
        w = r[4, 0] - (c1 * e[1] + c2 * e[2] + c3 * e[3])
        assert nu == pytest.approx(w - k1 * min(1.0, max(-1.0, cs.s[0] / delta)), rel=1e-9, abs=1e-9)


def test_erratum4_motor_equation_uses_motor_inertia(m):
    """Erratum 4: eq (2)'s "D_m(q_m'')" is J_m q_m'': J_m x4' + B_m x4 - K (x1 - x3) = u."""
    rng = np.random.default_rng(3)
    for x in STATES:
        for Bm in (0.0, 0.7):
            p = {**P, "B_m": Bm}
            u = rng.normal()
            x4dot = m.xdot(x, [u], p)[3]
            lhs = p["J_m"] * x4dot + Bm * x[3] - p["K"] * (x[0] - x[2])
            assert lhs == pytest.approx(u, abs=1e-12)


def test_erratum5_bracket_matrix_follows_the_papers_sign(m):
    """Erratum 5: the printed matrix is ad_f v = (df/dx) v - (dv/dx) f.

    The generated brackets equal the printed matrix; an independent SymPy
    computation with the Isidori/Khalil sign gives the odd columns negated,
    so it does not match the print.
    """
    Jl, Jm, K = P["J_l"], P["J_m"], P["K"]
    for x in STATES:
        np.testing.assert_allclose(m.ad(x, P), paper_brackets(Jl, Jm, K), rtol=1e-14, atol=1e-14)
    # Independent symbolic check of the sign convention on the paper's own f.
    x1, x2, x3, x4, sJl, sJm, sK, sMgL = sp.symbols("x1 x2 x3 x4 J_l J_m K MgL", positive=True)
    xs = [x1, x2, x3, x4]
    f = sp.Matrix([x2, -sMgL / sJl * sp.sin(x1) - sK / sJl * (x1 - x3), x4, sK / sJm * (x1 - x3)])
    g = sp.Matrix([0, 0, 0, 1 / sJm])
    paper = sp.Matrix(paper_brackets(sJl, sJm, sK).tolist())
    ours = ad_iterates(f, g, xs, 3)
    assert sp.simplify(ours - paper) == sp.zeros(4, 4)
    # Khalil's sign: [f, v] = (dv/dx) f - (df/dx) v, i.e. the negated bracket.
    khalil = [g]
    for _ in range(3):
        v = khalil[-1]
        khalil.append(v.jacobian(xs) * f - f.jacobian(xs) * v)
    khalil = sp.Matrix.hstack(*khalil)
    assert sp.simplify(khalil[:, 1] + paper[:, 1]) == sp.zeros(4, 1)
    assert sp.simplify(khalil[:, 1] - paper[:, 1]) != sp.zeros(4, 1)
    # Lie derivative helper agrees with the output chain: L_f x1 = x2.
    assert lie_derivative(sp.Matrix([x1]), f, xs)[0] == x2
