"""fjm design (fjm_runtime.cli.design): its exit status and verdict on the terminal, the parameter file reaching
the controller and the record, its flags' one-line errors."""
import json

import pytest

from fjm_runtime.cli.main import main

QUICK = ["--draws", "3", "--duration", "0.3", "--screen-draws", "3", "--screen-duration", "0.2", "--rounds", "1",
         "--seed", "5", "--task", "sine"]


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_design_that_misses_exits_1_names_the_miss_and_records_it(tmp_path, capsys):
    out = tmp_path / "g.json"
    rc = main(["design", "link1", "--law", "ismc", "--noise", "panda_white", "--recheck-draws", "2", "--out", str(out), *QUICK])
    err = capsys.readouterr().err
    assert rc == 1
    rec = json.loads(out.read_text())
    assert rec["meets"] is False and rec["misses"] and rec["recheck"]["draws"] == 0
    jit = [m for m in rec["misses"] if m["threshold"] == "jitter"][0]
    assert jit["joint"] == 1 and jit["limit"] == 3.0 and jit["value"] > 3.0
    assert f"jitter {jit['value']:.3g} N m on joint 1 > 3 N m by {jit['excess']:.3g} N m (draw {jit['draw']}" in err
    assert '"meets": false' in err and rec["noise"] == "panda_white" and rec["sensor"]["name"] == "panda_white"


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_design_that_meets_exits_0_after_the_recheck(tmp_path, capsys):
    out = tmp_path / "g.json"
    rc = main(["design", "link1", "--law", "ismc", "--noise", "ideal", "--max-rms", "0.5", "--max-jitter", "1e4", "--max-at-limit",
               "100", "--recheck-draws", "2", "--out", str(out), *QUICK])
    err = capsys.readouterr().err
    rec = json.loads(out.read_text())
    assert rc == 0 and rec["meets"] is True and rec["misses"] == []
    assert rec["recheck"]["draws"] == 2 and rec["recheck"]["meets"] is True and "re-checked on 2 fresh draws" in err
    assert rec["thresholds"] == {"max_rms": 0.5, "max_jitter": 1e4, "max_at_limit": 1.0, "jitter_joints": [1]}


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_design_params_file_reaches_the_controller_and_the_record(tmp_path, capsys):
    params = tmp_path / "p.toml"
    params.write_text("[parameters]\nK = 180.0\n\n[spread]\nstiffness = 0.1\nJ_m = 0.0\n")
    out = tmp_path / "g.json"
    main(["design", "link1", "--law", "ismc", "--noise", "ideal", "--params", str(params), "--recheck-draws", "0", "--out", str(out),
          *QUICK])
    rec = json.loads(out.read_text())
    assert rec["params"] == {"source": str(params), "nominal": {"K": 180.0}, "relative": {"K": 0.1, "J_m": 0.0},
                             "absolute": {}}
    assert rec["recheck"]["draws"] == 0


@pytest.mark.parametrize("argv, must", [
    (["--jitter-joints", "2-5"], ["--jitter-joints", "joint"]),
    (["--jitter-joints", "a"], ["--jitter-joints", "'a'"]),
    (["--max-jitter", "-1"], ["--max-jitter", "> 0"]),
    (["--max-at-limit", "150"], ["--max-at-limit", "percentage"]),
    (["--noise", "franka"], ["--noise", "franka_like"]),
    (["--params", "/nonexistent/p.toml"], ["--params", "not found"]),
    (["--duration", "1e9"], ["--duration/--rate", "GB"]),
    (["--recheck-draws", "-1"], ["--recheck-draws"]),
    (["--scheduler", "tcp://127.0.0.1:1"], ["--scheduler", "cannot connect"]),
])
def test_design_bad_flags_are_one_line_errors(capsys, argv, must):
    assert main(["design", "planar2", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("fjm: error:") and "Traceback" not in err, err
    for word in must:
        assert word in err, (word, err)
