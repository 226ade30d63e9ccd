"""fjm design's policy: the draws, the cost with its penalties, determinism, and the gains file
that fjm simulate --gains reads."""
import json
from types import SimpleNamespace

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.analysis.search.settings import SearchSettings
from fjm_runtime.analysis.search.search import design
from fjm_runtime.analysis.search.thresholds import DIVERGED_COST, PENALTY, run_cost
from fjm_runtime.analysis.search.draws import draw_params
from fjm_runtime.sim.step_layout import stiffness_indices


def _search(m, progress=None, **settings):
    """``design`` with the settings as keywords (the progress callback apart)."""
    return design(m, SearchSettings(**settings), progress=progress)


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
    a, b = _search(m, **kw), _search(m, **kw)
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


def test_cost_sums_the_excess_over_joints():
    """Two joints over the jitter limit cost twice one: a better gain on either joint counts."""
    n = 7
    jm = {"rms_second_half": np.full((3, n), 1e-3), "time_at_limit": np.zeros((3, n)),
          "torque_jitter": np.ones((3, n))}
    jm["torque_jitter"][1, 0] = 6.0
    jm["torque_jitter"][2, [0, 1]] = 6.0
    c = run_cost(SimpleNamespace(joint_metrics=jm, diverged=np.zeros(3, bool)))
    assert c[2] - c[0] == pytest.approx(2 * (c[1] - c[0])) and c[1] - c[0] == pytest.approx(PENALTY)


def test_moves_are_per_joint_and_keep_the_k_lin_floor():
    from fjm_runtime.analysis.search.search import LIN_FLOOR, combine_moves, move_gain
    g = {"lam": 80.0, "k_lin": [400.0, 200.0], "k_s": [1e3, 2e3], "delta": [5.0, 10.0]}
    h = move_gain(g, ("k_s", 1), 2.0)
    assert h["k_s"] == [1e3, 4e3] and g["k_s"] == [1e3, 2e3]          # the input is not changed
    low = move_gain(g, ("k_lin", 1), 1 / 16)
    assert low["k_lin"] == [400.0, LIN_FLOOR * 80.0]                    # 12.5 raised to the floor
    up = move_gain(g, "lam", 4.0)
    assert up["lam"] == 320.0 and up["k_lin"] == [LIN_FLOOR * 320.0] * 2
    both = combine_moves(g, [(("delta", 0), 2.0), (("k_lin", 0), 0.5)])
    assert both["delta"] == [10.0, 10.0] and both["k_lin"] == [200.0, 200.0]
