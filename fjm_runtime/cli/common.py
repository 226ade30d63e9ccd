"""What every ``fjm`` command shares: ``NAME=VALUE`` parsing, output checks, JSON without NaN or inf."""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Dict, List, Optional

from ..validation import FjmValueError


def parse_assignments(items: Optional[List[str]], flag: str) -> Dict[str, float]:
    """``['K=120', 'J_l=1.2']`` -> ``{'K': 120.0, 'J_l': 1.2}``; a one-line FjmValueError naming ``flag`` otherwise."""
    out: Dict[str, float] = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise FjmValueError(f"{flag} {item!r}: expected NAME=VALUE, e.g. {flag} K=120")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise FjmValueError(f"{flag} {item!r}: VALUE {value!r} is not a number") from None
    return out


def check_output_file(path: Path, flag: str, make_parent: bool = False) -> Path:
    """Refuse, before any long work, an output file that cannot be written.

    The parent directory must exist (nothing is created from the filesystem root; with
    ``make_parent`` a missing parent is created when ITS parent exists, e.g. ``out/`` for
    ``out/sweep.csv``), ``path`` must not be a directory, and a file must be creatable there
    (tried and removed).

    Raises
    ------
    FjmValueError
        One line naming ``flag``, the path and what was expected.
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if make_parent and not parent.exists() and parent.parent.is_dir():
        try:
            parent.mkdir()
        except OSError as exc:
            raise FjmValueError(f"{flag} {path}: cannot create the directory {parent} "
                                f"({exc.strerror or exc})") from None
    if not parent.is_dir():
        raise FjmValueError(f"{flag} {path}: the directory {parent} does not exist (expected an existing "
                            "directory; create it first)")
    if path.is_dir():
        raise FjmValueError(f"{flag} {path}: is a directory (expected a file path)")
    if path.exists():
        if not os.access(path, os.W_OK):
            raise FjmValueError(f"{flag} {path}: the file is not writable")
        return path
    try:
        with open(path, "x"):
            pass
        path.unlink()
    except OSError as exc:
        raise FjmValueError(f"{flag} {path}: cannot create a file there ({exc.strerror or exc})") from None
    return path


def check_output_dir(path: Path, flag: str) -> Path:
    """Refuse an output directory that is a file or whose parent does not exist (one line, FjmValueError)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise FjmValueError(f"{flag} {path}: is a file (expected a directory, existing or to be created)")
    parent = path.parent if str(path.parent) else Path(".")
    if not path.exists() and not parent.is_dir():
        raise FjmValueError(f"{flag} {path}: the parent directory {parent} does not exist")
    if not os.access(path if path.exists() else parent, os.W_OK):
        raise FjmValueError(f"{flag} {path}: not writable")
    return path


def finite_or_note(report: Dict[str, object], name: str, value: float, not_finite: str = "not finite") -> None:
    """``report[name] = value`` if finite, else ``report[name] = None`` and ``report[name + '_note']``.

    ``+inf`` is noted as ``'not reached'`` (a time never reached), anything else as ``not_finite``.
    JSON written by ``fjm`` never holds NaN, Infinity or the string ``'inf'``.
    """
    v = float(value)
    if math.isfinite(v):
        report[name] = v
    else:
        report[name] = None
        report[name + "_note"] = "not reached" if v == math.inf else not_finite


INTERFACE_HELP = ("command interface: a preset (motor: motor torque through a 2 kHz current loop, the default; "
                  "ideal; joint_torque; franka: libfranka's filter, rate limit and gravity) or a TOML interface "
                  "file (docs/simulation.md)")


def add_interface_argument(parser) -> None:
    """``--interface NAME|FILE.toml`` (default: the design's, else ``motor``)."""
    parser.add_argument("--interface", default=None, metavar="NAME|FILE.toml", help=INTERFACE_HELP)


def interface_arg(args, design=None):
    """The run's CommandInterface: ``--interface``, else the design's (a design record without one: ``motor``
    with the rate limit its sensor record states), else ``motor``."""
    from ..sim.interface import CommandInterface, interface_from_record, interface_from_spec
    given = getattr(args, "interface", None)
    if given is not None:
        return interface_from_spec(given, what="--interface")
    if design is not None:
        return interface_from_record({"interface": design.interface, "sensor": design.sensor}, design.source)
    return CommandInterface.motor()
