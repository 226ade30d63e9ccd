"""Torque-sensed controllers (fjm_runtime.control.sensing): the contract the simulators rely on."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.drives import linear_stiffness_indices
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.sensing import torque_measurement, torque_measurement_symbolic
from fjm_runtime.validation import FjmValueError

GAINS = {"smc": dict(lam=6.0, k_s=20.0, delta=0.5), "ismc": dict(lam=6.0, k_s=20.0, delta=0.5),
         "fl": dict(lam=6.0)}


def _state(m, rng):
    n = m.n
    q = rng.uniform(-1, 1, n)
    return np.concatenate([q, rng.uniform(-1, 1, n), q + rng.uniform(-0.05, 0.05, n), rng.uniform(-1, 1, n)])


@pytest.mark.parametrize("kind", ("smc", "ismc", "fl"))
def test_torque_law_equals_state_law_at_exact_stiffness(kind):
    m = fjm_runtime.load("planar2")
    rng = np.random.default_rng(2)
    p = m.params_array(None)
    K = p[linear_stiffness_indices(m, "torque sensing")]
    st = make_controller(kind, m, {}, **GAINS[kind])
    tq = make_controller(kind, m, {}, sensing="torque", **GAINS[kind])
    assert (st.sensing, st.measurement_size, tq.sensing, tq.measurement_size) == ("state", 8, "torque", 10)
    for _ in range(3):
        x = _state(m, rng)
        z = rng.uniform(-0.1, 0.1, st.n_states)
        r = rng.uniform(-1, 1, (5, m.n))
        a, b = st.evaluate(0.0, x, z, r), tq.evaluate(0.0, torque_measurement(x, K), z, r)
        assert np.allclose(a.u, b.u, rtol=1e-9, atol=1e-9 * np.max(np.abs(a.u)))
        assert np.allclose(a.y_hat, b.y_hat, rtol=1e-9, atol=1e-12)
        if st.n_states:
            da = st.state_derivative(0.0, x, z, r, a)
            db = tq.state_derivative(0.0, torque_measurement(x, K), z, r, b)
            assert np.allclose(da, db) and np.allclose(db, x[:m.n] - r[0])


def test_torque_law_sees_the_true_coordinates_under_wrong_stiffness():
    m = fjm_runtime.load("planar3")
    rng = np.random.default_rng(4)
    iK = linear_stiffness_indices(m, "torque sensing")
    p_true = m.params_array(None)
    p_true[iK] *= np.array([0.7, 1.3, 0.8])
    tq = make_controller("ismc", m, {}, sensing="torque", **GAINS["ismc"])
    st = make_controller("ismc", m, {}, **GAINS["ismc"])
    x = _state(m, rng)
    r = np.zeros((5, m.n))
    y_true = m.T(x, p_true).reshape(4, m.n)
    y_tq = tq.evaluate(0.0, torque_measurement(x, p_true[iK]), np.zeros(m.n), r).y_hat
    y_st = st.evaluate(0.0, x, np.zeros(m.n), r).y_hat
    assert np.max(np.abs(y_tq - y_true)) < 1e-10 * np.max(np.abs(y_true))
    assert np.max(np.abs(y_st - y_true)) > 1e-4 * np.max(np.abs(y_true))


def test_symbolic_evaluate_takes_the_measurement():
    m = fjm_runtime.load("planar2")
    rng = np.random.default_rng(6)
    K = m.params_array(None)[linear_stiffness_indices(m, "torque sensing")]
    tq = make_controller("ismc", m, {}, sensing="torque", **GAINS["ismc"])
    xs, zs, rs = ca.SX.sym("x", 8), ca.SX.sym("z", 2), ca.SX.sym("r", 10)
    ms = torque_measurement_symbolic(xs, K)
    out = tq.symbolic_evaluate(ms, zs, rs)
    zd = tq.symbolic_state_derivative(ms, zs, rs, out)
    fn = ca.Function("f", [xs, zs, rs], [out["u"], zd])
    x, z, r = _state(m, rng), rng.uniform(-0.1, 0.1, 2), rng.uniform(-1, 1, (5, 2))
    u, dz = (np.asarray(v).ravel() for v in fn(x, z, r.reshape(-1)))
    smp = tq.evaluate(0.0, torque_measurement(x, K), z, r)
    assert np.allclose(u, smp.u, rtol=1e-12, atol=1e-12)
    assert np.allclose(dz, tq.state_derivative(0.0, torque_measurement(x, K), z, r, smp))


def test_measurement_twins_and_errors():
    rng = np.random.default_rng(8)
    x = rng.uniform(-1, 1, (3, 12))
    K = rng.uniform(50, 500, 3)
    mm = torque_measurement(x, K)
    xs = ca.SX.sym("x", 12)
    f = ca.Function("m", [xs], [torque_measurement_symbolic(xs, K)])
    for row, ref in zip(x, mm):
        assert np.allclose(np.asarray(f(row)).ravel(), ref, rtol=1e-15, atol=0)
    assert np.allclose(mm[:, 6:9], K * (x[:, 6:9] - x[:, :3]))
    with pytest.raises(FjmValueError, match="stiffness"):
        torque_measurement(x[0], [1.0, -2.0, 3.0])
    with pytest.raises(FjmValueError, match="4n"):
        torque_measurement(np.zeros(7), 1.0)
    m = fjm_runtime.load("planar2")
    tq = make_controller("fl", m, {}, sensing="torque", lam=5.0)
    with pytest.raises(FjmValueError, match=r"expected \(10,\)"):
        tq.evaluate(0.0, np.zeros(8), np.zeros(0), np.zeros((5, 2)))
    for kind in ("adaptive", "sign", "pdg"):
        with pytest.raises(ValueError, match="sensing"):
            make_controller(kind, m, {}, sensing="torque", lam=5.0)
    with pytest.raises(ValueError, match="sensing"):
        make_controller("fl", m, {}, sensing="virtual", lam=5.0)
