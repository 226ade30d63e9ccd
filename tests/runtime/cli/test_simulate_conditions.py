"""``fjm simulate`` on an arm's own limits and a design's own conditions; ``fjm analyze`` on the default gains.

The arm is planar2 copied into a temporary folder with limits written into its manifest (as derive writes a
model file's ``[limits]``): effort 15 and 40 N m (joint 1 holds about 19.6 N m of gravity, so its limit
binds), and joint 2 within +-0.2 rad (the default 0.5 rad sine leaves it).
"""
from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime import make_reference, simulate
from fjm_runtime.cli.main import main as fjm_main
from fjm_runtime.cli.simulate_conditions import default_design, default_gains
from fjm_runtime.sim.step import SimulationDivergedError

from support.paths import GENERATED

EFFORT = [15.0, 40.0]


@pytest.fixture()
def arm(tmp_path):
    d = tmp_path / "myarm"
    shutil.copytree(GENERATED / "planar2", d)
    man = json.loads((d / "manifest.json").read_text())
    man["limits"] = {"effort": {"unit": "N m", "values": EFFORT, "from": ["model file"] * 2},
                     "position": {"unit": "rad", "lower": [None, -0.2], "upper": [None, 0.2],
                                  "from": [None, "model file"]}}
    (d / "manifest.json").write_text(json.dumps(man))
    return d


def _run(capsys, argv):
    status = fjm_main(argv)
    out, err = capsys.readouterr()
    return status, out, err


def test_the_models_effort_limits_apply_by_default(arm, capsys):
    argv = ["simulate", str(arm), "--duration", "0.5", "--json", "--quiet"]
    status, out, err = _run(capsys, argv)
    rep = json.loads(out)
    assert rep["settings"]["effort_limits"] == EFFORT
    assert rep["settings"]["effort_limits_from"] == "the model's effort limits"
    assert "fjm: effort limits applied: 15, 40 N m" in err
    peak = rep.get("peak_torque") or rep["peak_torque_until_divergence"]
    assert peak[0] == pytest.approx(15.0, rel=1e-12)            # held at the limit, never beyond
    assert peak[1] <= 40.0 * (1 + 1e-12)
    status, out, err = _run(capsys, argv + ["--no-effort-limits"])
    rep = json.loads(out)
    assert rep["settings"]["effort_limits"] is None and rep["settings"]["effort_limits_from"] == "--no-effort-limits"
    assert rep["peak_torque"][0] > 19.0                          # gravity alone asks 19.6 N m of joint 1
    assert "effort limits applied" not in err


def test_a_reference_beyond_the_position_limits_is_one_warning_naming_the_joint(arm, capsys):
    status, out, err = _run(capsys, ["simulate", str(arm), "--duration", "0.5", "--json", "--quiet",
                                     "--no-effort-limits"])
    lines = [ln for ln in err.splitlines() if "position limits" in ln]
    assert len(lines) == 1 and "joint 2" in lines[0] and "joint 1" not in lines[0]
    assert f"[0, {0.5 * math.sin(0.5):.3g}] rad" in lines[0] and "limits [-0.2, 0.2] rad" in lines[0]
    status, out, err = _run(capsys, ["simulate", str(arm), "--duration", "0.5", "--json", "--quiet",
                                     "--amplitude", "0.19"])
    assert "position limits" not in err


def test_default_gains_are_named_as_defaults_and_analyze_takes_the_same(capsys):
    m = fjm_runtime.load("link1")
    status, out, err = _run(capsys, ["simulate", "link1", "--duration", "0.05", "--quiet"])
    rep = json.loads(out)
    d = default_design(m)
    assert rep["gains_source"] == "defaults" and "(command line)" not in err
    assert (rep["lam"], rep["k_s"], rep["delta"]) == (d.gains["lam"], d.gains["k_s"], d.gains["delta"])
    lam, k_s, delta, gain = default_gains(m, {}, make_reference("sine", 1, amplitude=0.5, omega=1.0))
    assert gain is not None and k_s == gain.k_s and delta == k_s / 200.0   # Lemma 1's bound, the layer rule
    # analyze without --gains == analyze with those gains and conditions written in a file
    status, out, err = _run(capsys, ["analyze", "link1", "--json", "--no-margins", "--task-times", "0.5"])
    assert "no --gains: the default gains of fjm simulate" in err
    implicit = json.loads(out)
    assert implicit["gains_source"] == "defaults" and implicit["settings"]["sensing"] == "state"


def test_analyze_defaults_equal_the_same_design_written_out(tmp_path, capsys):
    m = fjm_runtime.load("planar2")
    f = tmp_path / "defaults.json"
    default_design(m).save(f)
    runs = []
    for extra in ([], ["--gains", str(f)]):
        status, out, err = _run(capsys, ["analyze", "planar2", "--json", "--no-margins", "--task-times", "0.5",
                                         "--plants", "nominal"] + extra)
        runs.append(json.loads(out))
    a, b = (r["plants"][0]["points"] for r in runs)
    for point in a:
        assert a[point]["rho"] == b[point]["rho"]
    assert runs[0]["settings"] == runs[1]["settings"] and runs[0]["settings"]["delay"] == 0
    assert json.loads(f.read_text())["gains"]["lam"] == 8.0


def _design_file(tmp_path, **conditions):
    f = tmp_path / "d.json"
    f.write_text(json.dumps({"model": "planar2", "kind": "ismc", **conditions,
                             "gains": {"lam": 20.0, "k_lin": 30.0, "k_s": 100.0, "delta": 5.0}}))
    return f


def test_gains_bring_the_designs_conditions_unless_a_flag_overrides(tmp_path, capsys):
    f = _design_file(tmp_path, sensing="torque", rate=500.0, delay=1, predict=True, noise="panda_white")
    base = ["simulate", "planar2", "--gains", str(f), "--duration", "0.2", "--json", "--quiet"]
    status, out, err = _run(capsys, base)
    taken = json.loads(out)
    s = taken["settings"]
    assert (s["rate"], s["sensing"], s["delay_samples"], s["predict"], s["noise"]) == \
        (500.0, "torque", 1, True, "panda_white")
    assert taken["designed_for_these_conditions"] is True
    assert "the design's conditions" in err and "overridden" not in err
    # the same run with every condition given as a flag: the same numbers
    status, out, err = _run(capsys, base + ["--rate", "500", "--sensing", "torque", "--delay-samples", "1",
                                            "--predict", "--noise", "panda_white"])
    explicit = json.loads(out)
    assert explicit["rms_second_half"] == taken["rms_second_half"]
    assert explicit["torque_jitter"] == taken["torque_jitter"]
    # an explicit flag wins and is said
    status, out, err = _run(capsys, base + ["--sensing", "state", "--no-predict"])
    rep = json.loads(out)
    assert rep["settings"]["sensing"] == "state" and rep["settings"]["predict"] is False
    assert rep["settings"]["rate"] == 500.0 and rep["settings"]["noise"] == "panda_white"
    line = next(ln for ln in err.splitlines() if "the design's conditions" in ln)
    assert "--sensing state (the design's: torque sensing)" in line and "--predict (off" in line
    assert rep["designed_for_these_conditions"] is False


def test_a_hand_written_gains_file_keeps_the_old_defaults(tmp_path, capsys):
    status, out, err = _run(capsys, ["simulate", "planar2", "--gains", str(_design_file(tmp_path)),
                                     "--duration", "0.05", "--json", "--quiet"])
    s = json.loads(out)["settings"]
    assert (s["rate"], s["sensing"], s["delay_samples"], s["predict"], s["noise"]) == \
        (1000.0, "state", 0, False, "ideal")
    assert "the design's conditions" not in err


def test_a_diverged_run_reports_the_peak_torques_up_to_the_divergence(capsys):
    m = fjm_runtime.load("planar2")
    # the ideal actuator: the current loop's lag of the default motor interface makes this loop blow up within
    # its first sample, where "up to the divergence" is a single torque
    status, out, err = _run(capsys, ["simulate", "planar2", "--lam", "900", "--duration", "0.5", "--json",
                                     "--quiet", "--interface", "ideal"])
    assert status == 3
    rep = json.loads(out)
    t_div, peak = rep["divergence_time"], rep["peak_torque_until_divergence"]
    assert "peak |u| per joint up to then" in err and f"{peak[0]:.4g}" in err
    # the same loop stopped one sample before: its torques are the ones applied up to the divergence
    from fjm_runtime.control.factory import make_controller
    from fjm_runtime.cli.simulate_conditions import default_gains as dg
    ref = make_reference("sine", 2, amplitude=0.5, omega=1.0)
    _, k_s, delta, _ = dg(m, {}, ref, lam=900.0)
    ctrl = make_controller("smc", m, {}, lam=900.0, k_s=k_s, delta=delta)
    assert t_div > 2e-3
    before = simulate(m, ctrl, ref, duration=t_div - 1e-3, dt=1e-3, interface="ideal")
    expected = np.max(np.abs(before.u), axis=0)
    assert np.allclose(peak, expected, rtol=1e-9)
    with pytest.raises(SimulationDivergedError) as e:
        simulate(m, ctrl, ref, duration=0.5, dt=1e-3, interface="ideal")
    assert np.allclose(e.value.peak_torque, expected, rtol=1e-9)


def test_design_warns_when_its_task_leaves_the_position_limits(arm, tmp_path, capsys):
    status, out, err = _run(capsys, ["design", str(arm), "--law", "ismc", "--draws", "1", "--recheck-draws", "0", "--duration", "0.5",
                                     "--screen-draws", "1", "--screen-duration", "0.3", "--rounds", "0",
                                     "--threads", "1", "--out", str(tmp_path / "d.json")])
    assert status in (0, 1)
    lines = [ln for ln in err.splitlines() if "position limits" in ln]
    assert len(lines) == 1 and lines[0].startswith("fjm design: warning:") and "joint 2" in lines[0]
    assert f"[0, {0.5 * math.sin(0.5):.3g}] rad" in lines[0]


@pytest.mark.parametrize("name", ["panda_impedance_1000hz_d1.json", "panda_joint_impedance_1000hz_d1.json"])
def test_analyze_reads_a_shipped_design_of_a_law_without_a_boundary_layer(capsys, name):
    """fjm analyze of the impedance designs (a law with no k_s / delta): a verdict, no traceback; the design's
    interface and franka_like sensor in the settings."""
    from importlib import resources
    path = resources.files("fjm_runtime.control").joinpath("designed", name)
    status, out, err = _run(capsys, ["analyze", "panda", "--gains", str(path), "--json", "--no-margins",
                                     "--task-times", "none", "--plants", "nominal"])
    rep = json.loads(out)
    assert status == 0 and "Traceback" not in err
    rest = rep["plants"][0]["points"]["rest"]
    assert rest["stable"] is True and rest["rho"] < 1.0 and "s_over_delta" not in rest
    assert rep["settings"]["sensor"] == "franka_like" and rep["settings"]["sensing"] == "full"
    assert rep["settings"]["interface"] == json.loads(path.read_text())["interface"]["name"]
