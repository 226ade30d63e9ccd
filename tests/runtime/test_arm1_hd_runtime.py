"""arm1_hd: a one-link arm on a harmonic drive (three-segment datasheet spring, motor friction), checked
from first principles on the generated functions (derive/robots/arm1_hd/arm1_hd.toml).

Everything the model should be is written out here, independently of the derivation: the datasheet
curve (piecewise linear through (phi_1, T_1), (phi_2, T_2) with slopes K_1..K_3, each kink blended by
the integral of the quintic smoothstep), the link and motor equations, the energy. Checked against
them: f and g, the spring functions and their inverse, the Lie identities of T, alpha, beta by central
differences, the energy balance, the torque-coordinate law at the measurement a state implies, the
paper's rank condition, runtime parameter checks, and a closed loop whose deflection crosses the first
breakpoint (so the curve, not one stiffness, is what the law linearizes), exact as the period shrinks.
"""

from __future__ import annotations

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime import make_controller, make_reference, simulate

H = 1e-7  # central-difference step (deflections are milliradians)


@pytest.fixture(scope="module")
def model():
    return fjm_runtime.load("arm1_hd")


def datasheet(phi, K_1, K_2, K_3, T_1, T_2, w):
    """``(psi, psi')`` of the datasheet curve with quintic-smoothstep blends, written out here."""
    a, sign = abs(phi), np.sign(phi)
    b1 = T_1 / K_1
    b2 = b1 + (T_2 - T_1) / K_2
    psi, k = K_1 * a, K_1
    for step, b in ((K_2 - K_1, b1), (K_3 - K_2, b2)):
        t = np.clip((a - b + w / 2) / w, 0.0, 1.0)
        ramp = a - b if a - b >= w / 2 else w * (t ** 6 - 3 * t ** 5 + 2.5 * t ** 4)
        psi += step * ramp
        k += step * (6 * t ** 5 - 15 * t ** 4 + 10 * t ** 3)
    return sign * psi, k


def _curve(p: dict):
    return tuple(p[k] for k in ("K_1", "K_2", "K_3", "T_1", "T_2", "w_blend"))


def _friction(v, p):
    return (p["F_c"] + (p["F_s"] - p["F_c"]) * np.exp(-(v / p["v_s"]) ** 2)) * np.tanh(v / p["v_c"])


def _params(rng, model):
    """Defaults with every coefficient moved (the curve's order and blend limits kept)."""
    d = dict(model.default_params)
    s = rng.uniform(0.8, 1.2, 6)
    d.update(m1=d["m1"] * s[0], r1=d["r1"] * s[1], I1=d["I1"] * s[2], Jm1=d["Jm1"] * s[3], Bm1=0.2 * s[4],
             K_1=1.3e4 * s[5], K_2=1.7e4 * s[5], K_3=2.0e4 * s[5], T_1=14.0 * s[0], T_2=48.0 * s[1],
             F_c=0.8 * s[2], F_s=1.2 * s[3], v_s=0.3 * s[4], v_c=0.2 * s[5])
    return d


def _states(rng, count):
    """States with deflections over the declared range (both breakpoints and every blend window)."""
    for phi in np.concatenate([rng.uniform(-0.01, 0.01, count - 4), [1.08e-3, -1.1e-3, 3.1e-3, 6e-3]]):
        q, dq, dqm = rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-2, 2)
        yield np.array([q, dq, q + phi, dqm])


def test_contract_and_dynamics_written_out(model):
    names = ("m1", "l1", "r1", "I1", "K_1", "K_2", "K_3", "T_1", "T_2", "w_blend", "Jm1", "Bm1", "g0",
             "F_c", "F_s", "v_s", "v_c")
    assert model.param_names == names
    assert set(model.manifest["controls"]) == {"smc", "ismc", "fl", "smc_tau", "ismc_tau", "fl_tau", "impedance",
                                              "joint_impedance"}
    assert model.manifest["springs"]["joints"][0]["law"] == "three_segment"
    rng = np.random.default_rng(1)
    for _ in range(3):
        p = _params(rng, model)
        J = p["I1"] + p["m1"] * p["r1"] ** 2
        for x in _states(rng, 8):
            q, dq, qm, dqm = x
            psi, _ = datasheet(qm - q, *_curve(p))
            f, g = model.f(x, p), model.g(x, p).ravel()
            expect = [dq, (psi - p["m1"] * p["g0"] * p["r1"] * np.sin(q)) / J, dqm,
                      (-psi - p["Bm1"] * dqm - _friction(dqm, p)) / p["Jm1"]]
            assert np.allclose(f, expect, rtol=1e-12, atol=1e-9 * max(1.0, abs(psi))), (x, f, expect)
            assert np.allclose(g, [0, 0, 0, 1 / p["Jm1"]], rtol=1e-14)


def test_spring_functions_are_the_datasheet_curve_and_invert(model):
    spring, inverse = model.spring_functions["spring"], model.spring_functions["spring_inverse"]
    rng = np.random.default_rng(2)
    for _ in range(3):
        p = _params(rng, model)
        pv = model.params_array(p)
        for phi in np.concatenate([np.linspace(-0.02, 0.02, 201), [0.0, 1e-9]]):
            psi, dpsi, ddpsi = (float(v) for v in spring(phi, pv))
            want, k = datasheet(phi, *_curve(p))
            assert abs(psi - want) <= 1e-12 * max(1.0, abs(want)), (phi, psi, want)
            assert abs(dpsi - k) <= 1e-9 * k
            assert p["K_1"] - 1e-9 <= dpsi <= p["K_3"] + 1e-9
            fd = (float(spring(phi + H, pv)[1]) - float(spring(phi - H, pv)[1])) / (2 * H)
            assert abs(ddpsi - fd) <= 2e-4 * max(1.0, abs(fd)) + 1e-3 * p["K_3"], (phi, ddpsi, fd)  # H^2 psi''''
            assert abs(float(inverse(psi, pv)) - phi) <= 1e-13 + 1e-12 * abs(phi), phi


def test_lie_identities_by_differences(model):
    """y_{k+1} = L_f y_k and L_g y_k = 0 (k = 1..3), L_g y4 = 1/beta, L_f y4 = -alpha/beta; the rank."""
    rng = np.random.default_rng(3)
    p = _params(rng, model)
    along = lambda fn, x, v: (fn(x + H * v, p) - fn(x - H * v, p)) / (2 * H)  # noqa: E731
    for x in _states(rng, 10):
        f, g, T = model.f(x, p), model.g(x, p).ravel(), model.T(x, p)
        dT_f, dT_g = along(model.T, x, f), along(model.T, x, g)
        scale = np.max(np.abs(T)) + 1.0
        assert np.allclose(dT_f[:3], T[1:], rtol=1e-6, atol=1e-6 * scale), (x, dT_f[:3], T[1:])
        assert np.max(np.abs(dT_g[:3])) < 1e-6 * scale
        beta, alpha = model.beta(x, p)[0, 0], model.alpha(x, p)[0]
        assert dT_g[3] == pytest.approx(1.0 / beta, rel=1e-6)
        assert dT_f[3] == pytest.approx(-alpha / beta, rel=1e-5, abs=1e-5 * abs(1.0 / beta) * scale)
        _, k = datasheet(x[2] - x[0], *_curve(p))
        J = p["I1"] + p["m1"] * p["r1"] ** 2
        assert beta == pytest.approx(J * p["Jm1"] / k, rel=1e-9)  # J_m D / psi'(phi)
        det = np.linalg.det(model.ad(x, p))
        assert det == pytest.approx(k ** 2 / (J ** 2 * p["Jm1"] ** 4), rel=1e-6)  # rank 4 while psi' > 0


def test_energy_balance(model):
    """dE/dt = -(B_m dq_m + F(dq_m)) dq_m + u dq_m (the spring potential is the curve's integral)."""
    rng = np.random.default_rng(4)
    p = _params(rng, model)
    for x in _states(rng, 8):
        E = lambda xx: model.energy(xx, p)  # noqa: E731
        LfE = (E(x + H * model.f(x, p)) - E(x - H * model.f(x, p))) / (2 * H)
        LgE = (E(x + H * model.g(x, p).ravel()) - E(x - H * model.g(x, p).ravel())) / (2 * H)
        scale = 1.0 + abs(E(x))
        assert abs(LfE + (p["Bm1"] * x[3] + _friction(x[3], p)) * x[3]) < 1e-5 * scale
        assert abs(LgE - x[3]) < 1e-5 * scale


def test_torque_law_equals_state_law_at_the_implied_measurement(model):
    rng = np.random.default_rng(5)
    p = _params(rng, model)
    pv = model.params_array(p)
    gains = np.array([4e3, 6e2, 40.0, 10.0, 50.0, 0.0, 0.0, 0.02])
    for x in _states(rng, 8):
        psi, k = datasheet(x[2] - x[0], *_curve(p))
        m = np.array([x[0], x[1], psi, k * (x[3] - x[1]), x[3]])
        for name in ("T", "alpha", "beta"):
            ours, theirs = model.torque_functions[f"{name}_tau"](m, pv).full(), model.functions[name](x, pv).full()
            assert np.allclose(ours, theirs, rtol=1e-8, atol=1e-8 * (1 + np.max(np.abs(theirs)))), name
        r = rng.uniform(-1, 1, 5)
        u_x = float(model.controls["control_fl"](x, np.zeros(0), r, pv, gains)[0])
        u_m = float(model.controls["control_fl_tau"](m, np.zeros(0), r, pv, gains)[0])
        assert abs(u_x - u_m) <= 1e-8 * max(1.0, abs(u_x))


@pytest.mark.parametrize("bad, expected", [({"K_2": 1.0e4}, "K_1 <= K_2 <= K_3"), ({"T_2": 10.0}, "T_1 < T_2"),
                                           ({"w_blend": 5e-3}, "w_blend"), ({"K_1": -1.0}, "> 0"),
                                           ({"F_c": -0.1}, ">= 0")])
def test_non_physical_drive_parameters_are_one_line_errors(model, bad, expected):
    with pytest.raises(fjm_runtime.FjmValueError) as info:
        model.f(np.zeros(4), bad)
    msg = str(info.value)
    assert "\n" not in msg and expected in msg, msg


def test_feedback_linearization_is_exact_in_the_continuous_limit(model):
    """fl (lam = 20) holding the arm about horizontal (gravity 14.7 N m, swing 0.5 rad at 5 rad/s): the
    deflection crosses phi_1 = T_1 / K_1 into the second segment. Sampled with a held torque the law
    misses by O(T) (the stiff drive moves within a period); the error halves with the period, so the
    law is exact in the limit. The same law told the linear spring K_1 misses by 0.5 rad at any rate."""
    p = model.default_params
    ref = make_reference("sine", 1, amplitude=0.5, omega=5.0, offset=np.pi / 2)
    x0 = np.array([np.pi / 2, 2.5, np.pi / 2, 2.5])

    def worst(nominal, dt):
        res = simulate(model, make_controller("fl", model, nominal, lam=20.0), ref, duration=1.5, dt=dt, x0=x0,
                       true_params=p, backend="casadi", interface="ideal")   # the held torque of the claim
        t = res.t.ravel()
        return np.abs(res.e1.ravel()[t > 1.0]).max(), np.abs(res.x[:, 2] - res.x[:, 0]).max()

    errors = [worst(p, dt) for dt in (2e-4, 1e-4, 5e-5)]
    linear = worst(dict(p, K_2=p["K_1"], K_3=p["K_1"]), 1e-4)[0]
    print(f"arm1_hd fl: |e1| after 1 s at T = 0.2, 0.1, 0.05 ms: {', '.join(f'{e:.2e}' for e, _ in errors)} rad; "
          f"|phi| up to {errors[0][1] * 1e3:.2f} mrad (phi_1 = {p['T_1'] / p['K_1'] * 1e3:.2f}); law told K_1 only: "
          f"{linear:.2f} rad")
    assert all(phi > p["T_1"] / p["K_1"] + p["w_blend"] / 2 for _, phi in errors)   # into the second segment
    assert all(phi < 0.01 for _, phi in errors)                                     # inside the declared range
    for (coarse, _), (fine, _) in zip(errors, errors[1:]):
        assert 1.9 < coarse / fine < 2.1, (coarse, fine)                            # first order in T -> 0
    assert errors[-1][0] < 1e-3 and linear > 100 * errors[1][0]


def test_rest_state_carries_gravity_through_the_curve(model):
    """rest_state: q_m = q + psi^-1(G(q)); the link is at rest (no acceleration) with the drive past T_1."""
    from fjm_runtime.sim.rest import rest_state
    p = model.default_params
    for q in (0.3, np.pi / 2, -1.2):
        x = rest_state(model, [q], p)
        assert model.f(x, p)[1] == pytest.approx(0.0, abs=1e-9)
        psi, _ = datasheet(x[2] - x[0], *_curve(p))
        assert psi == pytest.approx(p["m1"] * p["g0"] * p["r1"] * np.sin(q), rel=1e-12)
