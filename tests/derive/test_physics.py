"""Physics identities and independent formulations of the generated models."""

import numpy as np
import pytest
import sympy as sp

import fjm_runtime
from derive.registry import build
from support.independent_chain import PinocchioReference
from support.numerics import ALL_MODELS, energy_drifts, random_params, random_state, rk4

QUANTITIES = ("f", "g", "ad", "T", "alpha", "beta", "energy", "inertia")


def test_link1_equals_planar1_with_matching_parameters():
    """link1 (paper eq 3 + B_m) == planar1 with J_l = I1 + m1 r1^2, M = m1, L = r1."""
    l1, p1 = fjm_runtime.load("link1"), fjm_runtime.load("planar1")
    rng = np.random.default_rng(11)
    for _ in range(5):
        m1, r1, I1 = rng.uniform(0.5, 2), rng.uniform(0.1, 0.9), rng.uniform(0.01, 0.5)
        K, Jm, Bm, g0 = rng.uniform(100, 200), rng.uniform(0.5, 3), rng.uniform(0, 1), 9.81
        pp = {"m1": m1, "l1": 1.0, "r1": r1, "I1": I1, "K1": K, "Jm1": Jm, "Bm1": Bm, "g0": g0}
        pl = {"J_l": I1 + m1 * r1**2, "J_m": Jm, "K": K, "M": m1, "g0": g0, "L": r1, "B_m": Bm}
        x = random_state(l1, rng)
        for q in QUANTITIES:
            a = getattr(l1, q)(x, pl)
            b = getattr(p1, q)(x, pp)
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12, err_msg=q)


@pytest.mark.parametrize("name", ALL_MODELS)
def test_inertia_matrix_is_symmetric_positive_definite(name):
    m = fjm_runtime.load(name)
    rng = np.random.default_rng(5)
    for _ in range(20):
        x = random_state(m, rng, scale=4.0)
        D = m.inertia(x, random_params(m, rng))
        assert np.allclose(D, D.T, rtol=1e-14, atol=1e-14)
        assert np.linalg.eigvalsh(D).min() > 0


@pytest.mark.parametrize("name", ["link1", "planar1", "planar2", "planar3", "planar5"])
def test_energy_is_conserved_without_damping_or_input(name):
    """B_m = 0, u = 0: links + motors + springs + gravity energy is constant along RK4.

    RK4's energy drift is O(dt^4): halving dt must shrink it ~16x, which
    shows the residual is integration error, not a modelling error.
    """
    drifts = energy_drifts(fjm_runtime.load(name), (2e-3, 1e-3), 1.0)
    assert drifts[1] < 1e-7, drifts
    assert drifts[0] / max(drifts[1], 1e-300) > 8 or drifts[1] < 1e-12, drifts


@pytest.mark.parametrize("name", ["planar2", "planar3"])
def test_energy_decreases_with_damping(name):
    """With motor damping and u = 0 the energy can only decrease: dE/dt = -dq_m^T B_m dq_m."""
    m = fjm_runtime.load(name)
    rng = np.random.default_rng(4)
    p = random_params(m, rng, damping=True)
    xs = rk4(lambda x: m.f(x, p), random_state(m, rng), 2e-3, 500)
    E = np.array([m.energy(x, p) for x in xs])
    assert np.all(np.diff(E) < 1e-9)
    assert E[-1] < E[0] - 1e-3


def kinematic_inertia_and_potential(name, q):
    """``D(q)`` and the potential written from the arm's description, not from ``derive``.

    link1 is the paper's eq (3): ``D = J_l``, ``V = -M g0 L cos q``. A planar
    chain is assembled from its links: absolute angle ``theta_i = q_1 + .. + q_i``,
    link direction ``(sin theta_i, -cos theta_i)`` (q = 0 hangs down), joint
    ``i + 1`` at the tip of link ``i``, centre of mass at ``r_i`` along link ``i``;
    ``D = sum_i m_i Jc_i^T Jc_i + I_i Jw_i^T Jw_i`` with the centre-of-mass and
    angular-rate Jacobians, ``V = sum_i m_i g0 y_ci``.
    """
    s = lambda k: sp.Symbol(k, real=True)
    if name == "link1":
        return sp.Matrix([[s("J_l")]]), -s("M") * s("g0") * s("L") * sp.cos(q[0])
    n = len(q)
    D, V = sp.zeros(n, n), sp.Integer(0)
    joint, theta = sp.zeros(2, 1), sp.Integer(0)
    for i in range(1, n + 1):
        theta += q[i - 1]
        along = sp.Matrix([sp.sin(theta), -sp.cos(theta)])
        com = joint + s(f"r{i}") * along
        Jc = com.jacobian(q)
        Jw = sp.Matrix([[1 if k < i else 0 for k in range(n)]])
        D += s(f"m{i}") * Jc.T * Jc + s(f"I{i}") * Jw.T * Jw
        V += s(f"m{i}") * s("g0") * com[1]
        joint = joint + s(f"l{i}") * along
    return D.applyfunc(lambda e: sp.trigsimp(sp.expand(e))), V


def brute_force(name, pvals):
    """Independent SymPy derivation at fixed parameters: explicit D^-1, explicit Jacobians.

    D and the potential come from :func:`kinematic_inertia_and_potential`, h from
    Lagrange's equations written here, the Lie derivatives and brackets as plain
    Jacobian products: nothing of the model's closed form is reused, only its
    state and parameter names. Parameters are substituted first (as exact
    rationals) to keep the brute force affordable; it is exponential in n, so
    small models only.
    """
    mod = build(name)
    n = mod.n
    x = list(mod.state)
    subs = {s: sp.Rational(v).limit_denominator(10**6) for s, v in zip(mod.param_symbols, pvals)}
    q, dq, qm, dqm = (sp.Matrix(b) for b in (mod.q, mod.dq, mod.qm, mod.dqm))
    K, J, B = (sp.diag(*v).xreplace(subs) for v in (mod.K, mod.Jm, mod.Bm))
    D, V = (e.xreplace(subs) for e in kinematic_inertia_and_potential(name, list(mod.q)))
    # Lagrange: h_i = sum_jk (dD_ij/dq_k - 1/2 dD_jk/dq_i) dq_j dq_k + dV/dq_i.
    h = sp.Matrix([sum((D[i, j].diff(q[k]) - D[j, k].diff(q[i]) / 2) * dq[j] * dq[k]
                       for j in range(n) for k in range(n)) + V.diff(q[i]) for i in range(n)])
    Dinv = D.inv()
    f = sp.Matrix.vstack(dq, -Dinv * (h + K * (q - qm)), dqm, J.inv() * (K * (q - qm) - B * dqm))
    g = sp.Matrix.vstack(sp.zeros(3 * n, n), J.inv())
    y = [q]
    for _ in range(3):
        y.append(y[-1].jacobian(x) * f)
    a = y[3].jacobian(x) * f
    b = y[3].jacobian(x) * g
    beta = b.inv()
    alpha = -beta * a
    ads = [g]  # ad_f v = (df/dx) v - (dv/dx) f, column by column
    for _ in range(3):
        v = ads[-1]
        ads.append(sp.Matrix.hstack(*[f.jacobian(x) * v[:, c] - v[:, c].jacobian(x) * f
                                      for c in range(n)]))
    ad = sp.Matrix.hstack(*ads)
    exact = [float(v) for v in subs.values()]
    return exact, {k: sp.lambdify(x, v, "numpy") for k, v in
                   {"f": f, "T": sp.Matrix.vstack(*y), "alpha": alpha, "beta": beta, "ad": ad}.items()}


@pytest.mark.parametrize("name", ["link1", "planar1", "planar2"])
def test_structured_derivation_equals_brute_force(name):
    """Implicit-D^-1 derivation == explicit inverse + Jacobians (independent SymPy path)."""
    m = fjm_runtime.load(name)
    rng = np.random.default_rng(9)
    p, ref = brute_force(name, random_params(m, rng))
    for _ in range(4):
        x = random_state(m, rng)
        for k, fn in ref.items():
            want = np.array(fn(*x), dtype=float)
            got = getattr(m, k)(x, p)
            np.testing.assert_allclose(got.ravel(), want.ravel(), rtol=1e-10, atol=1e-10, err_msg=k)


@pytest.mark.exhaustive  # ~15 s of stiff integrations
def test_rigid_limit_as_stiffness_grows():
    """K -> infinity: the flexible arm moves like the rigid one with the motor inertias added.

    The rigid reference ``(D(q) + J_m) ddq = -h(q, dq)`` is Pinocchio's chain
    (``crba``, ``rnea``), built from the arm's description and not from the
    model, so a wrong inertia or gravity term in the derivation shows up as an
    O(1) deviation that does not shrink with K. The deviation of the link
    trajectory must shrink markedly as K grows.
    """
    m = fjm_runtime.load("planar2")
    n = m.n
    rng = np.random.default_rng(8)
    x0 = random_state(m, rng)
    x0[2 * n:3 * n] = x0[:n]          # spring unloaded ...
    x0[3 * n:] = x0[n:2 * n]          # ... and motors moving with the links
    base = random_params(m, rng, damping=False)
    Jm = np.array([base[m.param_names.index(f"Jm{i + 1}")] for i in range(n)])
    arm = PinocchioReference(dict(zip(m.param_names, base)), n)

    def rigid_rhs(w):
        q, dq = w[:n], w[n:]
        return np.concatenate([dq, np.linalg.solve(arm.inertia(q) + np.diag(Jm), -arm.bias(q, dq))])

    T_end, dt = 0.3, 5e-5
    steps = int(round(T_end / dt))
    rigid = rk4(rigid_rhs, x0[:2 * n], dt, steps)[-1]
    errs = []
    for K in (1e3, 1e5):
        p = base.copy()
        for i in range(n):
            p[m.param_names.index(f"K{i + 1}")] = K
        flex = rk4(lambda x: m.f(x, p), x0, dt, steps)[-1]
        errs.append(np.max(np.abs(flex[:n] - rigid[:n])))
    print("max |q_flex - q_rigid| at K = 1e3, 1e5:", errs)
    assert errs[1] < errs[0] / 20, errs
    assert errs[1] < 1e-3, errs
