"""fjm excite: rest-to-rest series, the nominal model's exact inverse, better conditioned than a random draw,
within the Panda's limits, bad settings refused in one line.

Independent references: central differences for the derivatives; the model's own linearizing
coordinates inverted by Newton (``analysis.certificates.evaluator.inverse_T``) and its emitted ``alpha``, ``beta``
(``u = alpha + beta q_d''''``) for the flat-output inverse; link1's gravity torque ``M g0 L sin q`` at rest;
the condition numbers recomputed here with ``numpy.linalg.cond``.
"""

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.cli.main import main as fjm_main
from fjm_runtime.ident.excite import (FourierReference, design_excitation, nominal_motion, rest_coefficients,
                                      whole_periods)
from fjm_runtime.ident.excite_loop import read_excitation
from fjm_runtime.validation import FjmValueError


def _cond(traj, v_c=0.01):
    """Worst joint's condition number, computed here: motor [ddq_m, dq_m, tanh], spring [phi, 1]."""
    worst = 0.0
    for i in range(traj["q"].shape[1]):
        dqm, phi = traj["dqm"][:, i], traj["phi"][:, i]
        for A in (np.column_stack([traj["ddqm"][:, i], dqm, np.tanh(dqm / v_c)]),
                  np.column_stack([phi, np.ones_like(phi)])):
            worst = max(worst, np.linalg.cond(A / np.linalg.norm(A, axis=0)))
    return worst


def _T_inverse(m, y, p):
    """``x`` with ``T(x) = y`` (the link half of ``T`` is the identity): Newton on the motor half, its
    Jacobian by central differences of the model's ``T``."""
    n = m.n
    x = np.concatenate([y[:2 * n], y[:2 * n]])
    res = lambda xm: m.T(np.concatenate([y[:2 * n], xm]), p)[2 * n:] - y[2 * n:]  # noqa: E731
    for _ in range(12):
        xm, h = x[2 * n:], 1e-6
        J = np.column_stack([(res(xm + h * e) - res(xm - h * e)) / (2 * h) for e in np.eye(2 * n)])
        x[2 * n:] = xm - np.linalg.solve(J, res(xm))
    assert np.max(np.abs(res(x[2 * n:]))) < 1e-9 * (1 + np.max(np.abs(y)))
    return x


def test_series_derivatives_and_rest_at_both_ends():
    rng = np.random.default_rng(0)
    a, b = rest_coefficients(rng.standard_normal((2, 4)), rng.standard_normal((2, 4)))
    ref = FourierReference([0.2, -0.1], a, b, 2.0)
    t, h = 0.37, 1e-5
    R = ref.sample([t - h, t, t + h])
    for k in range(4):
        np.testing.assert_allclose((R[2, k] - R[0, k]) / (2 * h), R[1, k + 1], rtol=1e-6, atol=1e-6)
    ends = ref.sample([0.0, ref.period, 3 * ref.period])
    np.testing.assert_allclose(ends[:, 0], [[0.2, -0.1]] * 3, atol=1e-12)
    np.testing.assert_allclose(ends[:, 1:], 0.0, atol=1e-11)             # derivatives 1..4 vanish
    assert np.max(np.abs(ref.sample(np.linspace(0, ref.period, 50))[:, 1])) > 0.1     # and it moves
    assert whole_periods(3.0, 0.2, 1000.0) == (1, pytest.approx(1 / 3), 3000)
    assert whole_periods(12.0, 0.2, 1000.0) == (3, pytest.approx(0.25), 4000)
    assert whole_periods(20.0, 0.2, 1000.0) == (4, pytest.approx(0.2), 5000)


@pytest.mark.parametrize("name", ["link1", "link1_hd", "planar2"])
def test_nominal_motion_is_the_models_flat_output_inverse(name):
    m = fjm_runtime.load(name)
    rng = np.random.default_rng(1)
    a, b = rest_coefficients(0.1 * rng.standard_normal((m.n, 5)), 0.1 * rng.standard_normal((m.n, 5)))
    ref = FourierReference(0.3 * np.ones(m.n), a, b, 2 * np.pi * 0.3)
    p = m.params_array({"B_m": 0.4} if "B_m" in m.param_names else {"Bm1": 0.4})
    t = np.linspace(0.0, 2.0, 23)
    tr = nominal_motion(m, ref, t, p)
    R = ref.sample(t)
    n = m.n
    X = np.array([_T_inverse(m, y, p) for y in R[:, :4, :].reshape(t.size, -1)])   # T(x) = [q_d, .., q_d''']
    np.testing.assert_allclose(tr["qm"], X[:, 2 * n:3 * n], atol=1e-10)
    np.testing.assert_allclose(tr["dqm"], X[:, 3 * n:], atol=1e-9)
    U = np.array([m.alpha(x, p) + m.beta(x, p) @ r[4] for x, r in zip(X, R)])
    np.testing.assert_allclose(tr["u"], U, rtol=1e-9, atol=1e-9 * np.max(np.abs(U)))
    ddqm = np.array([m.xdot(x, u, p)[3 * n:] for x, u in zip(X, U)])
    np.testing.assert_allclose(tr["ddqm"], ddqm, atol=1e-8 * np.max(np.abs(ddqm)))


def test_panda_excitation_within_limits_and_better_than_random():
    m = fjm_runtime.load("panda")
    exc = design_excitation(m, 3.0, candidates=3, iterations=4, seed=3)
    ref = exc.reference
    t = np.arange(3001) * 1e-3
    tr = nominal_motion(m, ref, t, m.params_array())
    np.testing.assert_allclose(tr["q"][[0, -1]], [ref.q0, ref.q0], atol=1e-12)
    np.testing.assert_allclose(tr["dq"][[0, -1]], 0.0, atol=1e-10)
    lo, hi = m.position_limits[:, 0], m.position_limits[:, 1]
    assert np.all(tr["q"] >= lo + 0.05) and np.all(tr["q"] <= hi - 0.05)
    assert np.all(np.abs(tr["dq"]) <= 0.5 * m.velocity_limits * (1 + 1e-9))
    assert np.all(np.abs(tr["u"]) <= 0.8 * m.effort_limits * (1 + 1e-9))
    assert np.max(np.abs(tr["dq"]) / m.velocity_limits) > 0.45        # it uses what it may
    assert _cond({k: v[:-1] for k, v in tr.items()}) == pytest.approx(exc.condition, rel=1e-9)   # one period
    # random series (rest-to-rest, scaled to the same velocity share): measured 5.8 to 25, median 11.8
    rng, random = np.random.default_rng(11), []
    for _ in range(5):
        a, b = rest_coefficients(rng.standard_normal((7, 5)), rng.standard_normal((7, 5)))
        rand = FourierReference(ref.q0, a, b, ref.w0)
        scale = 0.5 * m.velocity_limits / np.max(np.abs(rand.sample(t[::10])[:, 1]), axis=0)
        rand = FourierReference(ref.q0, a * scale[:, None], b * scale[:, None], ref.w0)
        random.append(_cond(nominal_motion(m, rand, t[:-1:10], m.params_array())))
    assert exc.condition < 0.7 * np.median(random), (exc.condition, random)


def test_bad_settings_are_refused_in_one_line(tmp_path, capsys):
    m = fjm_runtime.load("link1")
    with pytest.raises(FjmValueError, match="harmonics >= 3"):
        design_excitation(m, 4.0, harmonics=2)
    assert fjm_main(["excite", "link1", "--duration", "4", "--out", str(tmp_path / "x.csv"), "--posture", "0.1,0.2"]) != 0
    assert "--posture '0.1,0.2': expected 1 comma-separated angles" in capsys.readouterr().err
    with pytest.raises(FjmValueError, match="within 0.05 rad of the limits"):
        design_excitation(fjm_runtime.load("panda"), 4.0, q0=[0, 0, 0, 0, 0, 3.75, 0])
    (tmp_path / "bad.csv").write_text("t,q_d_1\n0,0\n")
    with pytest.raises(FjmValueError, match="no column dq_d_1"):
        read_excitation(tmp_path / "bad.csv", m)
