"""fjm design's thresholds, parameter file, verdict and re-check: the draws from the file, the misses
named by threshold, joint, excess and draw, and fresh draws that no stage of the search used."""
import json

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.analysis.search.settings import SearchSettings
from fjm_runtime.analysis.search.search import RECHECK_SEED_OFFSET, design
from fjm_runtime.analysis.search.draws import default_spread, draw_params, load_params_file
from fjm_runtime.analysis.search.thresholds import (PENALTY, Thresholds, describe_miss, find_misses, parse_joints,
                                                    run_cost)
from fjm_runtime.sim.step_layout import stiffness_indices
from fjm_runtime.sim.sensor import SensorModel
from fjm_runtime.validation import FjmValueError
from types import SimpleNamespace


def _search(m, progress=None, **settings):
    """``design`` with the settings as keywords (the progress callback apart)."""
    return design(m, SearchSettings(**settings), progress=progress)


def _former_draws(model, count, seed):
    """The hard-coded box of the former design.py, verbatim: the reference the default spread must equal."""
    n = int(model.n)
    iK, iJ = stiffness_indices(model)
    p0 = np.asarray(model.params_array({}), dtype=float)
    iL = list(model.param_names).index("m_load") if "m_load" in model.param_names else None
    alt = np.where(np.arange(n) % 2 == 0, 0.7, 1.3)
    corners = [(np.full(n, 0.7), 1.0, 0.0), (np.full(n, 1.3), 1.0, 0.0), (alt, 1.0, 0.0)]
    corners += [(k, jm, 1.0) for jm in (0.8, 1.2) for k in (np.full(n, 0.7), np.full(n, 1.3), alt)]
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(count):
        if i < len(corners):
            ks, js, load = corners[i][0], np.full(n, corners[i][1]), corners[i][2]
        else:
            ks, js, load = rng.uniform(0.7, 1.3, n), rng.uniform(0.8, 1.2, n), rng.uniform(0.0, 1.0)
        p = p0.copy()
        p[iK] *= ks
        p[iJ] *= js
        if iL is not None:
            p[iL] = load
        rows.append(p)
    return np.vstack(rows)


@pytest.mark.parametrize("name", ["panda", "link1", "planar2"])
def test_default_spread_draws_the_former_box_bit_for_bit(name):
    m = fjm_runtime.load(name)
    assert np.array_equal(draw_params(m, 30, seed=3), _former_draws(m, 30, 3))


def _write(tmp_path, text, name="p.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_params_file_sets_the_nominal_and_the_spread(tmp_path):
    m = fjm_runtime.load("planar2")
    path = _write(tmp_path, """
[parameters]
K1 = { default = 300.0, unit = "N m/rad" }
Jm2 = 1.5

[spread]
stiffness = 0.1
K2 = 0.25
Jm1 = [1.0, 3.0]
m1 = 0.05
""")
    s = load_params_file(path, m)
    assert s.nominal["K1"] == 300.0 and s.nominal["Jm2"] == 1.5 and s.nominal["K2"] == 150.0
    assert s.overrides == {"K1": 300.0, "Jm2": 1.5} and s.source == str(path)
    P = draw_params(m, 400, seed=1, spread=s)
    col = {k: P[:, m.param_names.index(k)] for k in ("K1", "K2", "Jm1", "Jm2", "m1", "m2")}
    # corners: stiffness low, high, alternating (K1 by its group's 0.1, K2 by its own 0.25)
    assert col["K1"][:3] == pytest.approx([270.0, 330.0, 270.0])
    assert col["K2"][:3] == pytest.approx([112.5, 187.5, 187.5])
    assert col["Jm1"][:3] == pytest.approx([1.0] * 3) and col["Jm1"][3:9] == pytest.approx([3.0] * 6)  # absolute
    assert col["Jm2"][3:6] == pytest.approx([1.2] * 3) and col["Jm2"][6:9] == pytest.approx([1.8] * 3)
    assert col["m1"][:3] == pytest.approx([1.0] * 3) and col["m1"][3:6] == pytest.approx([0.95] * 3)
    r = slice(9, None)
    assert 270 <= col["K1"][r].min() and col["K1"][r].max() <= 330 and np.ptp(col["K1"][r]) > 50
    assert 112.5 <= col["K2"][r].min() and col["K2"][r].max() <= 187.5 and np.ptp(col["K2"][r]) > 60
    assert 1.0 <= col["Jm1"][r].min() and col["Jm1"][r].max() <= 3.0 and np.ptp(col["Jm1"][r]) > 1.8
    assert 0.95 <= col["m1"][r].min() and col["m1"][r].max() <= 1.05 and np.ptp(col["m1"][r]) > 0.09
    assert np.all(col["m2"] == 1.0)                                    # not in [spread]: the nominal
    fresh = draw_params(m, 40, seed=1, spread=s, fresh=True)
    assert not np.any(np.all(np.isclose(fresh[:, None, :], P[None, :40, :]), axis=2))   # no row shared
    assert 270 <= fresh[:, m.param_names.index("K1")].min()


@pytest.mark.parametrize("text, must", [
    ("[parameters]\nK9 = 1.0\n", ["p.toml:2: parameters.K9", "not a parameter of planar2"]),
    ("[parameters]\nK1 = \"stiff\"\n", ["p.toml:2: parameters.K1", "expected a finite number"]),
    ("[parameters]\nK1 = { default = 200.0, unit = \"Nm/deg\" }\n", ["p.toml:2: parameters.K1", "'N m/rad'"]),
    ("[parameters]\nK1 = -5.0\n", ["p.toml:2: parameters.K1", "> 0"]),
    ("\n[spread]\nstiffness = 1.5\n", ["p.toml:3: spread.stiffness", "0 <= s < 1"]),
    ("[spread]\nstiffness = [0.5, 1.5]\n", ["p.toml:2: spread.stiffness", "relative half-width"]),
    ("[spread]\nJm1 = [3.0, 1.0]\n", ["p.toml:2: spread.Jm1", "lo <= hi"]),
    ("[spread]\nbogus = 0.1\n", ["p.toml:2: spread.bogus", "not a group"]),
    ("[nominal]\nK1 = 1.0\n", ["p.toml:1: [nominal]", "[parameters] and/or [spread]"]),
    ("[parameters\nK1 = 1.0\n", ["p.toml", "not valid TOML"]),
])
def test_params_file_errors_are_one_line_naming_file_line_key(tmp_path, text, must):
    m = fjm_runtime.load("planar2")
    path = _write(tmp_path, text)
    with pytest.raises(FjmValueError) as info:
        load_params_file(path, m)
    msg = str(info.value)
    assert "\n" not in msg, msg
    for word in must:
        assert word.replace("p.toml", str(path)) in msg or word in msg, (word, msg)
    assert str(path) in msg


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


TINY = dict(draws=3, duration=0.3, screen_draws=3, screen_duration=0.2, rounds=1, max_extra_delay=1, seed=5,
            progress=lambda msg: None)


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_passing_gains_are_rechecked_on_fresh_plants_and_seeds():
    m = fjm_runtime.load("link1")
    lax = Thresholds(max_rms=1.0, max_jitter=1e4, max_at_limit=1.0)
    a = _search(m, sensor=SensorModel.panda_white(seed=5), thresholds=lax, recheck_draws=16, **TINY)
    assert a["meets"] is True and a["misses"] == []
    rc = a["recheck"]
    assert rc["draws"] == 16 and rc["meets"] is True
    assert rc["noise_seeds"] == [5 + RECHECK_SEED_OFFSET, 5 + RECHECK_SEED_OFFSET + 15]   # none of seed + draw
    final_rms, fresh_rms = a["worst_case"]["rms_second_half"][0], rc["worst_case"]["rms_second_half"][0]
    assert fresh_rms > final_rms          # measured: one fresh plant tracks worse than every searched one
    # a limit between the two: the final check passes, the re-check on fresh plants fails the design
    b = _search(m, sensor=SensorModel.panda_white(seed=5), recheck_draws=16,
                                 thresholds=Thresholds(max_rms=0.5 * (final_rms + fresh_rms), max_jitter=1e4,
                                                       max_at_limit=1.0), **TINY)
    assert b["gains"] == a["gains"] and b["meets"] is False and b["recheck"]["meets"] is False
    assert [(x["threshold"], x["joint"], x["stage"]) for x in b["misses"]] == [("rms", 1, "recheck")]
    assert b["misses"][0]["value"] == fresh_rms and b["misses"][0]["seed"] >= RECHECK_SEED_OFFSET
    assert b["misses"][0]["message"].startswith("RMS error ") and "recheck)" in b["misses"][0]["message"]


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_a_failed_design_says_which_threshold_joint_and_draw():
    m = fjm_runtime.load("link1")
    a = _search(m, sensor=SensorModel.panda_white(seed=5), **TINY)
    assert a["meets"] is False and a["recheck"]["draws"] == 0
    jit = [x for x in a["misses"] if x["threshold"] == "jitter"][0]
    assert jit["joint"] == 1 and jit["value"] == pytest.approx(max(a["worst_case"]["torque_jitter"]))
    assert jit["message"].startswith(f"jitter {jit['value']:.3g} N m on joint 1 > 3 N m by ")
    assert a["thresholds"] == {"max_rms": 2e-3, "max_jitter": 3.0, "max_at_limit": 0.02, "jitter_joints": [1]}
    json.dumps(a, allow_nan=False)


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_design_on_a_two_worker_cluster_is_bit_identical():
    """The Monte Carlo stages on a dask LocalCluster (2 workers, threads) give the same record bit for bit."""
    from dask.distributed import Client, LocalCluster
    m = fjm_runtime.load("planar2")
    kw = dict(TINY, draws=4, recheck_draws=3, sensor=SensorModel.panda_white(seed=5),
              thresholds=Thresholds(max_rms=1.0, max_jitter=1e4, max_at_limit=1.0))
    local = _search(m, **kw)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        remote = _search(m, scheduler=client, **kw)
    assert remote["scheduler"] != "local" and local["scheduler"] == "local"
    for key in ("gains", "worst_case", "margins", "misses", "recheck", "meets"):
        assert remote[key] == local[key], key
    assert local["recheck"]["draws"] == 3 and local["evaluations"]["runs"] == remote["evaluations"]["runs"]
    assert local["meets"] is True and local["worst_case"]["diverged"] == 0        # numbers, not NaN, compared


class _LamScreen:
    """A stand-in screen: rejects every candidate with lam < 30 and says why."""

    name = "lam >= 30"

    def __init__(self):
        self.seen = []

    def check(self, cands):
        from fjm_runtime.analysis.search.screen import Verdict
        self.seen += [c["lam"] for c in cands]
        return [Verdict(ok=c["lam"] >= 30.0, reason="lam < 30", predicted={"lam": c["lam"]}) for c in cands]

    def explain(self, gains):
        return f"limited by the stand-in screen at lam = {gains['lam']:g}"


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_a_screen_keeps_rejected_candidates_out_of_the_monte_carlo(monkeypatch):
    from fjm_runtime.analysis.search.runs import DesignLoops
    m = fjm_runtime.load("link1")
    free = _search(m, sensor=SensorModel.panda_white(seed=5), screen=None, **TINY)
    simulated = []
    run = DesignLoops.run
    monkeypatch.setattr(DesignLoops, "run", lambda self, cands, *a, **k: (simulated.extend(c["lam"] for c in cands),
                                                                         run(self, cands, *a, **k))[1])
    scr = _LamScreen()
    a = _search(m, sensor=SensorModel.panda_white(seed=5), screen=scr, **TINY)
    rejected = sum(lam < 30.0 for lam in scr.seen)
    assert rejected > 0 and a["screen"] == {"name": "lam >= 30", "rejected": rejected,
                                            "simulated": len(scr.seen) - rejected}
    assert simulated and min(simulated) >= 30.0                      # no rejected candidate reached a batch
    assert free["gains"]["lam"] < 30.0 <= a["gains"]["lam"]         # the screen changed the outcome
    assert a["meets"] is False and a["limited_by"] == f"limited by the stand-in screen at lam = {a['gains']['lam']:g}"
    assert free["screen"]["rejected"] == 0 and "stand-in" not in free["limited_by"]   # Monte Carlo attribution


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_a_cluster_batch_uses_the_substeps_of_the_whole_batch():
    """Rows sorted soft to stiff: the first chunk alone would need fewer substeps; the cluster's runs must
    still equal the local batch bit for bit (substeps decided once, on the client, for every row)."""
    from dataclasses import replace
    from dask.distributed import Client, LocalCluster
    from fjm_runtime.analysis.search.runs import DesignLoops
    m = fjm_runtime.load("planar2")
    wide = default_spread(m, {"K1": 1500.0, "K2": 1500.0})
    wide = replace(wide, relative={**wide.relative, "K1": 0.6, "K2": 0.6})
    P = draw_params(m, 20, 5, wide)
    P = P[np.argsort(P[:, m.param_names.index("K1")] + P[:, m.param_names.index("K2")])]
    g = {"lam": 20.0, "k_lin": [100.0, 100.0], "k_s": [4e4, 2e4], "delta": [200.0, 100.0]}
    args = ("ismc", "torque", 500.0, 1, SensorModel.panda_white(seed=5), None, None, True, False)
    local = DesignLoops(m, *args, nominal=wide.nominal)
    assert local.substeps(P[:8]) < local.substeps(P)                   # the first chunk alone would differ
    a = local.run([g], P, 0.3, 5)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        b = DesignLoops(m, *args, nominal=wide.nominal, client=client).run([g], P, 0.3, 5)
    assert b.info["chunks"] >= 2 and not a.diverged.any()
    for k, v in a.joint_metrics.items():
        np.testing.assert_array_equal(b.joint_metrics[k], v, err_msg=k)


def test_the_params_file_nominal_reaches_the_law_and_the_draws_centre(tmp_path):
    """The controller runs on the file's nominal values (not the model's defaults); the draws centre on them."""
    from fjm_runtime.analysis.search.runs import DesignLoops
    m = fjm_runtime.load("planar2")
    spread = load_params_file(_write(tmp_path, "[parameters]\nK1 = 1500.0\nJm2 = 0.5\n"), m)
    loops = DesignLoops(m, "ismc", "torque", 1000.0, 1, SensorModel.ideal(), None, None, True, nominal=spread.nominal)
    ctrl = loops.controller({"lam": 20.0})
    assert ctrl.p_nom[m.param_names.index("K1")] == 1500.0 and ctrl.p_nom[m.param_names.index("Jm2")] == 0.5
    assert ctrl.p_nom[m.param_names.index("K2")] == 150.0
    P = draw_params(m, 200, 0, spread)
    k1 = P[9:, m.param_names.index("K1")]
    assert 1050.0 <= k1.min() and k1.max() <= 1950.0 and abs(np.mean(k1) / 1500.0 - 1) < 0.05


@pytest.mark.exhaustive
def test_design_on_process_workers_is_bit_identical():
    """As the threaded-cluster test, on 2 worker PROCESSES (pickled specs, a library loaded per process)."""
    from dask.distributed import Client, LocalCluster
    m = fjm_runtime.load("planar2")
    kw = dict(TINY, draws=6, recheck_draws=4, sensor=SensorModel.panda_white(seed=5),
              thresholds=Thresholds(max_rms=1.0, max_jitter=1e4, max_at_limit=1.0))
    local = _search(m, **kw)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        remote = _search(m, scheduler=client, **kw)
    for key in ("gains", "worst_case", "margins", "misses", "recheck", "meets"):
        assert remote[key] == local[key], key


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_attribution_reruns_the_binding_draw_without_each_noise_source():
    """'as designed' reproduces the miss (same plant row, gains, noise seed); with every level at zero the
    figure no longer depends on the noise seed; the design's sensor is restored afterwards."""
    from dataclasses import replace
    from fjm_runtime.analysis.search.attribution import attribute, variants
    from fjm_runtime.analysis.search.runs import DesignLoops
    m = fjm_runtime.load("link1")
    a = _search(m, sensor=SensorModel.panda_white(seed=5), **TINY)
    miss = a["binding"]
    assert miss["threshold"] == "jitter" and a["limited_by"] and a["attribution"]["as designed"] == miss["value"]
    loops = DesignLoops(m, "ismc", "torque", 1000.0, 1, SensorModel.panda_white(seed=5), None, None, True)
    row = draw_params(m, 3, 5)[miss["draw"]]
    sentence, figs = attribute(loops, a["gains"], row, miss["seed"], 0.3, miss)
    assert figs == a["attribution"] and sentence == a["limited_by"]
    assert loops.sensor == SensorModel.panda_white(seed=5)          # the design's sensor is restored
    other = attribute(loops, a["gains"], row, miss["seed"] + 99, 0.3, miss)[1]
    assert other["as designed"] != figs["as designed"]
    assert other["every noise level at zero"] == figs["every noise level at zero"]
    ratelimited = replace(SensorModel.panda_white(seed=5), torque_rate_limit=2000.0)
    assert "no torque-rate limit" in variants(ratelimited) and "no torque-rate limit" not in variants(loops.sensor)
    # the torque sensor carries this jitter (panda_white: tau_J 0.05 N m, differentiated for dtau_J)
    assert figs["torque-sensor noise (tau_J, dtau_J)"] < 0.5 * figs["as designed"]
    assert figs["encoder noise (q, q_m)"] == pytest.approx(figs["as designed"], rel=0.01)
    assert "torque-sensor noise (tau_J, dtau_J)" in sentence and set(figs) == {
        "as designed", "encoder noise (q, q_m)", "velocity noise (dq, dq_m)", "torque-sensor noise (tau_J, dtau_J)",
        "every noise level at zero"}                                # panda_white: no rate limit to remove


@pytest.mark.slow  # the linear analysis builds CasADi jacobians
def test_linear_screen_verdicts_follow_the_analysis():
    """The screen passes a candidate only when every corner is stable with the decay margin and the predicted
    jitter is within 1.25 x the limit; its reasons and explanation quote the analysis."""
    from fjm_runtime.analysis.search.runs import DesignLoops
    from fjm_runtime.analysis.search.screen_linear import JITTER_SLACK, LinearScreen
    m = fjm_runtime.load("planar2")
    unstable = {"lam": 20.0, "k_lin": [100.0] * 2, "k_s": [200.0] * 2, "delta": [1.0] * 2}
    stable = {"lam": 10.0, "k_lin": [100.0] * 2, "k_s": [50.0] * 2, "delta": [1.0, 0.5]}
    noisy = LinearScreen(DesignLoops(m, "ismc", "torque", 1000.0, 1, SensorModel.panda_white(seed=5), None, None,
                                     True), default_spread(m))
    a, b = noisy.check([unstable, stable])
    assert not a.ok and a.reason.startswith("spectral radius") and a.predicted["rho"] > 1.0
    jit = b.predicted["torque_jitter"]
    assert not b.ok and b.predicted["rho"] <= noisy.rho_max and max(jit) > JITTER_SLACK * 3.0
    assert b.reason == f"predicted jitter {max(jit):.3g} N m on joint {int(np.argmax(jit)) + 1} > 1.25 x 3 N m"
    assert noisy.explain(stable).startswith(f"linear analysis: predicted jitter {max(jit):.3g} N m on joint")
    quiet = LinearScreen(DesignLoops(m, "ismc", "torque", 1000.0, 1, SensorModel.ideal(), None, None, True),
                         default_spread(m))
    assert quiet.check([stable])[0].ok and not quiet.check([unstable])[0].ok     # no noise: stability decides
