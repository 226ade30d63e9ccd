"""The fjm command (fjm_runtime.cli.main) in a new user's first hour: --version, `fjm models`, one-line errors
before long work, readable --help texts, one command table for the parser, the help and the dispatch."""
import json
import time

import pytest

import fjm_runtime
from fjm_runtime.cli.main import build_parser, main


def one_line_error(capsys, argv, must=()):
    t0 = time.perf_counter()
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("fjm: error:"), err
    assert "Traceback" not in err
    for word in must:
        assert word in err, (word, err)
    return err, time.perf_counter() - t0


def test_version(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"fjm {fjm_runtime.__version__}"


def test_models_lists_every_model(capsys):
    assert main(["models", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in rows] == fjm_runtime.available_models()
    by = {r["name"]: r for r in rows}
    assert by["link1"] == {"name": "link1", "n": 1, "parameters": 7, "source": "built-in"}
    assert by["planar3"]["n"] == 3 and by["planar3"]["parameters"] == len(fjm_runtime.load("planar3").param_names)
    assert by["panda"]["n"] == 7 and by["panda"]["source"].startswith("URDF ") and "panda.urdf" in by["panda"]["source"]
    assert main(["models"]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split() == ["model", "n", "params", "source"] and len(table) == len(rows) + 1


def test_sweep_unwritable_out_fails_before_the_sweep(capsys):
    _, seconds = one_line_error(capsys, ["sweep", "link1", "--out", "/proc/x.csv"], ["--out", "/proc/x.csv"])
    assert seconds < 5.0  # refused at once, not after 1000 runs


def test_outputs_that_are_files_or_have_no_parent(capsys, tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    one_line_error(capsys, ["figures", "--out", str(a_file)], ["is a file", "directory"])
    one_line_error(capsys, ["figures", "--out", str(tmp_path / "no" / "such")], ["does not exist"])
    one_line_error(capsys, ["derive", "--out", str(a_file)], ["is a file", "directory"])
    one_line_error(capsys, ["simulate", "link1", "--plot", "/nonexistent/dir/x.png"], ["--plot", "does not exist"])
    assert not (tmp_path / "no").exists()


def test_bad_values_are_one_line(capsys):
    one_line_error(capsys, ["simulate", "link1", "--param", "K"], ["--param", "NAME=VALUE"])
    one_line_error(capsys, ["simulate", "nosuchmodel", "--quiet"], ["nosuchmodel"])
    one_line_error(capsys, ["figures", "--samples", "0"], ["--samples"])


def _subparser(name):
    parser = build_parser()
    action = next(a for a in parser._actions if getattr(a, "choices", None) and name in a.choices)
    return action.choices[name]


def test_help_texts_are_plain():
    sweep_help = _subparser("sweep").format_help()
    assert "+-20 %" in sweep_help and "%%" not in sweep_help
    assert _subparser("figures").description
    assert "Figs 1-4" in _subparser("figures").format_help()


#: The fewest arguments each command parses (derive's are passed on as they are).
ARGS = {"simulate": ["link1"], "design": ["link1"], "analyze": ["link1", "--gains", "g.json"], "derive": ["--x", "1"],
        "sweep": ["link1"], "export": ["mjcf", "link1", "--out", "m.xml"], "tune": ["link1"],
        "excite": ["link1", "--duration", "1", "--out", "e"], "identify": ["link1", "log.csv", "--out", "p.toml"]}


def test_one_command_table_builds_the_parser_the_help_and_the_dispatch(capsys, monkeypatch):
    """cli.main.COMMANDS is the one list: the sub-parsers in its order with its help lines, each
    parsed command runs its module's ``run``, and a command without ``add_arguments`` (derive) gets
    its arguments as they are."""
    import importlib

    from fjm_runtime.cli.main import COMMANDS
    parser = build_parser()
    action = next(a for a in parser._actions if getattr(a, "choices", None) and "simulate" in a.choices)
    assert list(action.choices) == [name for name, _, _ in COMMANDS]
    assert [c.help for c in action._choices_actions] == [h for _, _, h in COMMANDS]
    assert main([]) == 2
    listing = capsys.readouterr().out
    positions = [listing.index(f"    {name} ") for name, _, _ in COMMANDS]
    assert positions == sorted(positions)
    for name, module, _ in COMMANDS:
        mod = importlib.import_module(f"fjm_runtime.cli.{module}")
        seen = []
        monkeypatch.setattr(mod, "run", lambda args, seen=seen: seen.append(args) or 7)
        argv = [name] + ARGS.get(name, [])
        assert main(argv) == 7, name
        assert seen and (seen[0] == ["--x", "1"] if name == "derive" else seen[0].command == name), name


def test_cli_help(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    assert "simulate" in capsys.readouterr().out
