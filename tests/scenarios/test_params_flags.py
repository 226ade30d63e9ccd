"""The parameter file of fjm identify sets the controller's nominal values in simulate and export."""
import json

from fjm_runtime.cli.main import main as fjm_main
from support.controller_runs import LINK1_TORQUE_DESIGN


def test_simulate_params_sets_the_nominal_values_and_nominal_overrides_it(tmp_path, capsys):
    p = tmp_path / "params.toml"
    p.write_text("[parameters]\nK = 171.5\nJ_m = 1.85\n")
    assert fjm_main(["simulate", "link1", "--params", str(p), "--duration", "0.3", "--json", "--quiet"]) == 0
    nominal = json.loads(capsys.readouterr().out)["settings"]["nominal_params"]
    assert nominal["K"] == 171.5 and nominal["J_m"] == 1.85
    assert fjm_main(["simulate", "link1", "--params", str(p), "--nominal", "K=160", "--duration", "0.3", "--json",
                     "--quiet"]) == 0
    assert json.loads(capsys.readouterr().out)["settings"]["nominal_params"]["K"] == 160.0


def test_bad_params_file_is_one_line(tmp_path, capsys):
    p = tmp_path / "params.toml"
    p.write_text("[parameters]\nK_wrong = 1.0\n")
    assert fjm_main(["simulate", "link1", "--params", str(p), "--duration", "0.3", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "K_wrong" in err and "\n" not in err


def test_export_controller_params_are_the_embedded_nominal_values(tmp_path, capsys):
    p = tmp_path / "params.toml"
    p.write_text("[parameters]\nK = 171.25\n")
    gains = tmp_path / "gains.json"
    gains.write_text(json.dumps(dict(LINK1_TORQUE_DESIGN, noise="panda_white",
                                     gains=dict(LINK1_TORQUE_DESIGN["gains"], u_max=50.0))))
    out = tmp_path / "lib"
    assert fjm_main(["export", "controller", "link1", "--gains", str(gains), "--params", str(p), "--out",
                     str(out)]) == 0
    assert "171.25" in (out / "link1_ismc_tau_controller.c").read_text()
