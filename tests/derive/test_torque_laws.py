"""The torque-sensed derivation, checked by numbers against the state derivation and the model.

* ``T_tau`` of the measurement built from ``x`` under ANY true stiffness equals the true
  ``T(x; p_true)``: torque sensing removes K from y3, y4.
* With ``Gamma = K K_nom^-1``: ``beta_tau(m; p_nom) = Gamma beta(x; p_true)`` and
  ``alpha_tau - c = Gamma (alpha - c)`` with ``c = tau_J + J_m y3 + B_m dq_m`` (the design
  note's form without ``B_m dq_m`` holds when ``B_m = 0``, also checked).
* Exact stiffness: ``u = alpha_tau + beta_tau nu`` gives ``y4' = nu``, with ``y4'`` taken from
  the emitted state ``T``'s Jacobian times ``f + g u`` (independent of the torque derivation).
* Motor PD + gravity: rest at the set point under ``K = K_nom``; the static link offset
  ``(K_nom^-1 - K^-1) G(q_d)`` to first order otherwise.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.drives import drive_indices, linear_stiffness_indices
from fjm_runtime.control.sensing import torque_measurement
from support.numerics import random_params, random_state

MODELS = ("link1", "planar2", "planar3", "elbow3", "panda")
POINTS = 3


def _case(model, rng, damping=True):
    """x, p_true, p_nom (p_nom = p_true with K scaled per joint by U[0.7, 1.3]), K_true, Gamma."""
    iK = linear_stiffness_indices(model, "torque sensing")
    p_true = random_params(model, rng, damping=damping)
    K = p_true[iK]
    p_nom = p_true.copy()
    p_nom[iK] = K / rng.uniform(0.7, 1.3, model.n)
    return random_state(model, rng), p_true, p_nom, K, K / p_nom[iK]


def _tf(model, name, meas, p):
    return np.asarray(model.torque_functions[name](meas, p))


def _rel(a, b):
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


@pytest.mark.parametrize("name", MODELS)
def test_torque_coordinates_exact_under_any_stiffness(name):
    m = fjm_runtime.load(name)
    rng = np.random.default_rng(7)
    for _ in range(POINTS):
        x, p_true, p_nom, K, _ = _case(m, rng)
        T_tau = _tf(m, "T_tau", torque_measurement(x, K), p_nom).ravel()
        T_true = m.T(x, p_true)
        T_nom = m.T(x, p_nom)  # the state law's coordinates under the wrong K: visibly off
        assert _rel(T_tau, T_true) < 1e-10
        assert _rel(T_nom, T_true) > 1e-6


@pytest.mark.parametrize("name", MODELS)
def test_stiffness_error_is_a_matched_input_gain(name):
    m = fjm_runtime.load(name)
    n = m.n
    iJ, iB = drive_indices(m, "rotor_inertia"), drive_indices(m, "damping")
    rng = np.random.default_rng(11)
    for damping in (True, False):
        for _ in range(POINTS):
            x, p_true, p_nom, K, gamma = _case(m, rng, damping=damping)
            meas = torque_measurement(x, K)
            beta_tau = _tf(m, "beta_tau", meas, p_nom)
            beta = m.beta(x, p_true)
            assert _rel(beta_tau, gamma[:, None] * beta) < 1e-9
            alpha_tau = _tf(m, "alpha_tau", meas, p_nom).ravel()
            alpha = m.alpha(x, p_true)
            y3 = m.T(x, p_true)[2 * n:3 * n]
            c = meas[2 * n:3 * n] + p_nom[iJ] * y3 + p_nom[iB] * x[3 * n:]
            scale = max(np.max(np.abs(alpha)), np.max(np.abs(c)))
            assert np.max(np.abs((alpha_tau - c) - gamma * (alpha - c))) < 1e-9 * scale
            if not damping:  # the design note's form: c without B_m dq_m
                c0 = meas[2 * n:3 * n] + p_nom[iJ] * y3
                assert np.max(np.abs((alpha_tau - c0) - gamma * (alpha - c0))) < 1e-9 * scale
            # the identity is not vacuous: alpha_tau differs from the state alpha by the gain error
            assert np.max(np.abs(alpha_tau - alpha)) > 1e-6 * scale


def _y4_rate(m, x, p, u):
    """d/dt of y4 = T(x; p)[3n:] under f + g u, via the emitted T's Jacobian (CasADi AD), shape (n,)."""
    xs = ca.MX.sym("x", m.nx)
    jac = ca.Function("jT", [xs], [ca.jacobian(m.functions["T"](xs, ca.DM(p)), xs)])
    xdot = m.xdot(x, u, p)
    J = np.asarray(jac(x))[3 * m.n:]
    return J @ xdot, np.abs(J) @ np.abs(xdot)  # the rate, and the size of the terms it sums


@pytest.mark.parametrize("name", MODELS)
def test_exact_stiffness_linearizes(name):
    m = fjm_runtime.load(name)
    rng = np.random.default_rng(5)
    iK = linear_stiffness_indices(m, "torque sensing")
    for _ in range(2):
        x = random_state(m, rng)
        p = random_params(m, rng)
        meas = torque_measurement(x, p[iK])
        nu = rng.uniform(-50, 50, m.n)
        u = _tf(m, "alpha_tau", meas, p).ravel() + _tf(m, "beta_tau", meas, p) @ nu
        rate, size = _y4_rate(m, x, p, u)
        assert np.all(np.abs(rate - nu) < 1e-11 * size + 1e-9 * np.max(np.abs(nu)))


def _gravity(m, q, p):
    """G(q) from the plant: at rest with a relaxed spring the links accelerate by -D^-1 G."""
    n = m.n
    x0 = np.concatenate([q, np.zeros(n), q, np.zeros(n)])
    return -m.inertia(x0, p) @ m.f(x0, p)[n:2 * n]


def _pdg(m, x, q_d, p_nom, k_p, k_d):
    r = np.zeros(5 * m.n)
    r[:m.n] = q_d
    gains = np.concatenate([k_p, k_d, np.ones(m.n), [0.0]])
    u, s, _, _, _ = m.controls["control_pdg"](x, np.zeros(0), r, p_nom, gains)
    return np.asarray(u).ravel(), np.asarray(s).ravel()


def _rest(m, q_d, p_true, p_nom, k_p, k_d, x0):
    """Closed-loop equilibrium (q, q_m with zero rates) by Newton on the link and motor accelerations."""
    n = m.n

    def res(v):
        x = np.concatenate([v[:n], np.zeros(n), v[n:], np.zeros(n)])
        xd = m.xdot(x, _pdg(m, x, q_d, p_nom, k_p, k_d)[0], p_true)
        return np.concatenate([xd[n:2 * n], xd[3 * n:]])

    v = np.concatenate([x0[:n], x0[2 * n:3 * n]])
    for _ in range(30):
        r = res(v)
        h = 1e-7
        J = np.column_stack([(res(v + h * e) - res(v - h * e)) / (2 * h) for e in np.eye(2 * n)])
        v = v - np.linalg.solve(J, r)
    return v[:n], v[n:]


@pytest.mark.parametrize("name", ("link1", "planar2", "planar3", "panda"))
def test_pdg_rest_and_stiffness_offset(name):
    m = fjm_runtime.load(name)
    n = m.n
    rng = np.random.default_rng(3)
    iK = linear_stiffness_indices(m, "torque sensing")
    p_nom = m.params_array(None)
    K_nom = p_nom[iK]
    q_d = rng.uniform(-0.8, 0.8, n)
    G = _gravity(m, q_d, p_nom)
    assert np.max(np.abs(G)) > 1e-3  # gravity is acting: the test is not vacuous
    k_p, k_d = 5.0 * K_nom, np.sqrt(K_nom)
    x_star = np.concatenate([q_d, np.zeros(n), q_d + G / K_nom, np.zeros(n)])
    u, s = _pdg(m, x_star, q_d, p_nom, k_p, k_d)
    assert np.max(np.abs(u - G)) < 1e-9 * np.max(np.abs(G))
    assert np.max(np.abs(s)) < 1e-12
    assert np.max(np.abs(m.xdot(x_star, u, p_nom))) < 1e-8 * max(1.0, np.max(np.abs(G)))
    # true stiffness K != K_nom: the links settle off q_d by (K_nom^-1 - K^-1) G(q_d) to first order
    for eps in (0.02, 0.01):
        K = K_nom * (1 + eps * rng.choice([-1.0, 1.0], n))
        p_true = p_nom.copy()
        p_true[iK] = K
        q, _ = _rest(m, q_d, p_true, p_nom, k_p, k_d, x_star)
        e, predicted = q - q_d, (1 / K_nom - 1 / K) * G
        # first order in the stiffness error AND in the gravity gradient over the stiffness
        dG = np.column_stack([(_gravity(m, q_d + 1e-6 * v, p_nom) - _gravity(m, q_d - 1e-6 * v, p_nom)) / 2e-6
                              for v in np.eye(n)])
        coupling = np.linalg.norm((1 / K + 1 / k_p)[:, None] * dG, 2)
        assert np.max(np.abs(e - predicted)) <= (3 * coupling + 3 * eps) * np.max(np.abs(predicted)) + 1e-12
