"""The coupling-compensated law for complete models (fjm_runtime.control.coupling).

Checked against the model equations, not against the module's own formulas: the link-side and
motor-side terms are the residuals of the REDUCED equations under the COMPLETE model's
accelerations (f + g u of both emitted models); at rest they are S ddq_m with S the emitted
coupling; with the implicit torque solved, the law's y3 is the complete plant's link acceleration;
and on a short planar2_complete run the compensated law tracks better than the uncompensated one.
"""
import numpy as np
import pytest

from fjm_runtime import load
from fjm_runtime.control.coupling import (CouplingCompensatedController, complete_plant,
                                          measured_coupling_function)
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import Sinusoid
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.validation import FjmValueError


@pytest.fixture(scope="module")
def pair():
    return load("planar2"), load("planar2_complete")


def _param(model, p, name):
    names = list(model.param_names)
    return np.array([p[names.index(f"{name}{i + 1}")] for i in range(model.n)])


@pytest.mark.parametrize("names", [("planar2", "planar2_complete"), ("panda", "panda_complete")])
def test_terms_are_the_reduced_equations_residuals(names):
    red, comp = load(names[0]), load(names[1])
    n, rng = comp.n, np.random.default_rng(7)
    p = comp.params_array()
    fn = measured_coupling_function(comp, red, p)
    for _ in range(2):
        x, u = 0.4 * rng.standard_normal(4 * n), rng.standard_normal(n)
        _, _, d_l, d_m = (np.asarray(v).ravel() for v in fn(x, u))
        a = comp.xdot(x, u)                                  # complete accelerations under u
        ddq, ddq_m = a[n:2 * n], a[3 * n:]
        a_r = red.f(x)                                       # reduced accelerations at u = 0
        D, Jm = red.inertia(x), _param(comp, p, "Jm")
        # reduced link eq D ddq + h + K (q - q_m) = -d_l, with h + K (q - q_m) = -D a_r,q
        exp_l = D @ (a_r[n:2 * n] - ddq)
        np.testing.assert_allclose(d_l, exp_l, rtol=1e-9, atol=1e-11 * np.abs(exp_l).max())
        # reduced motor eq J_m ddq_m + B dq_m - K (q - q_m) = u - d_m, with B dq_m - K (q - q_m) = -J_m a_r,m
        exp_m = u - Jm * (ddq_m - a_r[3 * n:])
        np.testing.assert_allclose(d_m, exp_m, rtol=1e-9, atol=1e-11 * np.abs(exp_m).max())


def test_link_term_at_rest_without_gravity_is_S_ddq_m(pair):
    red, comp = pair
    n, rng = comp.n, np.random.default_rng(3)
    p = comp.params_array({"g0": 0.0})
    x = np.concatenate([rng.uniform(-1, 1, n), np.zeros(n), rng.uniform(-1, 1, n), np.zeros(n)])
    u = rng.standard_normal(n)
    _, _, d_l, _ = (np.asarray(v).ravel() for v in measured_coupling_function(comp, red, p)(x, u))
    a = comp.xdot(x, u, p)
    D_complete = comp.inertia(x, p)[:n, :n]
    expected = comp.coupling(x, p) @ a[3 * n:] + (D_complete - red.inertia(x, p[:len(red.param_names)])) @ a[n:2 * n]
    assert np.max(np.abs(comp.coupling(x, p) @ a[3 * n:])) > 1e-2      # the coupling is not negligible here
    np.testing.assert_allclose(d_l, expected, rtol=1e-9, atol=1e-12)


def test_implicit_law_sees_the_true_link_acceleration(pair):
    red, comp = pair
    rng = np.random.default_rng(1)
    law = make_controller("ismc", red, red.default_params, lam=10.0, k_s=200.0, delta=1.0)
    c = CouplingCompensatedController(law, comp, dt=1e-3, newton=4)
    x = 0.3 * rng.standard_normal(8)
    z, r = np.concatenate([np.zeros(2), rng.standard_normal(2)]), rng.standard_normal((5, 2))
    s = c.evaluate(0.0, x, z, r)
    np.testing.assert_allclose(s.y_hat[2], comp.xdot(x, s.u)[2:4], rtol=1e-8, atol=1e-9)
    s_red = law.evaluate(0.0, x, z[:2], r)          # the uncompensated law's y3 is off
    assert np.max(np.abs(s_red.y_hat[2] - comp.xdot(x, s_red.u)[2:4])) > 1.0


def test_compensated_law_tracks_better_on_planar2_complete(pair):
    red, comp = pair
    plant, ref, dt = complete_plant(comp), Sinusoid([0.5, 0.5], [2.0, 3.0], n=2), 1e-3

    def worst(ctrl):
        r = simulate(plant, ctrl, ref, duration=1.0, dt=dt, backend="casadi")
        return np.sqrt(np.mean(r.e1[r.t >= 0.5] ** 2, axis=0)).max()

    law = lambda: make_controller("ismc", red, red.default_params, lam=10.0, k_s=200.0, delta=1.0)  # noqa: E731
    plain, compensated = worst(law()), worst(CouplingCompensatedController(law(), comp, dt=dt))
    # measured: 0.149 vs 0.050 rad (ratio 3.0)
    assert compensated < 0.5 * plain


def test_predictor_of_the_compensated_law_is_the_nominal_complete_model(pair):
    """One sample of delay with prediction: the predictor integrates the controller's NOMINAL complete
    model (f, g only: a complete model has no T, alpha, beta). Without noise and with the plant at the
    nominal values it recovers the current state exactly, so the run equals the undelayed one to
    rounding; with a plant away from the nominal values it does not (the predictor is not the plant)."""
    red, comp = pair
    plant, ref, dt = complete_plant(comp), Sinusoid([0.5, 0.5], [2.0, 3.0], n=2), 1e-3
    law = lambda: make_controller("ismc", red, red.default_params, lam=10.0, k_s=200.0, delta=1.0)  # noqa: E731

    def run(delay, true=None):
        ctrl = CouplingCompensatedController(law(), comp, dt=dt)
        return simulate(plant, ctrl, ref, duration=0.3, dt=dt, backend="casadi", delay_samples=delay,
                        predict=delay > 0, true_params=true, interface="ideal").u  # the predictor has no current loop

    u0, u1 = run(0), run(1)
    assert np.max(np.abs(u1 - u0)) <= 1e-9 * np.max(np.abs(u0))
    off = {"K1": 1.05 * comp.default_params["K1"], "K2": 0.95 * comp.default_params["K2"]}
    assert np.max(np.abs(run(1, off) - run(0, off))) > 1e-6 * np.max(np.abs(u0))


def test_bad_pairs_are_refused(pair):
    red, comp = pair
    law = make_controller("ismc", red, red.default_params, lam=10.0, k_s=200.0, delta=1.0)
    with pytest.raises(FjmValueError, match="expected a complete model"):
        CouplingCompensatedController(law, red, dt=1e-3)
    with pytest.raises(FjmValueError, match="reduced model 'planar2'"):
        CouplingCompensatedController(law, load("panda_complete"), dt=1e-3)
    with pytest.raises(FjmValueError, match="dt"):
        CouplingCompensatedController(law, comp, dt=0.0)
    with pytest.raises(FjmValueError, match="source"):
        CouplingCompensatedController(law, comp, dt=1e-3, source="oracle")
