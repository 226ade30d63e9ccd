"""Thresholds and cost of the gain search (fjm_runtime.analysis.search.thresholds): penalties, misses named by
threshold, joint, excess and draw, and the jitter joints."""
from types import SimpleNamespace

import numpy as np
import pytest

from fjm_runtime.analysis.search.thresholds import (DIVERGED_COST, PENALTY, Thresholds, describe_miss, find_misses,
                                                    parse_joints, run_cost)
from fjm_runtime.validation import FjmValueError


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


def test_cost_sums_the_excess_over_joints():
    """Two joints over the jitter limit cost twice one: a better gain on either joint counts."""
    n = 7
    jm = {"rms_second_half": np.full((3, n), 1e-3), "time_at_limit": np.zeros((3, n)),
          "torque_jitter": np.ones((3, n))}
    jm["torque_jitter"][1, 0] = 6.0
    jm["torque_jitter"][2, [0, 1]] = 6.0
    c = run_cost(SimpleNamespace(joint_metrics=jm, diverged=np.zeros(3, bool)))
    assert c[2] - c[0] == pytest.approx(2 * (c[1] - c[0])) and c[1] - c[0] == pytest.approx(PENALTY)


def test_jitter_joints_parse():
    assert parse_joints("1-4") == (0, 1, 2, 3) and parse_joints("1,2,3") == (0, 1, 2)
    assert parse_joints("1-3,6", n=7) == (0, 1, 2, 5) and parse_joints("all", n=3) == (0, 1, 2)
    for bad in ("0", "4-2", "x", "1,,2"):
        with pytest.raises(FjmValueError, match="--jitter-joints"):
            parse_joints(bad, n=7)
    with pytest.raises(FjmValueError, match="joint 8"):
        parse_joints("8", n=7)
    assert Thresholds().joints(2) == [0, 1] and Thresholds().joints(7) == [0, 1, 2, 3]


def _batch(rms, tal, jit, diverged=None, time=None):
    B = rms.shape[0]
    return SimpleNamespace(joint_metrics={"rms_second_half": rms, "time_at_limit": tal, "torque_jitter": jit},
                           diverged=np.zeros(B, bool) if diverged is None else diverged,
                           seeds=100 + np.arange(B), divergence_time=np.full(B, np.nan) if time is None else time)


def test_misses_name_threshold_joint_excess_and_draw():
    thr = Thresholds(max_rms=1e-3, max_jitter=3.0, max_at_limit=0.02, jitter_joints=(0, 1))
    rms, tal, jit = np.full((4, 3), 5e-4), np.zeros((4, 3)), np.ones((4, 3))
    jit[2, 1] = 4.1                 # joint 2 over by 1.1 N m on draw 2
    jit[3, 2] = 50.0                # joint 3 is not a jitter joint
    tal[1, 2] = 0.05                # joint 3 at a limit 5 %
    rms[0, 0] = 1.5e-3              # joint 1 RMS
    misses = find_misses(_batch(rms, tal, jit), thr, draws=[10, 11, 12, 13], stage="final")
    got = {(m["threshold"], m["joint"]): m for m in misses}
    assert set(got) == {("jitter", 2), ("at_limit", 3), ("rms", 1)}
    j = got[("jitter", 2)]
    assert j["value"] == 4.1 and j["excess"] == pytest.approx(1.1) and j["draw"] == 12 and j["seed"] == 102
    assert describe_miss(j) == "jitter 4.1 N m on joint 2 > 3 N m by 1.1 N m (draw 12, seed 102; final)"
    assert describe_miss(got[("at_limit", 3)]).startswith("time at a torque limit 5 % on joint 3 > 2 % by 3 %")
    assert find_misses(_batch(np.full((2, 3), 5e-4), np.zeros((2, 3)), np.ones((2, 3))), thr, [0, 1], "final") == []
    div = find_misses(_batch(rms, tal, jit, diverged=np.array([False, True, True, False]),
                             time=np.array([np.nan, 2.5, 1.0, np.nan])), thr, [0, 1, 2, 3], "recheck")
    assert div[0]["threshold"] == "diverged" and div[0]["count"] == 2 and div[0]["draw"] == 1
    assert "diverged: 2 of 4 runs (first: draw 1, seed 101, at 2.5 s; recheck)" == describe_miss(div[0])
    assert ("jitter", 2) not in {(m["threshold"], m["joint"]) for m in div}   # a diverged run's numbers are not misses


def test_cost_penalises_the_rms_threshold_and_the_chosen_jitter_joints():
    rms, tal, jit = np.full((3, 2), 1e-3), np.zeros((3, 2)), np.ones((3, 2))
    rms[1, 0] = 4e-3                 # twice over a 2e-3 limit
    jit[2, 1] = 6.0                  # joint 2: twice the 3 N m
    c = run_cost(_batch(rms, tal, jit), Thresholds(max_rms=2e-3))
    assert c[0] == pytest.approx(1e-3) and c[1] == pytest.approx(4e-3 + PENALTY)
    assert c[2] == pytest.approx(1e-3 + PENALTY)
    only1 = run_cost(_batch(rms, tal, jit), Thresholds(max_rms=2e-3, jitter_joints=(0,)))
    assert only1[2] == pytest.approx(1e-3)
