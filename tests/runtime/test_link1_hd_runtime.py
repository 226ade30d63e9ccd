"""link1_hd through the runtime: the contract, the emitted laws, and a closed loop that converges.

The plant has the cubic spring psi(phi) = k1 phi + k3 phi^3 (generated/link1_hd); the
feedback-linearizing law derived for that spring must close the loop exactly (error dynamics
(s + lam)^4 with an ideal sensor), and the torque-sensed law at the measurement the state
implies (tau_J = psi(phi), dtau_J = psi'(phi) (dq_m - dq)) must command the state law's torque.
"""

from __future__ import annotations

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime import make_controller, make_reference, simulate
from fjm_runtime.model import _read_function
from scipy.linalg import expm


@pytest.fixture(scope="module")
def model():
    return fjm_runtime.load("link1_hd")


def test_contract(model):
    assert model.n == 1 and model.nx == 4
    assert model.param_names == ("J_l", "J_m", "k1", "k3", "M", "g0", "L", "B_m", "F_c", "F_s", "v_s", "v_c")
    assert model.default_params["k1"] == 75.0 and model.default_params["k3"] == 2500.0
    assert model.default_params["F_c"] == model.default_params["F_s"] == 0.0  # the paper's link: no friction
    x = np.array([0.3, -0.2, 0.4, 0.5])  # phi = 0.1: psi' = 75 + 3 * 2500 * 0.01 = 150
    assert model.f(x).shape == (4,) and model.T(x).shape == (4,) and model.alpha(x).shape == (1,)
    assert model.beta(x)[0, 0] == pytest.approx(1.0 * 2.0 / 150.0, rel=1e-14)  # J_l J_m / psi'(0.1)
    assert model.f(x)[1] == pytest.approx(75 * 0.1 + 2500 * 0.1 ** 3 - 9.8 * np.sin(0.3), rel=1e-14)
    assert set(model.manifest["controls"]) == {"smc", "ismc", "fl", "smc_tau", "ismc_tau", "fl_tau", "impedance",
                                              "joint_impedance"}


@pytest.mark.parametrize("name, value, expected", [("F_c", -0.5, ">= 0"), ("F_s", float("nan"), "finite"),
                                                   ("v_c", 0.0, "> 0"), ("v_s", -1.0, "> 0")])
def test_non_physical_friction_is_a_one_line_error(model, name, value, expected):
    with pytest.raises(fjm_runtime.FjmValueError) as info:
        model.f(np.zeros(4), {name: value})
    msg = str(info.value)
    assert "\n" not in msg and repr(name) in msg and expected in msg, msg


def test_torque_law_equals_state_law_at_the_implied_measurement(model):
    spring = _read_function(model.directory / "spring.casadi")
    p = model.params_array(None)
    rng = np.random.default_rng(11)
    gains = {"fl": np.array([4e3, 6e2, 40.0, 10.0, 50.0, 0.0, 0.0, 0.02])}
    for _ in range(5):
        q, dq, dqm, phi = rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-0.25, 0.25)
        x = np.array([q, dq, q + phi, dqm])
        psi, dpsi, _ = (float(v) for v in spring(phi, p))
        m = np.array([q, dq, psi, dpsi * (dqm - dq), dqm])
        r = rng.uniform(-1, 1, 5)
        lay = model.manifest["controls"]["fl"]["gains"]
        assert [b["name"] for b in lay] == ["c", "k_lin", "u_max", "limit", "use_beta_hat", "beta_hat"]
        u_x = model.controls["control_fl"](x, np.zeros(0), r, p, gains["fl"])[0]
        u_m = model.controls["control_fl_tau"](m, np.zeros(0), r, p, gains["fl"])[0]
        assert abs(float(u_x) - float(u_m)) <= 1e-11 * max(1.0, abs(float(u_x)))


def test_feedback_linearization_closes_the_loop(model):
    """fl (lam = 10) from a 0.2 rad error on a sine: the error decays as the quadruple pole says."""
    ref = make_reference("sine", 1, amplitude=0.5, omega=1.0)
    ctrl = make_controller("fl", model, model.default_params, lam=10.0)
    res = simulate(model, ctrl, ref, duration=3.0, dt=1e-3, x0=np.array([0.2, 0.0, 0.2, 0.0]))
    e = np.abs(res.e1.ravel())
    t = res.t.ravel()
    deflection = np.abs(res.x[:, 2] - res.x[:, 0])
    # the error obeys (d/dt + 10)^4 e = 0 from the initial linearizing-coordinate error (sampled at 1 kHz)
    e0 = (res.y_hat[0] - res.ref[0, :4]).ravel()
    A = np.diag(np.ones(3), 1)
    A[3] = -np.array([1e4, 4e3, 6e2, 40.0])
    step = expm(A * (t[10] - t[0]))  # every 10th sample
    predicted, z = [], e0
    for _ in t[::10]:
        predicted.append(z[0])
        z = step @ z
    deviation = np.abs(res.e1.ravel()[::10] - np.array(predicted)).max()
    print(f"link1_hd fl: max |e1 - continuous prediction| = {deviation:.2e} rad, e1(0) = {e0[0]:.2f}, "
          f"|e1| after 2.5 s <= {np.abs(res.e1.ravel()[t > 2.5]).max():.1e}")
    assert deviation < 2e-3 * abs(e0[0]), deviation
    assert e[t > 2.5].max() < 1e-4
    assert deflection.max() < 0.25  # stayed in the declared range, where psi' > 0
    assert deflection.max() > 0.04  # and deep enough that the cubic term matters (psi' > 87 N m/rad)
