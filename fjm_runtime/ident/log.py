"""A robot's log for identification: reading, writing and checking it (docs/identification.md).

Columns (CSV header or NPZ keys), one per joint ``i = 1..n``:

===========  =======  ==================================================================
``t``        s        sample time, increasing, uniform (1 % jitter allowed)
``q_<i>``    rad      link angle
``q_m_<i>``  rad      motor angle on the LINK side (the rotor angle divided by the gear ratio)
``tau_J_<i>`` N m     joint (spring) torque, when the arm senses it; optional
``u_<i>``    N m      commanded motor torque on the link side (what drives the motor equation)
===========  =======  ==================================================================

Extra columns (e.g. ``dq_<i>``) are ignored, unless they name a joint beyond the model's (a log of
another arm). The CSV is UTF-8 text (a byte-order mark is accepted); every data row has one field per
header column (a short last line is a truncated file). NPZ files hold ``t`` (N,) and ``q``, ``q_m``, ``u``,
``tau_J`` (N, n). Every problem is one :class:`~fjm_runtime.validation.FjmValueError` line naming
the file, the data row (1-based, the header not counted) and the column.
"""
from __future__ import annotations

import csv
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from ..validation import FjmValueError

__all__ = ["Log", "read_log", "write_log", "check_log", "MIN_ROWS", "TIME_JITTER", "MAX_DEFLECTION"]

#: Fewest samples a log may have (a few periods of the slowest motion at 1 kHz need far more).
MIN_ROWS = 200
#: Largest relative deviation of a sample interval from the median interval.
TIME_JITTER = 0.01
#: Largest plausible joint deflection ``|q_m - q|`` (rad): elastic joints deflect by milliradians;
#: beyond this the angles are in degrees or ``q_m`` is the rotor angle before the gear.
MAX_DEFLECTION = 0.5
#: Largest plausible link angle (rad): beyond it the log is in degrees.
MAX_ANGLE = 20.0
#: A torque beyond this multiple of the model's effort limit is in the wrong unit.
TORQUE_FACTOR = 10.0


@dataclass
class Log:
    """A log of ``N`` samples of an ``n``-joint arm.

    Attributes
    ----------
    t : ndarray, shape (N,)
    q, q_m, u : ndarray, shape (N, n)
    tau_J : ndarray, shape (N, n) or None
        None when the arm has no joint-torque sensors.
    source : str
        Where it came from (a file name).
    """

    t: np.ndarray
    q: np.ndarray
    q_m: np.ndarray
    u: np.ndarray
    tau_J: Optional[np.ndarray] = None
    source: str = "log"

    @property
    def n(self) -> int:
        return int(self.q.shape[1])

    @property
    def dt(self) -> float:
        """The median sample interval, s."""
        return float(np.median(np.diff(self.t)))


def _columns(n: int, with_tau: bool) -> Dict[str, List[str]]:
    names = {"q": [f"q_{i + 1}" for i in range(n)], "q_m": [f"q_m_{i + 1}" for i in range(n)],
             "u": [f"u_{i + 1}" for i in range(n)]}
    if with_tau:
        names["tau_J"] = [f"tau_J_{i + 1}" for i in range(n)]
    return names


#: Columns that carry a joint index (``q_3``): one beyond the model's joints means a log of another arm.
JOINT_COLUMN = re.compile(r"^(q|q_m|u|tau_J|dq|dq_m|dtau_J|ddq)_(\d+)$")


def _text(path: Path) -> str:
    """The file as text (UTF-8, a byte-order mark dropped); one line for a binary or compressed file."""
    raw = path.read_bytes()
    if raw[:2] == b"\x1f\x8b":
        raise FjmValueError(f"{path}: gzip-compressed; expected a plain-text CSV log (decompress it first: gunzip)")
    if raw[:4] == b"PK\x03\x04":
        raise FjmValueError(f"{path}: a zip archive; expected a plain-text CSV log (an .npz log needs the .npz suffix)")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        row = raw.count(b"\n", 0, exc.start)
        where = "header" if row == 0 else f"row {row}"
        raise FjmValueError(f"{path}: {where}: byte 0x{raw[exc.start]:02x} at offset {exc.start} is not UTF-8 text; "
                            "expected a plain-text CSV log (a binary or compressed file?)") from None


def _check_header(path: Path, header: List[str], n: int) -> None:
    for k, h in enumerate(header):
        m = JOINT_COLUMN.match(h)
        if m and not 1 <= int(m.group(2)) <= n:
            raise FjmValueError(f"{path}: header, column {k + 1} ({h}): joint {m.group(2)}; expected joints 1..{n} "
                                "(a log of another arm?)")
    want = ["t"] + [c for cols in _columns(n, False).values() for c in cols]
    missing = [c for c in want if c not in header]
    if missing:
        raise FjmValueError(f"{path}: missing column(s) {', '.join(missing[:6])}{' ...' if len(missing) > 6 else ''}; "
                            f"expected t, q_<i>, q_m_<i>, u_<i> (and tau_J_<i> if sensed) for i = 1..{n}")


def _rows(path: Path, lines: List[str], header: List[str]) -> List[List[str]]:
    """The data rows, each with exactly one field per header column (trailing blank lines dropped)."""
    rows = list(csv.reader(lines))
    while rows and not any(c.strip() for c in rows[-1]):
        rows.pop()
    if not rows:
        raise FjmValueError(f"{path}: header only, no data rows; expected at least {MIN_ROWS} rows of samples")
    ncol = len(header)
    for r, cells in enumerate(rows):
        if len(cells) != ncol:
            last = r == len(rows) - 1
            what = f"column {header[len(cells)]} missing" if len(cells) < ncol else f"{len(cells) - ncol} extra"
            hint = " (the last line cut short: a truncated file?)" if last and len(cells) < ncol else ""
            raise FjmValueError(f"{path}: row {r + 1}: {len(cells)} fields for {ncol} header columns ({what}){hint}; "
                                "expected one value per column")
    return rows


def _numbers(path: Path, rows: List[List[str]], header: List[str]) -> np.ndarray:
    """``rows`` as floats, shape (N, columns); an empty cell is NaN, text is named by row and column."""
    try:
        return np.array(rows, dtype=float)
    except ValueError:
        pass
    data = np.empty((len(rows), len(header)))
    for r, cells in enumerate(rows):
        for c, cell in enumerate(cells):
            try:
                data[r, c] = float(cell) if cell.strip() else np.nan
            except ValueError:
                raise FjmValueError(f"{path}: row {r + 1}, column {header[c]}: {cell[:20]!r} is not a number; "
                                    "expected a decimal number") from None
    return data


def _read_csv(path: Path, n: int) -> Log:
    text = _text(path)
    lines = text.splitlines()
    if len(lines) > 1 and text[-1:] not in ("\n", "\r"):
        # a writer that stopped mid-row leaves no line end; a cut inside the last number still parses
        raise FjmValueError(f"{path}: row {len(lines) - 1}: the last line has no line end (a truncated file?); "
                            "expected every row to end with a line break (append one if the file is complete)")
    header = [h.strip() for h in next(csv.reader(lines[:1]), [])]
    if not header:
        raise FjmValueError(f"{path}: empty file; expected a CSV header t, q_1, q_m_1, u_1, ... (docs/identification.md)")
    _check_header(path, header, n)
    data = _numbers(path, _rows(path, lines[1:], header), header)
    col = {h: data[:, k] for k, h in enumerate(header)}
    with_tau = all(c in col for c in _columns(n, True)["tau_J"])
    arrays = {k: np.column_stack([col[c] for c in cols]) for k, cols in _columns(n, with_tau).items()}
    _check_finite(path, header, data)
    return Log(col["t"], arrays["q"], arrays["q_m"], arrays["u"], arrays.get("tau_J"), str(path))


def _check_finite(path: Path, header: List[str], data: np.ndarray) -> None:
    bad = ~np.isfinite(data)
    if bad.any():
        row, c = np.argwhere(bad)[0]
        raise FjmValueError(f"{path}: row {row + 1}, column {header[c]}: not a finite number (empty, NaN or inf); "
                            "expected every sample complete (drop or repair the row)")


def _npz_arrays(path: Path) -> Dict[str, np.ndarray]:
    """The arrays ``t``, ``q``, ``q_m``, ``u`` (and ``tau_J``) of an NPZ archive, as floats."""
    try:
        with np.load(path, allow_pickle=False) as z:
            if not isinstance(z, np.lib.npyio.NpzFile):
                raise ValueError("a single array")
            keys = set(z.files)
            missing = [k for k in ("t", "q", "q_m", "u") if k not in keys]
            if missing:
                raise FjmValueError(f"{path}: missing array(s) {', '.join(missing)}; expected t (N,), q, q_m, u "
                                    "(N, n) and tau_J (N, n) if sensed")
            return {k: np.asarray(z[k], dtype=float) for k in ("t", "q", "q_m", "u", "tau_J") if k in keys}
    except FjmValueError:
        raise
    except (ValueError, TypeError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise FjmValueError(f"{path}: not a readable NPZ archive of numeric arrays (random bytes, "
                            "a damaged file, or object arrays); expected numpy.savez output with t (N,), q, q_m, u (N, n)") from None


def _read_npz(path: Path, n: int) -> Log:
    arr = _npz_arrays(path)
    N = arr["t"].reshape(-1).size
    for k in ("q", "q_m", "u", "tau_J"):
        if k in arr:
            if arr[k].shape != (N, n):
                more = arr[k].ndim == 2 and arr[k].shape[1] > n
                col = f", column {k}_{n + 1}" if more else ""
                raise FjmValueError(f"{path}{col}: {k} has shape {arr[k].shape}; expected ({N}, {n})"
                                    f"{' (a log of another arm?)' if more else ''}")
            bad = ~np.isfinite(arr[k])
            if bad.any():
                row, j = np.argwhere(bad)[0]
                raise FjmValueError(f"{path}: row {row + 1}, column {k}_{j + 1}: not a finite number; expected "
                                    "every sample complete")
    t = arr["t"].reshape(-1)
    if not np.all(np.isfinite(t)):
        raise FjmValueError(f"{path}: row {int(np.argmin(np.isfinite(t))) + 1}, column t: not a finite number")
    return Log(t, arr["q"], arr["q_m"], arr["u"], arr.get("tau_J"), str(path))


def read_log(path, model) -> Log:
    """The log at ``path`` (``.csv`` or ``.npz``) for ``model``, checked (:func:`check_log`).

    Raises
    ------
    FjmValueError
        One line naming the file, row and column of the first problem.
    """
    p = Path(path)
    if not p.is_file():
        raise FjmValueError(f"log {p}: not found; expected a .csv or .npz log (docs/identification.md)")
    n = int(model.n)
    if p.suffix.lower() == ".npz":
        log = _read_npz(p, n)
    elif p.suffix.lower() == ".csv":
        log = _read_csv(p, n)
    else:
        raise FjmValueError(f"log {p}: unknown format {p.suffix!r}; expected .csv or .npz")
    check_log(log, model)
    return log


def _check_time(log: Log) -> None:
    t, where = log.t, log.source
    if t.size < MIN_ROWS:
        raise FjmValueError(f"{where}: {t.size} samples; expected at least {MIN_ROWS}")
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0)) + 1
        raise FjmValueError(f"{where}: row {k + 1}, column t: time {float(t[k])!r} s does not increase (previous "
                            f"{float(t[k - 1])!r} s); expected strictly increasing time")
    med = float(np.median(d))
    if med > 0.1:
        raise FjmValueError(f"{where}: column t: sample interval {med:g}; expected seconds (is t in ms?) and a rate "
                            "of at least 10 Hz")
    off = np.abs(d - med) > TIME_JITTER * med
    if off.any():
        k = int(np.argmax(off)) + 1
        raise FjmValueError(f"{where}: row {k + 1}, column t: interval {d[k - 1]:.6g} s against the median "
                            f"{med:.6g} s; expected uniform sampling (within {TIME_JITTER:.0%}: a dropped sample?)")


def check_log(log: Log, model) -> None:
    """Shapes, time, and the units a glance can catch (degrees, motor-side angles, torque scale).

    Raises
    ------
    FjmValueError
        One line naming the row and column (``q_<i>`` ...) of the first problem.
    """
    n, where = int(model.n), log.source
    for k in ("q", "q_m", "u") + (("tau_J",) if log.tau_J is not None else ()):
        a = getattr(log, k)
        if a.shape != (log.t.size, n):
            raise FjmValueError(f"{where}: {k} has shape {a.shape}; expected ({log.t.size}, {n}) for {model.name}")
    _check_time(log)
    big = np.abs(log.q) > MAX_ANGLE
    if big.any():
        row, j = np.argwhere(big)[0]
        raise FjmValueError(f"{where}: row {row + 1}, column q_{j + 1}: {log.q[row, j]:.4g}; expected radians "
                            f"(|q| <= {MAX_ANGLE:g}: is the log in degrees?)")
    defl = np.abs(log.q_m - log.q) > MAX_DEFLECTION
    if defl.any():
        row, j = np.argwhere(defl)[0]
        raise FjmValueError(f"{where}: row {row + 1}, column q_m_{j + 1}: deflection q_m - q = "
                            f"{log.q_m[row, j] - log.q[row, j]:.4g} rad; expected |q_m - q| <= {MAX_DEFLECTION:g} "
                            "(q_m on the link side: the rotor angle divided by the gear ratio, in radians)")
    limits = getattr(model, "effort_limits", None)
    if limits is not None:
        for k in ("u", "tau_J"):
            a = getattr(log, k)
            if a is None:
                continue
            over = np.abs(a) > TORQUE_FACTOR * np.asarray(limits)[None, :]
            if over.any():
                row, j = np.argwhere(over)[0]
                raise FjmValueError(f"{where}: row {row + 1}, column {k}_{j + 1}: {a[row, j]:.4g} N m, over "
                                    f"{TORQUE_FACTOR:g}x the joint's effort limit {limits[j]:g} N m; expected N m "
                                    "on the link side (motor-side torque not multiplied by the gear ratio?)")


def write_log(path, log: Log) -> Path:
    """Write ``log`` as CSV (full precision) or NPZ, by the suffix of ``path``; returns the path."""
    p = Path(path)
    n = log.n
    if p.suffix.lower() == ".npz":
        arrays = {"t": log.t, "q": log.q, "q_m": log.q_m, "u": log.u}
        if log.tau_J is not None:
            arrays["tau_J"] = log.tau_J
        np.savez(p, **arrays)
        return p
    cols = _columns(n, log.tau_J is not None)
    header = ["t"] + [c for k in cols for c in cols[k]]
    data = np.column_stack([log.t] + [getattr(log, k) for k in cols])
    p.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(p, data, delimiter=",", header=",".join(header), comments="", fmt="%.17g")
    return p
