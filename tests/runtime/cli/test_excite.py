"""fjm excite (fjm_runtime.cli.excite) writes the trajectory a robot plays: from rest to rest, the CSV read back
equals the excitation, its metadata."""
import json

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.cli.main import main as fjm_main
from fjm_runtime.ident.excite_loop import load_excitation, read_excitation


def test_cli_writes_the_trajectory_a_robot_plays(tmp_path, capsys):
    out = tmp_path / "traj.csv"
    assert fjm_main(["excite", "link1", "--duration", "4", "--out", str(out), "--posture", "0.3",
                     "--candidates", "3", "--iterations", "2"]) == 0
    text = capsys.readouterr().out
    assert "condition number" in text and "closed-loop check" in text and "from rest to rest" in text
    m = fjm_runtime.load("link1")
    d = read_excitation(out, m)
    assert d["t"][0] == 0.0 and d["t"][-1] == pytest.approx(4.0) and d["t"].size == 4001
    np.testing.assert_allclose(d["q_d"][:, 0], load_excitation(out).sample(d["t"])[:, 0, 0], atol=1e-12)
    p = m.default_params
    hold = p["M"] * p["g0"] * p["L"] * np.sin(0.3)                      # at rest at both ends: gravity only
    for row in (0, -1):
        assert d["q_d"][row, 0] == pytest.approx(0.3, abs=1e-12)
        assert abs(d["dq_d"][row, 0]) < 1e-10 and abs(d["dq_m_d"][row, 0]) < 1e-8
        assert d["u_ff"][row, 0] == pytest.approx(hold, rel=1e-9)
        assert d["tau_J_d"][row, 0] == pytest.approx(hold, rel=1e-9)
        assert d["q_m_d"][row, 0] == pytest.approx(0.3 + hold / p["K"], rel=1e-9)
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["condition"] >= 1.0 and meta["check"]["max_error"] < 5e-3
