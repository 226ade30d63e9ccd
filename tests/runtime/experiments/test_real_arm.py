"""The real-arm section (fjm_runtime.experiments.real_arm): draws, controllers, failures visible, figure.

Short runs only (0.1 s, casadi backend); the documented numbers come from ``make demo``.
"""
import numpy as np
import pytest

from fjm_runtime.experiments import real_arm as ra
from fjm_runtime.experiments.panda import mismatch_ratio
from fjm_runtime.sim.rest import rest_state
from fjm_runtime.sim.step import SimulationDivergedError


def test_draws_cover_the_box_and_the_corners(panda):
    cases = ra.draws(panda, 20)
    assert len(cases) == 23 and len({d["seed"] for d in cases}) == 23
    p0 = panda.default_params
    for d in cases:
        p = d["params"]
        kr = np.array([p[f"K{i + 1}"] / p0[f"K{i + 1}"] for i in range(7)])
        jr = np.array([p[f"Jm{i + 1}"] / p0[f"Jm{i + 1}"] for i in range(7)])
        assert np.all((kr >= 0.7 - 1e-12) & (kr <= 1.3 + 1e-12)) and np.all((jr >= 0.8 - 1e-12) & (jr <= 1.2 + 1e-12))
        assert 0.0 <= p["m_load"] <= 1.0
        np.testing.assert_allclose(kr, d["K_ratio"], rtol=1e-12)
    corners = [np.array([d["params"][f"K{i + 1}"] / p0[f"K{i + 1}"] for i in range(7)]) for d in cases[-3:]]
    np.testing.assert_allclose(corners[0], 0.7)
    np.testing.assert_allclose(corners[1], 1.3)
    np.testing.assert_allclose(corners[2], [0.7, 1.3, 0.7, 1.3, 0.7, 1.3, 0.7])
    assert all(d["params"]["m_load"] == 1.0 for d in cases[-3:])
    # random draws really vary per joint (not one factor for the whole arm)
    assert np.ptp(cases[0]["K_ratio"]) > 0.05


def test_controllers_know_only_the_nominal_parameters(panda):
    gains, source = ra.ismc_gains()
    assert "hand-found" in source or "designed" in source
    for label, (kind, sensing, predict) in ra.CONTROLLERS.items():
        ctrl, pr = ra.controller(label, panda, gains)
        np.testing.assert_array_equal(ctrl.p_nom, panda.params_array())
        assert ctrl.sensing == sensing and pr == predict
        np.testing.assert_array_equal(ctrl.u_max, ra.PANDA_EFFORT)


@pytest.mark.slow
def test_failures_are_counted_and_metrics_are_worst_over_draws(panda, tmp_path):
    cases = ra.draws(panda, 1)[:1] + ra.draws(panda, 1)[-3:-2]
    gains, _ = ra.ismc_gains()
    res = ra.run_all(panda, cases, 0.1, gains, backend="casadi")
    assert set(res) == set(ra.CONTROLLERS) and all(len(v) == 2 for v in res.values())
    label = "torque-sensed ismc + prediction"
    res[label].append(SimulationDivergedError(0.05, "injected"))
    rows = ra.summary_rows(res)
    assert rows[label]["diverged"] == 1 and rows[label]["runs"] == 3
    done = [r for r in res[label] if not isinstance(r, SimulationDivergedError)]
    by_hand = []
    for r in done:
        half = r.t >= 0.5 * r.t[-1]
        by_hand.append(np.max(np.sqrt(np.mean(r.e1[half] ** 2, axis=0))))
    np.testing.assert_allclose(rows[label]["rms"], max(by_hand), rtol=1e-12)
    at = max(np.max(np.mean(np.abs(r.u[:-1]) >= np.asarray(ra.PANDA_EFFORT) * (1 - 1e-9), axis=0)) for r in done)
    np.testing.assert_allclose(rows[label]["at_limit"], at)
    lines = ra.table(rows)
    assert any(line.startswith(f"| {label} | 1 / 3 |") for line in lines)
    png = ra.plot(res, tmp_path / "real_arm.png")
    assert png.stat().st_size > 10_000
    # the runs start at rest holding gravity on the TRUE plant: the first error is the reference's offset only
    r0 = res["motor PD + gravity"][0]
    np.testing.assert_allclose(r0.x[0], rest_state(panda, r0.ref[0, 0], cases[0]["params"]), atol=1e-12)


def test_mismatch_ratio_is_the_coefficient_on_the_acceleration(panda):
    """The y'' coefficient scales linearly with the stiffness error and is a I, not a (30 % = 10 x 3 %)."""
    r3, r30 = mismatch_ratio(panda, 0.97), mismatch_ratio(panda, 0.7)
    np.testing.assert_allclose(r30, 10.0 * r3, rtol=1e-12)
    x = rest_state(panda, (0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785), None)
    I7 = np.asarray(panda.inertia(x)).reshape(7, 7)[6, 6]
    p = panda.default_params
    # joint 7 by hand: 3 % of K7 times (1/J_m7 + 1/I_77), over c2 = 6 lambda^2
    np.testing.assert_allclose(r3[6], 0.03 * p["K7"] * (1 / p["Jm7"] + 1 / I7) / (6 * 10.0 ** 2), rtol=1e-12)
