"""panda_hd: the Panda on harmonic drives (seven three-segment datasheet springs, motor friction), checked on the
generated functions from first principles and against ``panda`` (itself checked against Pinocchio).

* With every curve made linear (``K_1 = K_2 = K_3``) and no friction, panda_hd IS panda: f, g, T, alpha, beta,
  the brackets, the energy and the torque-sensed functions agree to rounding. That ties the rigid-body part
  and the derivation route of the several-joint emitter to the verified linear model.
* With the curves: the spring functions are the datasheet curve written out in this file and invert to
  1e-12 rad over the declared range; f's link row is panda's at the state whose linear spring carries the
  same torque; f's motor row is the motor equation written out; T, alpha, beta satisfy the Lie identities
  (``T`` a chain of derivatives, ``d/dt y4 = nu`` under ``u = alpha + beta nu``) by CasADi AD of the
  emitted ``T``; the energy balance holds; the torque-sensed functions equal the state ones at the
  measurement a state implies; bad coefficients are one-line errors naming the joint.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import fjm_runtime
from tests.runtime.test_arm1_hd_runtime import datasheet

N = 7
CURVE = ("K_1", "K_2", "K_3", "T_1", "T_2", "w_blend")


@pytest.fixture(scope="module")
def hd():
    return fjm_runtime.load("panda_hd")


def _friction(v, p, j):
    F_c, F_s, v_s, v_c = (p[f"{k}_{j}"] for k in ("F_c", "F_s", "v_s", "v_c"))
    return (F_c + (F_s - F_c) * np.exp(-(v / v_s) ** 2)) * np.tanh(v / v_c)


def _params(rng, hd):
    """Defaults with every drive coefficient, rotor and the payload moved (curve order and blend limits kept)."""
    d = dict(hd.default_params)
    for j in range(1, N + 1):
        k, t = rng.uniform(0.8, 1.2, 2)
        d.update({f"{c}_{j}": k * d[f"{c}_{j}"] for c in ("K_1", "K_2", "K_3")})
        d.update({f"{c}_{j}": t * d[f"{c}_{j}"] for c in ("T_1", "T_2")})
        d.update({f"F_c_{j}": rng.uniform(0.2, 1.0), f"F_s_{j}": rng.uniform(0.2, 1.5), f"v_s_{j}": rng.uniform(0.1, 0.5),
                  f"v_c_{j}": rng.uniform(0.05, 0.3), f"Jm{j}": d[f"Jm{j}"] * rng.uniform(0.8, 1.2),
                  f"Bm{j}": rng.uniform(0.0, 0.5)})
    d.update(m_load=0.7, x_load=0.01, y_load=-0.02, z_load=0.1)
    return d


def _state(rng, p):
    """A state whose deflections run over the declared ranges (both breakpoints of every curve)."""
    q = rng.uniform(-1.5, 1.5, N)
    return np.concatenate([q, rng.normal(0, 0.8, N), q + rng.uniform(-1, 1, N) * 6e-3, rng.normal(0, 0.8, N)])


def _curve(p, j):
    return tuple(p[f"{c}_{j}"] for c in CURVE)


def test_linear_curves_without_friction_are_the_panda(hd, panda):
    K = [1e4] * 4 + [3e3] * 3
    d = dict(hd.default_params)
    for j in range(1, N + 1):
        d.update({f"{c}_{j}": K[j - 1] for c in ("K_1", "K_2", "K_3")})
        d.update({f"F_c_{j}": 0.0, f"F_s_{j}": 0.0})
    ph, pl = hd.params_array(d), panda.params_array(panda.default_params)
    rng = np.random.default_rng(3)
    for _ in range(4):
        x = rng.uniform(-1, 1, 4 * N)
        for name in ("f", "g", "T", "alpha", "beta", "ad", "energy", "inertia"):
            a, b = np.asarray(hd.functions[name](x, ph)), np.asarray(panda.functions[name](x, pl))
            assert np.max(np.abs(a - b)) <= 1e-12 * max(1.0, np.max(np.abs(b))), name
        m = np.concatenate([x[:2 * N], rng.normal(0, 20, 2 * N), x[3 * N:]])
        for name in ("T_tau", "alpha_tau", "beta_tau"):
            a, b = np.asarray(hd.torque_functions[name](m, ph)), np.asarray(panda.torque_functions[name](m, pl))
            assert np.max(np.abs(a - b)) <= 1e-12 * max(1.0, np.max(np.abs(b))), name


def test_spring_functions_are_the_datasheet_curves_and_invert(hd):
    rng = np.random.default_rng(4)
    p = _params(rng, hd)
    pv = hd.params_array(p)
    spring, inverse = hd.spring_functions["spring"], hd.spring_functions["spring_inverse"]
    grid = np.linspace(-0.01, 0.01, 4001)
    for k in range(0, grid.size, 7):
        phi = grid[(k + np.arange(N) * 577) % grid.size]  # every joint its own deflection
        psi, dpsi, _ = (np.asarray(v).ravel() for v in spring(phi, pv))
        want = np.array([datasheet(phi[j - 1], *_curve(p, j)) for j in range(1, N + 1)])
        assert np.allclose(psi, want[:, 0], rtol=1e-12, atol=1e-9) and np.allclose(dpsi, want[:, 1], rtol=1e-12)
        assert np.max(np.abs(np.asarray(inverse(psi, pv)).ravel() - phi)) <= 1e-12


def test_f_is_the_panda_link_row_and_the_motor_equation(hd, panda):
    rng = np.random.default_rng(5)
    for _ in range(6):
        p = _params(rng, hd)
        pv = hd.params_array(p)
        x = _state(rng, p)
        q, dq, qm, dqm = (x[i * N:(i + 1) * N] for i in range(4))
        psi = np.array([datasheet(qm[j - 1] - q[j - 1], *_curve(p, j))[0] for j in range(1, N + 1)])
        f = np.asarray(hd.f(x, p)).ravel()
        # the linear model at the same rigid body, its springs carrying psi: q_m' = q + psi / K
        pl = dict(panda.default_params, m_load=p["m_load"], x_load=p["x_load"], y_load=p["y_load"],
                  z_load=p["z_load"])
        K = np.array([pl[f"K{j}"] for j in range(1, N + 1)])
        fl = np.asarray(panda.f(np.concatenate([q, dq, q + psi / K, dqm]), pl)).ravel()
        assert np.allclose(f[:2 * N], fl[:2 * N], rtol=1e-10, atol=1e-10) and np.array_equal(f[2 * N:3 * N], dqm)
        Jm, Bm = (np.array([p[f"{g}{j}"] for j in range(1, N + 1)]) for g in ("Jm", "Bm"))
        F = np.array([_friction(dqm[j - 1], p, j) for j in range(1, N + 1)])
        assert np.allclose(f[3 * N:], (-psi - Bm * dqm - F) / Jm, rtol=1e-10, atol=1e-9)
        assert np.allclose(np.asarray(hd.g(x, p)), np.vstack([np.zeros((3 * N, N)), np.diag(1 / Jm)]))


def _along(hd, pv):
    """CasADi AD of the emitted T and energy along the closed-loop field f + g u."""
    x, u = ca.SX.sym("x", 4 * N), ca.SX.sym("u", N)
    xd = hd.functions["f"](x, pv) + ca.mtimes(hd.functions["g"](x, pv), u)
    return ca.Function("d", [x, u], [ca.jtimes(hd.functions["T"](x, pv), x, xd),
                                     ca.jtimes(hd.functions["energy"](x, pv), x, xd)])


def test_lie_identities_and_energy_balance(hd):
    rng = np.random.default_rng(6)
    p = _params(rng, hd)
    pv = hd.params_array(p)
    d = _along(hd, pv)
    Jm, Bm = (np.array([p[f"{g}{j}"] for j in range(1, N + 1)]) for g in ("Jm", "Bm"))
    for _ in range(8):
        x = _state(rng, p)
        nu = rng.normal(0, 2, N)
        alpha, beta = np.asarray(hd.alpha(x, p)).ravel(), np.asarray(hd.beta(x, p))
        u = alpha + beta @ nu
        dT, dE = (np.asarray(v).ravel() for v in d(x, u))
        T = np.asarray(hd.T(x, p)).ravel()
        assert np.max(np.abs(dT[:3 * N] - T[N:])) <= 1e-12 * max(1.0, np.max(np.abs(T[N:])))
        # d/dt y4 = L_f y4 + L_g y4 u = nu: on the scale of L_f y4, the term u cancels
        scale = np.max(np.abs(np.asarray(d(x, np.zeros(N))[0]).ravel()[3 * N:])) + 1.0
        assert np.max(np.abs(dT[3 * N:] - nu)) <= 1e-12 * scale, (np.max(np.abs(dT[3 * N:] - nu)), scale)
        dqm = x[3 * N:]
        F = np.array([_friction(dqm[j - 1], p, j) for j in range(1, N + 1)])
        power = dqm @ (u - Bm * dqm - F)
        assert abs(dE[0] - power) <= 1e-10 * max(1.0, abs(power), np.max(np.abs(u * dqm)))


def test_torque_functions_equal_the_state_ones_at_the_implied_measurement(hd):
    rng = np.random.default_rng(7)
    p = _params(rng, hd)
    pv = hd.params_array(p)
    for _ in range(6):
        x = _state(rng, p)
        q, dq, qm, dqm = (x[i * N:(i + 1) * N] for i in range(4))
        psi, dpsi, _ = (np.asarray(v).ravel() for v in hd.spring_functions["spring"](qm - q, pv))
        m = np.concatenate([q, dq, psi, dpsi * (dqm - dq), dqm])
        for tau, state in (("T_tau", "T"), ("alpha_tau", "alpha"), ("beta_tau", "beta")):
            a, b = np.asarray(hd.torque_functions[tau](m, pv)), np.asarray(hd.functions[state](x, pv))
            assert np.max(np.abs(a - b)) <= 1e-9 * max(1.0, np.max(np.abs(b))), tau


@pytest.mark.parametrize("bad, expected", [({"K_2_3": 1.0e4}, "joint 3"), ({"T_2_6": 1.0}, "T_1 < T_2"),
                                           ({"w_blend_7": 5e-3}, "w_blend_7"), ({"K_1_2": -1.0}, "> 0"),
                                           ({"F_c_5": -0.1}, ">= 0"), ({"v_c_1": 0.0}, "> 0")])
def test_non_physical_drive_parameters_are_one_line_errors(hd, bad, expected):
    with pytest.raises(fjm_runtime.FjmValueError) as info:
        hd.f(np.zeros(4 * N), bad)
    msg = str(info.value)
    assert "\n" not in msg and expected in msg, msg
