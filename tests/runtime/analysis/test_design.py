"""fjm design's policy: the draws, the cost with its penalties, determinism, and the gains file
that fjm simulate --gains reads."""
import json
from types import SimpleNamespace

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.analysis.design import DIVERGED_COST, PENALTY, design, draw_params, run_cost
from fjm_runtime.sim.sample_step import stiffness_indices


def test_draws_corners_then_box():
    m = fjm_runtime.load("panda")
    P = draw_params(m, 40, seed=3)
    p0 = np.asarray(m.params_array({}))
    iK, iJ = stiffness_indices(m)
    kr, jr = P[:, iK] / p0[iK], P[:, iJ] / p0[iJ]
    assert np.allclose(kr[0], 0.7) and np.allclose(kr[1], 1.3)
    assert np.allclose(kr[2], [0.7, 1.3] * 3 + [0.7])
    assert np.allclose(jr[3:6], 0.8) and np.allclose(jr[6:9], 1.2)
    iL = m.param_names.index("m_load")
    assert np.all(P[:3, iL] == 0) and np.all(P[3:9, iL] == 1.0)
    assert np.all((kr[9:] >= 0.7) & (kr[9:] <= 1.3)) and np.all((jr[9:] >= 0.8) & (jr[9:] <= 1.2))
    assert np.all((P[9:, iL] >= 0) & (P[9:, iL] <= 1)) and np.ptp(kr[9:]) > 0.3
    assert np.array_equal(P, draw_params(m, 40, seed=3)) and not np.array_equal(P, draw_params(m, 40, seed=4))


def test_cost_penalises_limit_time_jitter_and_divergence():
    n = 7
    base = {"rms_second_half": np.full((4, n), 1e-3), "time_at_limit": np.zeros((4, n)),
            "torque_jitter": np.ones((4, n))}
    base["time_at_limit"][1, 6] = 0.04             # twice the 2 % allowed
    base["torque_jitter"][2, 4] = 100.0            # joint 5: not constrained
    base["torque_jitter"][3, 0] = 6.0              # joint 1: twice the 3 N m
    b = SimpleNamespace(joint_metrics=base, diverged=np.array([False, False, False, False]))
    c = run_cost(b)
    assert c[0] == pytest.approx(1e-3) and c[2] == pytest.approx(1e-3)
    assert c[1] == pytest.approx(1e-3 + PENALTY) and c[3] == pytest.approx(1e-3 + PENALTY)
    b.diverged = np.array([True, False, False, False])
    assert run_cost(b)[0] == DIVERGED_COST


@pytest.mark.slow
def test_tiny_design_is_deterministic_and_simulate_reads_it(tmp_path):
    from fjm_runtime.cli.main import main
    m = fjm_runtime.load("link1")
    kw = dict(draws=3, duration=0.3, screen_draws=3, screen_duration=0.2, rounds=1, max_extra_delay=1, seed=5,
              progress=lambda msg: None)
    a, b = design(m, **kw), design(m, **kw)
    assert a["gains"] == b["gains"] and a["worst_case"] == b["worst_case"]
    assert a["kind"] == "ismc" and a["sensing"] == "torque" and a["draws"] == 3
    path = tmp_path / "g.json"
    path.write_text(json.dumps(a))
    import contextlib
    import io
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["simulate", "link1", "--controller", "ismc", "--sensing", "torque", "--gains", str(path),
                     "--duration", "0.3", "--noise", "panda", "--seed", "5", "--delay-samples", "1", "--json"]) == 0
    rep = json.loads(buf.getvalue())
    from fjm_runtime.control.factory import make_controller
    from fjm_runtime.control.references import make_reference
    from fjm_runtime.sim.metrics import rms_second_half
    from fjm_runtime.sim.sensor import SensorModel
    from fjm_runtime.sim.simulate import simulate
    ctrl = make_controller("ismc", m, {}, sensing="torque", **a["gains"])
    r = simulate(m, ctrl, make_reference("sine", 1, amplitude=0.5, omega=1.0), duration=0.3,
                 sensor=SensorModel.panda(seed=5), delay_samples=1)
    assert rep["diverged"] is False
    assert np.allclose(rep["rms_second_half"], rms_second_half(r), rtol=1e-9, atol=0)
