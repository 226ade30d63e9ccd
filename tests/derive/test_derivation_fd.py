"""Finite-difference checks of every generated model.

Each identity of the feedback linearization is checked on random states and
random physical parameters (with motor damping), using only the generated
functions and a fourth-order directional difference.
"""

import numpy as np
import pytest

import fjm_runtime
from support.numerics import ALL_MODELS, directional, random_params, random_state

RTOL = 2e-6


def blocks(v, n):
    return [v[k * n:(k + 1) * n] for k in range(4)]


def close(a, b, rtol=RTOL, scale=None):
    """|a - b| <= rtol * max(1, |b|_inf) (mixed absolute/relative)."""
    a, b = np.asarray(a), np.asarray(b)
    s = max(1.0, float(np.max(np.abs(b)))) if scale is None else scale
    return float(np.max(np.abs(a - b))) <= rtol * s, float(np.max(np.abs(a - b))) / s


def cases(name, count=3, seed=0):
    m = fjm_runtime.load(name)
    rng = np.random.default_rng(seed + sum(map(ord, name)))
    return m, [(random_state(m, rng), random_params(m, rng)) for _ in range(count)]


@pytest.mark.parametrize("name", ALL_MODELS)
def test_output_chain_y_next_is_lie_derivative_of_y(name):
    """y_{k+1} = L_f y_k for k = 1..3 (T2 = L_f T1, T3 = L_f T2, T4 = L_f T3)."""
    m, samples = cases(name)
    n = m.n
    for x, p in samples:
        T = m.T(x, p)
        f = m.f(x, p)
        dT = directional(lambda z: m.T(z, p), x, f)
        for k in range(3):
            ok, err = close(blocks(dT, n)[k], blocks(T, n)[k + 1])
            assert ok, f"{name}: L_f y{k + 1} != y{k + 2} (rel err {err:.2e})"


@pytest.mark.parametrize("name", ALL_MODELS)
def test_input_does_not_reach_y1_to_y3_and_Lg_y4_is_inverse_beta(name):
    """L_g y_k = 0 (k = 1..3) and L_g y4 = beta^-1 (relative degree 4 per joint)."""
    m, samples = cases(name)
    n = m.n
    for x, p in samples:
        g = m.g(x, p)
        Lg = np.column_stack([directional(lambda z: m.T(z, p), x, g[:, j]) for j in range(n)])
        Lg_blocks = [Lg[k * n:(k + 1) * n, :] for k in range(4)]
        y_scale = max(1.0, np.max(np.abs(m.T(x, p))))
        for k in range(3):
            assert np.max(np.abs(Lg_blocks[k])) <= RTOL * y_scale, f"{name}: L_g y{k + 1} != 0"
        ok, err = close(Lg_blocks[3], np.linalg.inv(m.beta(x, p)), rtol=1e-6)
        assert ok, f"{name}: L_g y4 != beta^-1 (rel err {err:.2e})"


@pytest.mark.parametrize("name", ALL_MODELS)
def test_bracket_recursion(name):
    """ad_f^{k+1} g = (df/dx) ad_f^k g - (d ad_f^k g/dx) f, the paper's sign; ad_f^0 g = g."""
    m, samples = cases(name, count=2)
    n = m.n
    for x, p in samples:
        ad = m.ad(x, p)
        f = m.f(x, p)
        assert np.allclose(ad[:, :n], m.g(x, p), rtol=0, atol=1e-14)
        # (d ad/dx) f for all columns at once
        dad_f = directional(lambda z: m.ad(z, p), x, f)
        for k in range(3):
            for j in range(n):
                v = ad[:, k * n + j]
                df_v = directional(lambda z: m.f(z, p), x, v)
                expected = df_v - dad_f[:, k * n + j]
                ok, err = close(ad[:, (k + 1) * n + j], expected, rtol=5e-6)
                assert ok, f"{name}: bracket {k + 1}, column {j} (rel err {err:.2e})"


@pytest.mark.parametrize("name", ALL_MODELS)
def test_closed_loop_gives_y4_dot_equal_nu(name):
    """With u = alpha + beta nu, d/dt y4 along f + g u equals nu."""
    m, samples = cases(name)
    rng = np.random.default_rng(7)
    n = m.n
    for x, p in samples:
        nu = rng.normal(0, 5, n)
        u = m.alpha(x, p) + m.beta(x, p) @ nu
        xdot = m.f(x, p) + m.g(x, p) @ u
        # a step of 2e-3: xdot is large (stiff springs), and at 1e-3 the rounding of T over the
        # step reached 2.8e-6 of alpha on one Panda sample (3e-3: 2.3e-7; 2e-3: 2.9e-7)
        y4dot = blocks(directional(lambda z: m.T(z, p), x, xdot, rel_step=2e-3), n)[3]
        ok, err = close(y4dot, nu, scale=max(1.0, np.max(np.abs(m.alpha(x, p)))))
        assert ok, f"{name}: y4' != nu (rel err {err:.2e})"


@pytest.mark.parametrize("name", ALL_MODELS)
def test_controllability_rank_and_involutivity(name):
    """rank [g, ad_f g, ad_f^2 g, ad_f^3 g] = 4n; span{g, ad_f g, ad_f^2 g} (3n columns) is involutive.

    Every pair of the 3n columns is checked: ``[v_i, v_j] = (dv_j/dx) v_i - (dv_i/dx) v_j`` with
    ``dv/dx`` from the CasADi Jacobian of the generated ``ad`` Function, and
    ``rank [D3, [v_i, v_j]] = 3n``. Controls that the check can fail: the same rank test gives
    ``3n + 1`` for each column of ``ad_f^3 g``, the brackets with ``ad_f^3 g`` columns are non-zero
    (chains of n >= 2), and the Jacobian agrees with a finite difference of ``m.ad``.
    """
    import casadi as ca
    m, samples = cases(name, count=2)
    n, nx = m.n, m.nx
    F = m.functions["ad"]
    xs, ps = ca.MX.sym("x", nx), ca.MX.sym("p", len(m.param_names))
    jac = ca.Function("jac_ad", [xs, ps], [ca.jacobian(ca.vec(F(xs, ps)), xs)])
    for x, p in samples:
        pv = m.params_array(p)
        ad = m.ad(x, p)
        assert np.linalg.matrix_rank(ad) == 4 * n
        J = np.array(jac(x, pv))  # rows: column-major vec(ad), i.e. column c is rows c*nx .. (c+1)*nx
        dcol = [J[c * nx:(c + 1) * nx, :] for c in range(4 * n)]
        v = np.random.default_rng(5).normal(size=nx)
        ok, err = close((J @ v).reshape(4 * n, nx).T, directional(lambda z: m.ad(z, p), x, v), rtol=1e-5)
        assert ok, f"{name}: CasADi Jacobian of ad != finite difference (rel err {err:.2e})"
        D3 = ad[:, :3 * n]
        tol = 1e-9 * np.linalg.norm(D3, 2)

        def rank_with(w):
            return np.linalg.matrix_rank(np.column_stack([D3, w]), tol=tol)

        assert np.linalg.matrix_rank(D3, tol=tol) == 3 * n
        pairs = 0
        for i in range(3 * n):
            for j in range(i + 1, 3 * n):
                br = dcol[j] @ ad[:, i] - dcol[i] @ ad[:, j]
                assert rank_with(br) == 3 * n, (name, i, j, np.linalg.norm(br))
                pairs += 1
        assert pairs == 3 * n * (3 * n - 1) // 2
        for k in range(n):  # the rank test does see a vector outside D3
            assert rank_with(ad[:, 3 * n + k]) == 3 * n + 1
        if n > 1:  # one joint: constant brackets (link1: the paper's matrix); chains: D(q) makes them vary
            outside = max(np.max(np.abs(dcol[3 * n + k] @ ad[:, i] - dcol[i] @ ad[:, 3 * n + k]))
                          for k in range(n) for i in range(3 * n))
            assert outside > 1.0
