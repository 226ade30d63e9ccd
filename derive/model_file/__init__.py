"""User model files: a planar flexible-joint chain described in TOML.

``fjm derive --model-file arm.toml --out DIR`` (or ``python -m derive ...``)
derives and emits the chain into ``DIR/<name>/`` exactly like a built-in
``planar<n>`` model (same derivation, same emitter, same atomic swap)::

    [model]
    name = "arm3"                 # C identifier; becomes DIR/arm3/ and arm3_alpha() etc.
    links = 3                     # 1..7
    description = "..."           # optional, one line

    [parameters]                  # optional; omitted parameters keep the planar<n> defaults
    m1 = 2.0                      # a bare number is in fjm's SI unit for that parameter
    l1 = { default = 0.5, unit = "m" }   # or a table with default and (optional) unit

    [parameters.K1]               # table headers and dotted keys work too
    default = 180.0
    unit = "N m/rad"

Parameter names are those of ``planar<n>``: ``m1..mn, l1..ln, r1..rn,
I1..In, K1..Kn, Jm1..Jmn, Bm1..Bmn, g0``. Units must be fjm's SI units (a few
spellings accepted, e.g. ``"kg m^2"``, ``"kg*m^2"``, ``"kg·m²"``).

A second form describes a spatial arm by a URDF file (``[model] urdf = "arm.urdf"``, relative
to the model file, with ``base`` and ``tip`` link names) and per-joint elastic parameters
(``[joints.default]`` and ``[joints.<URDF joint name>]`` with ``K``, ``Jm``, ``Bm``; optional
``[parameters] g0`` and ``[notes]``); it is built by :func:`derive.spatial.spatial.make_spatial`. See
docs/spatial.md, examples/elbow_arm.toml and :mod:`derive.model_file.urdf_form`.

Either form may state the robot's ``[limits]`` (effort, velocity, torque rate; defaults: the URDF's) and
``[task]`` (the sines or poses its demo and design run), carried into the manifest
(:mod:`derive.model_file.robot_facts`).

The file is parsed with :mod:`tomllib` (Python >= 3.11) or ``tomli`` and then
checked against an explicit schema: allowed tables and keys, types, ranges and
physical plausibility. Nothing from the file is evaluated or sympified: it
only supplies a name, an integer, a description and floats. Every problem
raises :class:`ModelFileError` (a ``ValueError``) whose message reads
``<file>:<line>: <key>: <what is wrong and what is expected>``; TOML syntax
errors read ``<file>:<line>:<column>: TOML syntax error: ...``. TOML parsers
do not report where keys are, so :func:`locate_keys` finds them in the raw
text (table headers, dotted keys, quoted keys, inline tables, multi-line
strings and arrays).

Modules: :mod:`~derive.model_file.toml_keys` (key locations),
:mod:`~derive.model_file.schema` (errors and shared checks),
:mod:`~derive.model_file.chain_form` and :mod:`~derive.model_file.urdf_form`
(the two forms); this package's top level is the public entry.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Union

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python < 3.11 only
    import tomli as tomllib

from .chain_form import parse_chain_form
from .schema import Checker, ModelFileError
from .urdf_form import parse_urdf_form

__all__ = ["load_model_file", "parse_model_text"]

Path_ = Union[str, Path]

_SYNTAX = re.compile(r"^(?P<msg>.*?)\s*\(at line (?P<line>\d+), column (?P<col>\d+)\)\s*$", re.S)


def _load_toml(text: str, source: str) -> dict:
    """``tomllib.loads``, its syntax errors as :class:`ModelFileError` with line and column."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = _SYNTAX.match(msg)
        if m:
            line, col = int(m.group("line")), int(m.group("col"))
            src_lines = text.splitlines()
            near = src_lines[line - 1].strip() if 0 < line <= len(src_lines) else ""
            raise ModelFileError(f"TOML syntax error: {m.group('msg')}" + (f" in `{near}`" if near else ""),
                                 source, line, column=col) from None
        end = text.count("\n") + 1
        raise ModelFileError(f"TOML syntax error: {msg}", source, end) from None


def parse_model_text(text: str, source: str = "<model file>", base_dir: Path_ = None,
                     builtin: bool = False):
    """Parse and validate the text of a model file.

    Parameters
    ----------
    text : str
    source : str
        File name for messages.
    base_dir : path, optional
        Directory the URDF form's ``urdf`` path is relative to (default: the
        current directory).
    builtin : bool
        True for fjm's own robots (``derive/robots``), which may use built-in names.

    Returns
    -------
    ModelSpec or UrdfModelSpec

    Raises
    ------
    ModelFileError
        TOML syntax error, unknown table or key, wrong type, value out of range,
        non-physical default, unit that is not fjm's SI unit, missing required key.
    """
    data = _load_toml(text, source)
    chk = Checker(text, source)
    if isinstance(data.get("model"), dict) and "urdf" in data["model"]:
        return parse_urdf_form(data, chk, Path(base_dir) if base_dir is not None else Path("."), builtin)
    return parse_chain_form(data, chk, builtin)


def load_model_file(path: Path_, builtin: bool = False):
    """Read, parse and validate a model file (see the module docstring for the format).

    Raises
    ------
    ModelFileError
        For every problem with the file's content (message: ``<file>:<line>: <key>: ...``).
    OSError
        If the file cannot be read.
    """
    path = Path(path)
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ModelFileError(f"not UTF-8 text (byte {exc.start}); TOML files are UTF-8",
                             str(path), raw.count(b"\n", 0, exc.start) + 1) from None
    return parse_model_text(text, source=str(path), base_dir=path.parent, builtin=builtin)
