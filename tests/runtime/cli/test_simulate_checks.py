"""`fjm simulate`: bad input refused in one line before any work, where the gains
came from and whether they were designed for the run, and runs that leave the workspace.

Each expected number is computed here from its definition (the layout's columns, the Nyquist
frequency, the time a sine crosses 4 pi), not copied from the output.
"""
import json
import math

import numpy as np
import pytest

from fjm_runtime.cli.main import main
from fjm_runtime.cli.simulate_checks import ERROR_BOUND, WORKSPACE_BOUND, workspace_exit

PANDA_DESIGN = "fjm_runtime/control/designed/panda_ismc_tau_1000hz_d1.json"


def _run(capsys, argv):
    status = main(argv)
    out = capsys.readouterr()
    return status, out.out, out.err


def _one_line_error(capsys, argv, must):
    status, out, err = _run(capsys, argv)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert status == 2 and out == "", (status, err)
    assert len(lines) == 1 and lines[0].startswith("fjm: error: "), err
    for word in must:
        assert word in lines[0], (word, lines[0])
    return lines[0]


def test_a_design_for_another_model_names_the_mismatch(capsys):
    msg = _one_line_error(capsys, ["simulate", "link1", "--gains", PANDA_DESIGN, "--json"],
                          ["--gains", PANDA_DESIGN, "'panda'", "7 joints", "link1 has 1 joint"])
    assert "amplitude" not in msg and "shape" not in msg


def _gains(tmp_path, gains, kind="ismc"):
    path = tmp_path / "g.json"
    path.write_text(json.dumps({"kind": kind, "gains": gains}))
    return str(path)


GOOD = {"lam": 8.0, "k_s": [100.0, 100.0], "delta": [2.0, 2.0]}


@pytest.mark.parametrize("change, must", [
    ({"lam": "fast"}, ["gains.lam = 'fast'", "finite number > 0"]),
    ({"lam": [8, "x"]}, ["gains.lam = [8, 'x']", "finite number > 0"]),
    ({"k_s": [100.0, "x"]}, ["gains.k_s", "'x'", "list of 2", ">= 0"]),
    ({"k_s": [100.0, 100.0, 100.0]}, ["gains.k_s has 3 entries", "list of 2", "planar2"]),
    ({"delta": [2.0, -1.0]}, ["gains.delta", "-1.0", "> 0"]),
    ({"u_max": 0.0}, ["gains.u_max = 0.0", "> 0"]),
    ({"k_s": float("inf")}, ["gains.k_s = inf", "finite"]),
    ({"k_s": None}, ["gains.k_s is missing", "lam, k_s, delta"]),
    ({"lam": 1e300}, ["gains.lam", "1e+300", "pi x rate", "3142"]),
], ids=["lam-text", "lam-list", "k_s-text", "k_s-length", "delta-negative", "u_max-zero", "k_s-inf",
        "k_s-missing", "lam-beyond-nyquist"])
def test_bad_gains_file_names_file_key_and_expectation(capsys, tmp_path, change, must):
    gains = {**GOOD, **change}
    gains = {k: v for k, v in gains.items() if v is not None}
    path = _gains(tmp_path, gains)
    _one_line_error(capsys, ["simulate", "planar2", "--gains", path, "--duration", "0.01", "--json"],
                    [f"--gains {path}", *must])


def _columns(nw, n, nm):
    # stored per sample: step state, torque + s + estimate (6n), reference (5n), noise, true outputs (4n), error
    return nw + 6 * n + 5 * n + nm + 4 * n + n


@pytest.mark.parametrize("argv, samples", [(["--duration", "1e9"], 1e12 + 1), (["--rate", "1e12"], 1e13 + 1)])
def test_a_run_too_large_to_hold_is_refused_with_its_estimate(capsys, argv, samples):
    # the Panda, state sensing, smc, no delay: the step state is x (4n = 28) and the default motor interface's
    # current-loop torque (n), measurement 4n
    n = 7
    stored_gb = samples * _columns(5 * n, n, 4 * n) * 8 / 1e9
    _one_line_error(capsys, ["simulate", "panda", "--json", *argv],
                    [argv[0], f"{_columns(35, 7, 28)} stored columns", f"{stored_gb:.3g} GB", "--max-memory 4 GB"])


def test_the_delay_buffer_counts_in_the_estimate(capsys):
    # link1, d = 10^8: the step state holds d measurements (4) and d torques (1) besides x (4) and the
    # current-loop torque (1)
    d = 10 ** 8
    _one_line_error(capsys, ["simulate", "link1", "--delay-samples", str(d), "--duration", "0.05", "--json"],
                    [f"{_columns(4 + d * 5 + 1, 1, 4)} stored columns", "--delay-samples"])


def test_max_memory_is_the_limit(capsys):
    # 1 s at 1 kHz on link1: 1001 x 25 x 8 bytes = 200 kB stored (the step state x and the default motor
    # interface's current-loop torque), about 12x at peak: over 0.001 GB? no; 1e-4 yes
    _one_line_error(capsys, ["simulate", "link1", "--duration", "1", "--max-memory", "1e-4", "--json"],
                    ["1001 samples x 25 stored columns", "--max-memory 0.0001 GB"])


@pytest.mark.parametrize("argv, must", [
    (["--lam", "1e300"], ["--lam", "1e+300", f"{math.pi * 1000:.4g}", "Nyquist"]),
    (["--lam", "0"], ["--lam", "0 < lam"]),
    (["--rate", "500", "--lam", "1600"], ["--lam", f"{math.pi * 500:.4g}", "500 Hz"]),
    (["--dt", "0"], ["--dt", "0 < dt"]),
    (["--dt", "nan"], ["--dt nan"]),
    (["--duration", "nan"], ["--duration nan"]),
    (["--rate", "0"], ["--rate"]),
    (["--omega", "1e300"], ["--omega", "Nyquist"]),
    (["--amplitude", "inf"], ["--amplitude inf", "finite"]),
    (["--substeps", "20000"], ["--substeps 20000", "at most 10000"]),
    (["--substeps", "-3"], ["--substeps -3", ">= 1"]),
    (["--delay-samples", "-1"], ["delay_samples", ">= 0"]),
    (["--nominal", "K=1e300"], ["--nominal K = 1e+300", "1e-12 <= |value| <= 1e+12"]),  # refused before Lemma 1
    (["--max-memory", "0"], ["--max-memory", "> 0 GB"]),
    (["--seed", "-1"], ["seed", "-1"]),
])
def test_absurd_flags_are_one_line_errors(capsys, argv, must):
    _one_line_error(capsys, ["simulate", "link1", "--duration", "0.05", "--json", *argv], must)


def test_an_unphysical_stiffness_names_the_substeps_it_would_need(capsys):
    # link1 at rest at q = 0: omega^2 = K / J_l + K / J_m (the model's defaults for J_l, J_m)
    import fjm_runtime
    p = fjm_runtime.load("link1").default_params
    K = 1e300
    omega = math.sqrt(K / p["J_l"] + K / p["J_m"])
    need = math.ceil(1.5 * 1e-3 * omega / 0.1)
    msg = _one_line_error(capsys, ["simulate", "link1", "--K", "1e300", "--duration", "0.05", "--json"],
                          ["--K", "at most 10000", "RK4 substeps"])
    assert f"{omega:.4g} rad/s" in msg and f"{need:.4g}" in msg


def _json(capsys, argv, status=0):
    got, out, err = _run(capsys, argv)
    assert got == status, err
    return json.loads(out), err


def test_generic_defaults_are_flagged_as_not_designed(capsys):
    rep, err = _json(capsys, ["simulate", "link1", "--duration", "0.05", "--json"])
    assert rep["gains_source"] == "defaults" and rep["designed_for_these_conditions"] is False
    assert any("generic defaults" in r for r in rep["not_designed_because"])
    assert err.startswith("fjm: warning: the default gains (lam 8 1/s, k_s ") and "(command line)" not in err
    assert "were not designed for link1" in err
    # a gain flag given: the command line's gains
    rep, err = _json(capsys, ["simulate", "link1", "--lam", "9", "--duration", "0.05", "--json"])
    assert rep["gains_source"] == "command line" and "(--lam, --k-s, --delta" in rep["not_designed_because"][0]
    assert err.startswith("fjm: warning: the gains (command line) were not designed for link1")


def test_the_shipped_design_is_picked_and_named_when_it_matches(capsys):
    argv = ["simulate", "panda", "--sensing", "torque", "--delay-samples", "1", "--duration", "0.02", "--json"]
    rep, err = _json(capsys, argv + ["--noise", "panda_white"])
    assert rep["gains_source"] == f"shipped design {PANDA_DESIGN}"
    assert rep["designed_for_these_conditions"] is True and "not_designed_because" not in rep
    assert rep["settings"]["controller"] == "ismc" and rep["settings"]["predict"] is True
    assert PANDA_DESIGN in err and "warning" not in err
    # the same design under another sensor and another rate: used, but said not to hold
    rep, err = _json(capsys, argv + ["--noise", "franka_like", "--gains", PANDA_DESIGN, "--rate", "500"])
    assert rep["designed_for_these_conditions"] is False
    assert rep["not_designed_because"] == ["designed at 1000 Hz, run at 500 Hz",
                                           "designed with the sensor 'panda_white', run with 'franka_like'"]
    assert "fjm: warning:" in err and "500 Hz" in err


def test_a_run_that_leaves_the_workspace_is_flagged_with_its_time(capsys):
    # q_d = 20 sin(t) crosses 4 pi at t = asin(4 pi / 20); the link follows it with a lag (an error of
    # under 1.5 rad at 15 rad/s): it crosses within 0.1 s after, never before
    t_cross = math.asin(WORKSPACE_BOUND / 20.0)
    rep, err = _json(capsys, ["simulate", "link1", "--amplitude", "20", "--duration", "1", "--json"], status=3)
    assert rep["diverged"] is True and t_cross <= rep["divergence_time"] <= t_cross + 0.1
    assert "|q_1|" in rep["reason"] and "fjm: diverged:" in err
    # without --json: the same flag in the report and the exit status
    status, out, err = _run(capsys, ["simulate", "link1", "--amplitude", "20", "--duration", "1", "--quiet"])
    assert status == 3 and json.loads(out)["diverged"] is True and "left the workspace" in err


def test_a_state_that_blows_up_exits_3_with_the_json(capsys):
    # poles at 300 1/s sampled at 100 Hz: the discrete loop is unstable (a state that blows up from legal flags)
    rep, err = _json(capsys, ["simulate", "link1", "--lam", "300", "--rate", "100", "--duration", "0.5", "--json"],
                     status=3)
    assert rep["diverged"] is True and rep["rms_second_half"] is None and rep["divergence_time"] >= 0
    assert "gains_source" in rep and "fjm: diverged:" in err


def test_workspace_exit_finds_the_first_sample_beyond_either_bound():
    t = np.linspace(0.0, 1.0, 11)
    q = np.zeros((11, 2))
    e = np.zeros((11, 2))
    assert workspace_exit(t, q, e) is None
    q[7, 1] = -(WORKSPACE_BOUND + 1e-9)      # link 2 beyond -4 pi at t = 0.7
    e[4, 0] = ERROR_BOUND + 1e-9             # joint 1 a full turn off at t = 0.4: first
    tk, why = workspace_exit(t, q, e)
    assert tk == pytest.approx(0.4) and "|e_1|" in why
    e[4, 0] = ERROR_BOUND                    # on the bound is inside
    tk, why = workspace_exit(t, q, e)
    assert tk == pytest.approx(0.7) and "|q_2|" in why
    q[2, 0] = np.nan                         # not finite counts too
    assert workspace_exit(t, q, e)[0] == pytest.approx(0.2)
