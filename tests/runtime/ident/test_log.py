"""Bad logs get one line naming the file, the row and the column (fjm_runtime.ident.log)."""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.cli.main import main as fjm_main
from fjm_runtime.ident.log import MIN_ROWS, Log, read_log, write_log
from fjm_runtime.validation import FjmValueError


@pytest.fixture(scope="module")
def link1():
    return fjm_runtime.load("link1")


def _good(N=1000, n=1, dt=1e-3, tau=True) -> Log:
    t = dt * np.arange(N)
    q = 0.3 * np.sin(2 * t)[:, None] * np.ones(n)
    qm = q + 0.01 * np.cos(3 * t)[:, None]
    u = np.cos(t)[:, None] * np.ones(n)
    return Log(t, q, qm, u, 150.0 * (qm - q) if tau else None, "good")


def _csv(tmp_path, log, edit=None, name="log.csv"):
    p = write_log(tmp_path / name, log)
    if edit is not None:
        lines = p.read_text().splitlines()
        edit(lines)
        p.write_text("\n".join(lines) + "\n")
    return p


def test_round_trip_csv_and_npz(tmp_path, link1):
    log = _good()
    for name in ("log.csv", "log.npz"):
        back = read_log(write_log(tmp_path / name, log), link1)
        for k in ("t", "q", "q_m", "u", "tau_J"):
            np.testing.assert_array_equal(getattr(back, k), getattr(log, k))
    back = read_log(write_log(tmp_path / "no_tau.csv", _good(tau=False)), link1)
    assert back.tau_J is None


def _set(row, col, value):
    def edit(lines):
        header = lines[0].split(",")
        cells = lines[row].split(",")
        cells[header.index(col)] = value
        lines[row] = ",".join(cells)
    return edit


@pytest.mark.parametrize("case,edit,expect", [
    ("missing column", lambda L: L.__setitem__(0, L[0].replace("q_m_1", "qm_1")), "missing column(s) q_m_1"),
    ("NaN", _set(5, "q_1", "nan"), "row 5, column q_1: not a finite number"),
    ("empty cell", _set(7, "u_1", ""), "row 7, column u_1: not a finite number"),
    ("inf", _set(9, "tau_J_1", "inf"), "row 9, column tau_J_1"),
    ("non-monotonic time", _set(11, "t", "0.0085"), "row 11, column t: time 0.0085 s does not increase"),
    ("dropped sample", lambda L: L.__delitem__(20), "row 20, column t: interval 0.002 s"),
    ("degrees", _set(3, "q_1", "45.0"), "row 3, column q_1: 45; expected radians"),
    ("motor side angle", _set(4, "q_m_1", "3.0"), "row 4, column q_m_1: deflection"),
])
def test_bad_csv_names_row_and_column(tmp_path, link1, case, edit, expect):
    with pytest.raises(FjmValueError) as err:
        read_log(_csv(tmp_path, _good(), edit), link1)
    msg = str(err.value)
    assert expect in msg and "\n" not in msg, (case, msg)


def test_time_in_milliseconds_and_short_logs(tmp_path, link1):
    log = _good()
    with pytest.raises(FjmValueError, match="expected seconds"):
        read_log(write_log(tmp_path / "ms.csv", Log(1000 * log.t, log.q, log.q_m, log.u, log.tau_J)), link1)
    with pytest.raises(FjmValueError, match=f"expected at least {MIN_ROWS}"):
        read_log(write_log(tmp_path / "short.csv", _good(N=MIN_ROWS - 1)), link1)


def test_torque_in_the_wrong_unit_against_the_effort_limit(tmp_path):
    panda = fjm_runtime.load("panda")
    log = _good(n=7)
    u = log.u.copy()
    u[12, 4] = 1000 * panda.effort_limits[4]            # e.g. mN m
    with pytest.raises(FjmValueError, match=r"row 13, column u_5: .* effort limit"):
        read_log(write_log(tmp_path / "u.npz", Log(log.t, log.q, log.q_m, u, log.tau_J)), panda)


def test_npz_shape_and_wrong_model(tmp_path, link1):
    with pytest.raises(FjmValueError, match=r"q has shape \(1000, 1\); expected \(1000, 7\)"):
        read_log(write_log(tmp_path / "l.npz", _good()), fjm_runtime.load("panda"))
    with pytest.raises(FjmValueError, match="missing column"):
        read_log(write_log(tmp_path / "l.csv", _good()), fjm_runtime.load("planar2"))


def test_cli_bad_log_is_one_line_and_status_2(tmp_path, capsys):
    p = _csv(tmp_path, _good(), _set(5, "q_1", "nan"))
    assert fjm_main(["identify", "link1", str(p), "--out", str(tmp_path / "p.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "row 5, column q_1" in err
    assert not (tmp_path / "p.toml").exists()
