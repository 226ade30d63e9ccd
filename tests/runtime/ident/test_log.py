"""Bad logs get one line naming the file, the row and the column (fjm_runtime.ident.log)."""
import gzip
import warnings

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.cli.main import main as fjm_main
from fjm_runtime.ident.log import MIN_ROWS, Log, read_log, write_log
from fjm_runtime.validation import FjmValueError


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


# --- files that are not logs of this arm: one line naming the file (and the row and column where one applies) ---

def _cli_error(tmp_path, capsys, path, model="link1"):
    """``fjm identify`` on ``path``: the exit status 2, nothing written, the one stderr line."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")              # numpy's "empty input" warnings are not a message
        status = fjm_main(["identify", model, str(path), "--out", str(tmp_path / "p.toml")])
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert status == 2, (status, err)
    assert err.count("\n") == 0 and "Traceback" not in err and err.startswith("fjm: error: "), err
    assert str(path) in err, err
    assert not (tmp_path / "p.toml").exists()
    return err


def test_gzipped_and_binary_csv(tmp_path, capsys):
    text = write_log(tmp_path / "good.csv", _good()).read_bytes()
    gz = tmp_path / "gz.csv"
    gz.write_bytes(gzip.compress(text))
    assert "gzip-compressed" in _cli_error(tmp_path, capsys, gz)
    lines = text.split(b"\n")
    lines[3] = bytes([0x87, 0x00, 0xff, 0x10]) + lines[3]          # binary bytes inside data row 3
    binary = tmp_path / "binary.csv"
    binary.write_bytes(b"\n".join(lines))
    err = _cli_error(tmp_path, capsys, binary)
    assert "row 3: byte 0x87" in err and f"offset {len(b''.join(l + b'x' for l in lines[:3]))}" in err, err


def test_random_bytes_npz(tmp_path, capsys):
    p = tmp_path / "random.npz"
    p.write_bytes(np.random.default_rng(0).bytes(4096))
    err = _cli_error(tmp_path, capsys, p)
    assert "not a readable NPZ archive" in err and "pickle" not in err, err
    obj = tmp_path / "object.npz"                                    # arrays numpy would only unpickle
    np.savez(obj, t=np.arange(3.0), q=np.array([None, 1, 2], dtype=object), q_m=np.zeros(3), u=np.zeros(3))
    assert "not a readable NPZ archive" in _cli_error(tmp_path, capsys, obj)


@pytest.mark.parametrize("row,cells,expect", [
    (12, lambda c: c[:-1], "row 12: 4 fields for 5 header columns (column tau_J_1 missing)"),
    (500, lambda c: c + ["0.5"], "row 500: 6 fields for 5 header columns (1 extra)"),
])
def test_row_with_the_wrong_number_of_fields(tmp_path, capsys, row, cells, expect):
    def edit(lines):
        lines[row] = ",".join(cells(lines[row].split(",")))
    assert expect in _cli_error(tmp_path, capsys, _csv(tmp_path, _good(), edit))


@pytest.mark.parametrize("cut", [0.5, 3])
def test_truncated_last_line(tmp_path, capsys, cut):
    """The write stopped inside row 1000: half way through it, or 3 digits into its last number (every
    field there, the value wrong); also the half row with a line end added."""
    p = write_log(tmp_path / "cut.csv", _good(N=1000))
    text = p.read_text()
    last = text.rstrip("\n").rsplit("\n", 1)[1]
    keep = int(len(last) * cut) if cut < 1 else len(last) - len(last.rsplit(",", 1)[1]) + cut
    cut_text = text[:len(text) - 1 - len(last) + keep]
    assert cut_text.count("\n") == 1000 and (cut < 1) == (cut_text.count(",") < 4 * 1001)
    p.write_text(cut_text)
    err = _cli_error(tmp_path, capsys, p)
    assert "row 1000: the last line has no line end (a truncated file?)" in err, err
    p.write_text(cut_text + "\n")
    if cut < 1:
        fields = cut_text.rsplit("\n", 1)[1].count(",") + 1
        missing = ["t", "q_1", "q_m_1", "u_1", "tau_J_1"][fields]
        assert f"row 1000: {fields} fields for 5 header columns (column {missing} missing) (the last line cut " \
            "short" in _cli_error(tmp_path, capsys, p)


def test_extra_joints(tmp_path, capsys):
    panda_log = _good(n=7)
    err = _cli_error(tmp_path, capsys, write_log(tmp_path / "panda.csv", panda_log), "link1")
    assert "column 3 (q_2): joint 2; expected joints 1..1" in err, err
    err = _cli_error(tmp_path, capsys, write_log(tmp_path / "panda.npz", panda_log), "link1")
    assert "column q_2: q has shape (1000, 7); expected (1000, 1)" in err, err

    def add_q8(lines):
        lines[0] += ",q_8"
        for r in range(1, len(lines)):
            lines[r] += ",0.1"
    err = _cli_error(tmp_path, capsys, _csv(tmp_path, panda_log, add_q8, "q8.csv"), "panda")
    assert "column 30 (q_8): joint 8; expected joints 1..7" in err, err


def test_byte_order_mark_is_accepted(tmp_path, link1):
    log = _good()
    p = write_log(tmp_path / "bom.csv", log)
    p.write_bytes(b"\xef\xbb\xbf" + p.read_bytes())                  # as spreadsheet programs write UTF-8
    back = read_log(p, link1)
    for k in ("t", "q", "q_m", "u", "tau_J"):
        np.testing.assert_array_equal(getattr(back, k), getattr(log, k))


def test_header_only_and_text_cells(tmp_path, capsys):
    p = write_log(tmp_path / "header.csv", _good())
    p.write_text(p.read_text().splitlines()[0] + "\n")
    assert "header only, no data rows" in _cli_error(tmp_path, capsys, p)
    err = _cli_error(tmp_path, capsys, _csv(tmp_path, _good(), _set(8, "q_m_1", "0.1x"), "text.csv"))
    assert "row 8, column q_m_1: '0.1x' is not a number" in err, err
