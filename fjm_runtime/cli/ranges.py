"""The physical range of every numeric flag of ``fjm``, in one place, and the size check of what a run stores.

Each range is an argparse ``type=`` (:class:`Range`): the flag's text is parsed and refused outside its
range, before any work, in one line naming the flag (argparse prefixes ``argument --flag:``), the value
as typed and the range; ``str(range)`` is the range as the flag's help states it. The parser
(:class:`OneLineParser`) prints every usage error as one line.

Ranges (SI units):

* time: a run or log of 0 < T <= 3600 s (:data:`DURATION`); control and sample rates 1..100000 Hz
  (:data:`RATE`), their periods 1e-5..1 s (:data:`PERIOD`); delays 0..100 samples (:data:`DELAY`);
* counts: seeds 0..2^64-1 (:data:`SEED`), draws and samples bounded so that the run's arrays fit
  (:func:`check_stored_size`);
* parameter values within 1e-12..1e12 in magnitude (the export's ``C_VALUE_RANGE``), gains up to 1e20
  (``GAIN_MAX``: lam^4 at the Nyquist pole of 10 kHz is 1e18).
"""
from __future__ import annotations

import argparse
import math
import re
from pathlib import Path
from typing import Optional

from ..export.controller_checks import C_VALUE_RANGE, GAIN_MAX
from ..validation import FjmValueError

__all__ = ["Range", "OneLineParser", "available_bytes", "check_stored_size", "MAX_STORED_BYTES", "DURATION",
           "RATE", "PERIOD", "DELAY", "SEED", "ANGLE", "AMPLITUDE", "FREQUENCY", "STIFFNESS", "GAIN", "LAYER",
           "POLE", "TORQUE", "MASS", "FACTOR", "VELOCITY", "THREADS"]


class Range:
    """An argparse ``type=``: ``lo <= value <= hi`` (``lo_open``: ``lo < value``), an integer if ``integer``.

    Parameters
    ----------
    lo, hi : float
        The bounds, in ``unit``.
    unit : str
        SI unit as the help states it (``""``: a count or a ratio).
    symbol : str
        The quantity's symbol in the range text, e.g. ``"T"`` for ``0 < T <= 3600 s``.
    integer : bool
        Whole numbers only (``1e3`` is read as 1000).
    lo_open : bool
        Exclude ``lo``.
    why : str
        Why the range (appended to the error in parentheses), optional.
    """

    def __init__(self, lo: float, hi: float, unit: str = "", symbol: str = "value", integer: bool = False,
                 lo_open: bool = False, why: str = ""):
        self.lo, self.hi, self.unit, self.symbol = lo, hi, unit, symbol
        self.integer, self.lo_open, self.why = integer, lo_open, why
        self.__name__ = "integer" if integer else "number"  # argparse names the type in its own errors

    def __str__(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        kind = "an integer " if self.integer else ""
        return f"{kind}{_g(self.lo)} {'<' if self.lo_open else '<='} {self.symbol} <= {_g(self.hi)}{unit}"

    def contains(self, value: float) -> bool:
        """Whether ``value`` (a float or int) lies in the range."""
        above = value > self.lo if self.lo_open else value >= self.lo
        return math.isfinite(value) and above and value <= self.hi and (not self.integer or float(value).is_integer())

    def check(self, flag: str, value) -> None:
        """Refuse ``value`` outside the range after parsing (a flag whose own checks come first), one line."""
        if not (isinstance(value, (int, float)) and not isinstance(value, bool) and self.contains(value)):
            why = f" ({self.why})" if self.why else ""
            shown = f"{value:g}" if isinstance(value, (int, float)) else repr(value)
            raise FjmValueError(f"{flag} {shown}: expected {self}{why}")

    def __call__(self, text: str):
        try:
            value = int(text) if self.integer and str(text).strip().lstrip("+-").isdigit() else float(text)
        except (TypeError, ValueError):
            raise argparse.ArgumentTypeError(f"{text!r} is not a number; expected {self}") from None
        if self.integer and math.isfinite(value) and not float(value).is_integer():
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer; expected {self}")
        if not self.contains(value):
            why = f" ({self.why})" if self.why else ""
            raise argparse.ArgumentTypeError(f"{text}: expected {self}{why}")
        return int(value) if self.integer else float(value)


def _g(v: float) -> str:
    """A bound as the help writes it: ``2^64-1`` for the seed's, whole numbers below 1e8 in full, else ``%g``."""
    if v == 2 ** 64 - 1:
        return "2^64-1"
    return f"{int(v)}" if float(v).is_integer() and abs(v) < 1e8 else f"{v:g}"


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one :class:`FjmValueError` line, printed by ``fjm`` as every
    other error (``fjm: error: --rate 1e12: expected 1 <= rate <= 100000 Hz (...) (see fjm excite --help)``,
    exit status 2)."""

    def error(self, message: str):
        named = re.match(r"argument (-?-?[\w-]+)(?:/[^:]*)?: (.*)$", message, re.S)
        if named:
            message = f"{named.group(1)} {named.group(2)}"
        raise FjmValueError(f"{' '.join(message.split())} (see {self.prog} --help)")


#: Run, log and search durations, s: an hour (3.6e6 samples at 1 kHz); longer logs are several runs.
DURATION = Range(0, 3600, "s", "T", lo_open=True, why="an hour at most; split longer runs")
#: Control and sample rates, Hz.
RATE = Range(1, 100_000, "Hz", "rate", why="a physical controller or logger")
#: Control periods, s (at least 1 Hz; a short period is bounded by the memory the run stores).
PERIOD = Range(0, 1, "s", "dt", lo_open=True, why="at least 1 Hz")
#: Computation delay, control samples.
DELAY = Range(0, 100, "samples", "delay", integer=True)
#: Random seeds (numpy's SeedSequence takes any; the sensor's counter-based noise 64 bits).
SEED = Range(0, 2 ** 64 - 1, "", "seed", integer=True)
#: Set points and angles, rad: two full turns each way (the simulator's workspace bound).
ANGLE = Range(-4 * math.pi, 4 * math.pi, "rad", "q", why="two full turns each way")
#: Sine amplitudes and excursions, rad.
AMPLITUDE = Range(0, 2 * math.pi, "rad", "amplitude", lo_open=True, why="one full turn")
#: Reference frequencies, rad/s (a 16 kHz oscillation no arm follows).
FREQUENCY = Range(0, 1e5, "rad/s", "omega")
#: Stiffness values and bounds, N m/rad (the magnitudes the export holds).
STIFFNESS = Range(0, C_VALUE_RANGE[1], "N m/rad", "K", lo_open=True)
#: Switching gains, rad/s^4.
GAIN = Range(0, GAIN_MAX, "rad/s^4", "k_s")
#: Boundary layers, rad/s^3.
LAYER = Range(0, GAIN_MAX, "", "delta", lo_open=True)
#: Pole magnitudes, 1/s (the law's own check is 0 < lam <= pi x rate).
POLE = Range(0, math.pi * RATE.hi, "1/s", "lam", lo_open=True, why="at most pi x the highest rate")
#: Torque limits and bounds, N m (the largest industrial joints deliver ~5e4 N m).
TORQUE = Range(0, 1e6, "N m", "u", lo_open=True)
#: Payload masses, kg.
MASS = Range(0, 1e4, "kg", "m")
#: Scale factors and ratios of a true to a nominal value.
FACTOR = Range(0, 1e3, "", "factor", lo_open=True)
#: Velocities of friction laws, rad/s.
VELOCITY = Range(0, 1e4, "rad/s", "v", lo_open=True)
#: Worker threads and processes.
THREADS = Range(1, 1024, "", "threads", integer=True)

#: Largest array a command stores before it starts (when the machine's available memory is unknown), bytes.
MAX_STORED_BYTES = 8e9


def available_bytes() -> Optional[float]:
    """``MemAvailable`` of /proc/meminfo in bytes (None where there is none)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return float(line.split()[1]) * 1024.0
    except (OSError, ValueError, IndexError):
        return None
    return None


def check_stored_size(flags: str, rows: float, columns: float, advice: str, factor: float = 1.0) -> float:
    """Refuse, before allocating, ``rows x columns`` float64 values (times ``factor`` copies) beyond memory.

    Parameters
    ----------
    flags : str
        The flags that set the size, as the user gave them (e.g. ``"--duration 1e9 s at --rate 1000 Hz"``).
    rows, columns : float
        The stored array's shape.
    advice : str
        What to lower (e.g. ``"shorten --duration or lower --rate"``).
    factor : float
        Copies of the array held at once.

    Returns
    -------
    float
        The bytes it needs.

    Raises
    ------
    FjmValueError
        One line: the flags, the size and the bound (the available memory, else :data:`MAX_STORED_BYTES`).
    """
    need = float(rows) * float(columns) * 8.0 * factor
    avail = available_bytes()
    bound = MAX_STORED_BYTES if avail is None else min(avail, MAX_STORED_BYTES)
    if not need <= bound:
        raise FjmValueError(f"{flags}: {float(rows):.4g} rows x {int(columns)} columns x 8 bytes"
                            f"{f' x {factor:g}' if factor != 1 else ''} = {need / 1e9:.3g} GB; expected at most "
                            f"{bound / 1e9:.3g} GB (this machine's available memory, at most "
                            f"{MAX_STORED_BYTES / 1e9:g} GB); {advice}")
    return need
