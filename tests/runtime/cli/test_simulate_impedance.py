"""The impedance laws on `fjm simulate`: the CLI's run is the API's (default gains, or a design file's), the
full measurement is set for them, and a bad gain, a conflicting --sensing or a law on the interface it is not
made for is a one-line error."""
import json

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.cli.main import main
from fjm_runtime.control.factory import make_controller
from fjm_runtime.sim.metrics import rms_second_half
from fjm_runtime.sim.sensor import SensorModel


def _run(capsys, argv):
    status = main(argv)
    out = capsys.readouterr()
    return status, out.out, out.err


def _api_rms(kind, interface, gains=None):
    m = fjm_runtime.load("panda")
    ctrl = make_controller(kind, m, {}, u_max=list(m.limits.effort), **(gains or {}))
    res = fjm_runtime.simulate(m, ctrl, fjm_runtime.make_reference("sine", m.n, amplitude=0.5, omega=1.0),
                               duration=0.2, sensor=SensorModel.franka_like(seed=0), interface=interface)
    return rms_second_half(res)


@pytest.mark.parametrize("kind, interface", [("impedance", "motor"), ("joint_impedance", "franka")])
def test_default_gains_run_is_the_apis(capsys, kind, interface):
    argv = ["simulate", "panda", "--controller", kind, "--noise", "franka_like", "--duration", "0.2", "--json"]
    status, out, _ = _run(capsys, argv + (["--interface", interface] if interface != "motor" else []))
    assert status == 0
    rep = json.loads(out)
    assert rep["settings"]["sensing"] == "full" and rep["settings"]["controller"] == kind
    assert not rep["diverged"]
    np.testing.assert_allclose(rep["rms_second_half"], _api_rms(kind, interface), rtol=1e-9, atol=0)


def test_a_design_files_gains_are_the_laws(capsys, tmp_path):
    gains = {"K_p": 800.0, "K_T": [-0.7] * 4 + [-0.5] * 3, "K_i": 0.0}
    path = tmp_path / "imp.json"
    path.write_text(json.dumps({"kind": "impedance", "gains": gains}))
    status, out, _ = _run(capsys, ["simulate", "panda", "--gains", str(path), "--noise", "franka_like",
                                   "--duration", "0.2", "--json"])
    assert status == 0
    rep = json.loads(out)
    np.testing.assert_allclose(rep["rms_second_half"], _api_rms("impedance", "motor", gains), rtol=1e-9, atol=0)
    assert not np.allclose(rep["rms_second_half"], _api_rms("impedance", "motor"), rtol=1e-3)  # the gains acted


@pytest.mark.parametrize("gains, needle", [
    ({"K_T": -1.2}, "gains.K_T = -1.2"), ({"K_p": [1.0, 2.0]}, "gains.K_p has 2 entries"),
    ({"K_d": -3.0}, "gains.K_d = -3.0"), ({"K_i": "slow"}, "gains.K_i = 'slow'"), ({"lam": 30}, "gains.lam"),
    ({"K_q": float("nan")}, "gains.K_q")])
def test_bad_impedance_gains_are_one_line_errors(capsys, tmp_path, gains, needle):
    kind = "joint_impedance" if "K_q" in gains else "impedance"
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"kind": kind, "gains": gains}))
    status, _, err = _run(capsys, ["simulate", "panda", "--gains", str(path), "--duration", "0.1"]
                          + (["--interface", "franka"] if kind == "joint_impedance" else []))
    assert status == 2 and err.count("\n") == 1 and needle in err and "bad.json" in err


@pytest.mark.parametrize("argv, needles", [
    (["--controller", "joint_impedance"], ("the default interface motor", "joint_impedance on joint_torque")),
    (["--controller", "joint_impedance", "--interface", "motor"], ("--interface motor", "joint_torque interface")),
    (["--controller", "impedance", "--interface", "franka"], ("--interface franka", "impedance on motor")),
    (["--controller", "impedance", "--interface", "joint_torque"], ("--interface joint_torque", "motor interface")),
    (["--controller", "impedance", "--sensing", "torque"], ("--sensing torque", "expected --sensing full")),
    (["--controller", "ismc", "--sensing", "full"], ("--sensing full", "impedance, joint_impedance only")),
    (["--controller", "impedance", "--k-s", "100"], ("--k-s", "sliding-mode"))])
def test_wrong_pairings_are_one_line_errors(capsys, argv, needles):
    status, _, err = _run(capsys, ["simulate", "panda", "--duration", "0.1"] + argv)
    assert status == 2 and err.count("\n") == 1 and all(n in err for n in needles), err
