"""Regulation with the motor-side impedance: at a constant reference the flatness feedforward IS the motor-side
gravity compensation (tau_Jd = g(q_d), theta_d = q_d + psi^-1(g(q_d)), u_ff = tau_Jd, to rounding), the fixed
point of Ott et al.'s iteration q_bar <- theta_d - psi^-1(g(q_bar)), which reaches q_d from theta_d where its
contraction factor ||psi'^-1 dg/dq|| < 1; a set point where it is not is refused in one line."""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.cli.main import main
from fjm_runtime.control.impedance import regulation_contraction, regulation_motor_position
from fjm_runtime.drives import model_springs
from fjm_runtime.sim.interface import gravity_function
from fjm_runtime.sim.rest import rest_state
from fjm_runtime.validation import FjmValueError


def _set_point(m):
    return np.linspace(0.3, -0.4, m.n) + 0.1 * np.arange(m.n) % 0.3


@pytest.mark.parametrize("name", ["panda", "planar2", "link1_hd"])
def test_constant_reference_feedforward_is_gravity_on_the_motor(name):
    """Against two independent routes: the gravity of the model's energy, and the rest state computed from the
    model's dynamics f (sim/rest.py)."""
    m = fjm_runtime.load(name)
    p = m.params_array(None)
    q_d = _set_point(m)
    tau_Jd, theta_d, dtheta_d, ddtheta_d, u_ff = m.feedforward(np.concatenate([q_d, np.zeros(4 * m.n)]), p)
    g = np.asarray(gravity_function(m)(q_d, p), dtype=float).ravel()
    scale = max(1.0, np.max(np.abs(g)))
    assert np.max(np.abs(g)) > 1e-3                                      # gravity acts at this pose
    assert np.max(np.abs(tau_Jd - g)) <= 1e-12 * scale
    assert np.max(np.abs(u_ff - tau_Jd)) <= 1e-12 * scale
    assert np.max(np.abs(theta_d - rest_state(m, q_d, p)[2 * m.n:3 * m.n])) <= 1e-12
    # zero up to rounding: at rest the second derivative still forms v' x P' of the subtrees, two parallel vectors
    # (gravity's upward acceleration and the subtree's momentum rate), ~1e-17 (derive/emit/rnea_jets.py)
    assert np.all(dtheta_d == 0.0) and np.max(np.abs(ddtheta_d)) <= 1e-12
    assert np.array_equal(regulation_motor_position(m, q_d, p), theta_d)


@pytest.mark.parametrize("name", ["panda", "planar2", "link1_hd"])
def test_the_fixed_point_iteration_from_theta_d_reaches_the_set_point(name):
    """q_bar <- theta_d - psi^-1(g(q_bar)) from q_bar = theta_d: the error shrinks at least by the factor rho
    (measured at q_d, with 20 % for the pose moving over the first steps) and reaches q_d to 1e-12."""
    m = fjm_runtime.load(name)
    p = m.params_array(None)
    q_d = _set_point(m)
    theta_d = regulation_motor_position(m, q_d, p)
    rho = regulation_contraction(m, q_d, p)
    g, inv = gravity_function(m), model_springs(m)["spring_inverse"]
    q, errors = theta_d.copy(), []
    for _ in range(60):
        q = theta_d - np.asarray(inv(np.asarray(g(q, p), dtype=float).ravel(), p), dtype=float).ravel()
        errors.append(np.linalg.norm(q - q_d))
    print(f"{name}: rho {rho:.3g}, errors {errors[0]:.3g} -> {errors[-1]:.3g}")
    assert 0 < rho < 1 and errors[-1] <= 1e-12
    ratios = [b / a for a, b in zip(errors, errors[1:]) if a > 1e-10]
    assert ratios and max(ratios) <= 1.2 * rho


def test_contraction_factor_is_the_gravity_gradient_over_the_stiffness():
    """link1 (a pendulum, g(q) = M g0 L sin q, linear spring K): rho = M g0 L |cos q_d| / K."""
    m = fjm_runtime.load("link1")
    p = dict(m.default_params)
    for q_d, K in ((0.5, 150.0), (1.0, 5.0), (2.5, 30.0)):
        expected = p["M"] * p["g0"] * p["L"] * abs(np.cos(q_d)) / K
        assert regulation_contraction(m, [q_d], {**p, "K": K}) == pytest.approx(expected, rel=1e-12)


def test_a_set_point_where_the_iteration_does_not_contract_is_refused(capsys):
    m = fjm_runtime.load("link1")
    with pytest.raises(FjmValueError) as e:                      # rho = 9.8 cos(1) / 5 = 1.06
        regulation_motor_position(m, [1.0], {"K": 5.0})
    assert "\n" not in str(e.value) and "1.06" in str(e.value)
    status = main(["simulate", "link1", "--controller", "impedance", "--reference", "constant", "--q-d", "1",
                   "--nominal", "K=5", "--duration", "0.1"])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and "--q-d" in err and "1.06" in err
    status = main(["simulate", "link1", "--controller", "impedance", "--reference", "constant", "--q-d", "1",
                   "--nominal", "K=6", "--duration", "0.1", "--json"])           # rho = 0.88: runs
    assert status == 0
