"""`--interface` on the command line: the run's numbers are the API's with that interface, `--json` records it,
bad names and files are one-line errors, and an old sensor file's rate limit names where it went."""
import json

import pytest

import fjm_runtime
from fjm_runtime.cli.main import main
from fjm_runtime.sim.interface import CommandInterface
from fjm_runtime.sim.metrics import rms_second_half


def _run(capsys, argv):
    status = main(argv)
    out = capsys.readouterr()
    return status, out.out, out.err


@pytest.mark.parametrize("name", ["ideal", "motor", "joint_torque"])
def test_simulate_json_runs_and_records_the_interface(capsys, name):
    status, out, _ = _run(capsys, ["simulate", "link1", "--controller", "ismc", "--lam", "8", "--k-s", "100",
                                   "--delta", "2", "--beta-hat", "model", "--duration", "0.2", "--json", "--interface", name])
    assert status == 0
    rep = json.loads(out)
    assert rep["settings"]["interface"] == getattr(CommandInterface, name)().as_dict()
    m = fjm_runtime.load("link1")
    ctrl = fjm_runtime.make_controller("ismc", m, {}, lam=8.0, k_s=100.0, delta=2.0)
    res = fjm_runtime.simulate(m, ctrl, fjm_runtime.make_reference("sine", 1, amplitude=0.5, omega=1.0),
                               duration=0.2, interface=name)
    assert rep["rms_second_half"][0] == pytest.approx(float(rms_second_half(res)[0]), rel=1e-9)


def test_an_interface_file_sets_the_run(capsys, tmp_path):
    path = tmp_path / "arm.toml"
    path.write_text('preset = "joint_torque"\ntorque_rate_limit = 200.0\nK_T = -0.3\nD_T = 2e-3\n')
    status, out, _ = _run(capsys, ["simulate", "link1", "--controller", "ismc", "--lam", "8", "--k-s", "100",
                                   "--delta", "2", "--duration", "0.2", "--json", "--interface", str(path)])
    assert status == 0
    s = json.loads(out)["settings"]["interface"]
    assert (s["kind"], s["torque_rate_limit"], s["K_T"], s["D_T"], s["lowpass_cutoff_hz"], s["name"]) == \
        ("joint_torque", 200.0, -0.3, 2e-3, 100.0, "arm")


@pytest.mark.parametrize("text, needle", [
    ('kind = "motr"', "kind"), ("K_T = -1.5", "K_T"), ('current_bandwidth_hz = "fast"', "current_bandwidth_hz"),
    ("lowpass_cutoff_hz = 100.0", "joint_torque"), ("volume = 3", "volume"), ("K_T = [", "TOML"),
    ('preset = "robot"', "preset")])
def test_bad_interface_files_are_one_line_errors(capsys, tmp_path, text, needle):
    path = tmp_path / "bad.toml"
    path.write_text(text + "\n")
    status, _, err = _run(capsys, ["simulate", "link1", "--duration", "0.1", "--interface", str(path)])
    assert status == 2 and err.count("\n") == 1 and needle in err and "bad.toml" in err


def test_a_preset_for_another_arm_and_an_unknown_name_are_one_line_errors(capsys):
    status, _, err = _run(capsys, ["simulate", "link1", "--duration", "0.1", "--interface", "franka"])
    assert status == 2 and err.count("\n") == 1 and "K_T has 7 values" in err
    status, _, err = _run(capsys, ["simulate", "link1", "--duration", "0.1", "--interface", "fast"])
    assert status == 2 and err.count("\n") == 1 and "--interface 'fast'" in err


def test_an_old_sensor_file_with_a_rate_limit_names_the_interface_file(capsys, tmp_path):
    path = tmp_path / "old.toml"
    path.write_text('preset = "franka_like"\ntorque_rate_limit = 1000.0\n')
    status, _, err = _run(capsys, ["simulate", "link1", "--duration", "0.1", "--noise", str(path)])
    assert status == 2 and err.count("\n") == 1 and "torque_rate_limit" in err and "interface file" in err
