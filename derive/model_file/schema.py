"""Shared checks of model files: :class:`ModelFileError`, the key-locating :class:`Checker`, values.

Both forms (:mod:`derive.model_file.chain_form`, :mod:`derive.model_file.urdf_form`)
raise every problem as a :class:`ModelFileError` reading
``<file>:<line>: <key>: <what is wrong and what is expected>``, with the line
found by :func:`derive.model_file.toml_keys.locate_keys`. Nothing is evaluated.
"""

from __future__ import annotations

import difflib
import json
import math
import re
from typing import Optional, Tuple

from ..core.model_base import MODEL_NAMES
from .toml_keys import BARE_KEY, KeyPath, locate_keys

__all__ = ["ModelFileError", "Checker", "got", "show", "suggest", "check_name", "check_description",
           "number", "optional_table", "NAME_RE", "MAX_NAME", "MAX_DESCRIPTION"]

NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
MAX_NAME = 64
MAX_DESCRIPTION = 500


class ModelFileError(ValueError):
    """A model file that cannot be used. ``str(err)`` names the file, line and key.

    Attributes
    ----------
    source : str
        File name (or ``"<model file>"`` for text).
    line : int or None
        1-based line of the offending key (or of the syntax error).
    column : int or None
        1-based column, for TOML syntax errors only.
    key : str or None
        Dotted key, e.g. ``"parameters.m1"``; None for syntax errors.
    """

    def __init__(self, message: str, source: str, line: Optional[int], key: Optional[str] = None,
                 column: Optional[int] = None):
        self.source, self.line, self.key, self.column = source, line, key, column
        where = source if line is None else f"{source}:{line}" + (f":{column}" if column else "")
        super().__init__(f"{where}: {key}: {message}" if key else f"{where}: {message}")


def type_name(v) -> str:
    """TOML's name of the type of a parsed value (``"integer"``, ``"table"``, ...)."""
    if isinstance(v, bool):
        return "boolean"
    if isinstance(v, int):
        return "integer"
    if isinstance(v, float):
        return "float"
    if isinstance(v, str):
        return "string"
    if isinstance(v, dict):
        return "table"
    if isinstance(v, list):
        return "array"
    return type(v).__name__  # dates and times


def show(v) -> str:
    """A parsed value as it reads in TOML (strings quoted, tables and arrays by type)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (dict, list)):
        return type_name(v)
    return repr(v)


def got(v) -> str:
    """``got string "3"``, ``got float 3.0``, ``got an array``."""
    if isinstance(v, (dict, list)):
        return f"got {'a table' if isinstance(v, dict) else 'an array'}"
    return f"got {type_name(v)} {show(v)}"


class Checker:
    """Builds :class:`ModelFileError` for a key path, at the line where the key (or its table) is."""

    def __init__(self, text: str, source: str):
        self.source = source
        self.lines = locate_keys(text)

    def line_of(self, path: KeyPath) -> int:
        for k in range(len(path), 0, -1):
            if path[:k] in self.lines:
                return self.lines[path[:k]]
        return 1

    def fail(self, path: KeyPath, message: str, line_path: Optional[KeyPath] = None) -> ModelFileError:
        return ModelFileError(message, self.source, self.line_of(line_path or path),
                              ".".join(quote_key(p) for p in path))


def quote_key(part: str) -> str:
    """A key as written in a dotted key: bare if it can be, else quoted."""
    return part if BARE_KEY.fullmatch(part) else json.dumps(part, ensure_ascii=False)


def suggest(word: str, options) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``options``, or an empty string."""
    close = difflib.get_close_matches(word, list(options), n=1, cutoff=0.6)
    lower = [o for o in options if o.lower() == word.lower()]
    best = lower or close
    return f" (did you mean {best[0]!r}?)" if best else ""


def optional_table(data: dict, chk: Checker, name: str) -> Optional[dict]:
    """The top-level table ``[name]`` of a parsed file, None when absent; a value that is not a table is refused."""
    if name not in data:
        return None
    table = data[name]
    if not isinstance(table, dict):
        raise chk.fail((name,), f"expected a table ([{name}] with key = value lines), {got(table)}")
    return table


def check_name(chk: Checker, name, builtin: bool) -> None:
    """A C identifier, not reserved, not a built-in model's name (unless ``builtin``)."""
    if not isinstance(name, str):
        raise chk.fail(("model", "name"), f"expected a string, {got(name)}")
    if not NAME_RE.fullmatch(name) or len(name) > MAX_NAME:
        raise chk.fail(("model", "name"), f"{show(name)} is not a valid model name: expected a C identifier "
                                          f"[A-Za-z_][A-Za-z0-9_]* of at most {MAX_NAME} characters "
                                          "(it names the output directory and the C functions)")
    if name.startswith("__") or re.match(r"_[A-Z]", name) or name.lower().startswith("casadi"):
        raise chk.fail(("model", "name"), f"{show(name)} is reserved (C reserves __x and _X names; "
                                          "casadi* names collide with CasADi's generated code)")
    clash = [b for b in MODEL_NAMES if b.lower() == name.lower()]
    if clash and not builtin:
        raise chk.fail(("model", "name"), f"{show(name)} is a built-in model name ({clash[0]}); "
                                          "choose another name so `fjm_runtime.load` stays unambiguous")


def check_description(chk: Checker, description, path: KeyPath = ("model", "description")) -> None:
    """One printable ASCII line, safe inside C comments (the description goes there)."""
    if description is None:
        return
    if not isinstance(description, str):
        raise chk.fail(path,
                       f"expected a string, {got(description)}")
    bad = next((c for c in description if not (" " <= c <= "~")), None)
    if bad is not None or not description.strip():
        raise chk.fail(path,
                       "expected one non-empty line of printable ASCII text"
                       + (f" (found {bad!r})" if bad is not None else ""))
    for seq in ("*/", "/*", "\\", "??"):
        if seq in description:
            raise chk.fail(path,
                           f"must not contain {seq!r} (the description goes into C comments)")
    if len(description) > MAX_DESCRIPTION:
        raise chk.fail(path,
                       f"{len(description)} characters; at most {MAX_DESCRIPTION} allowed")


#: Smallest non-zero magnitude of any value (a motor inertia of 1e-7 kg m^2 is small; below 1e-12 the
#: derivation's products underflow the conditioning its checks need).
SMALLEST = 1e-12
#: Largest magnitude of a value by its SI unit, and why: beyond it no arm exists (and the derivation's
#: numeric checks, an SVD among them, lose every digit: F_c = 1e300 ended in "SVD did not converge").
PHYSICAL_MAX = {
    "kg": (1e4, "10 t"), "m": (100.0, "100 m"), "kg m^2": (1e4, "a 10 t mass 1 m out"),
    "N m/rad": (1e9, "stiffer than any drive by 100x"), "N m/rad^3": (1e12, "a cubic spring term"),
    "N m s/rad": (1e6, "damping"), "N m": (1e6, "torque of the largest joints x 20"),
    "N m/s": (1e9, "torque rate"), "m/s^2": (100.0, "10 g"), "rad": (4 * math.pi, "two turns"),
    "rad/s": (1e4, "100000 rpm"), "1": (1e4, "gear ratio"), "s": (3600.0, "an hour"),
}


def number(chk: Checker, path: KeyPath, value, unit: str, kind: str, meaning: str,
           top: Optional[Tuple[float, str]] = None) -> float:
    """A finite number in ``unit``; ``kind`` ``">0"`` or ``">=0"`` bounds it below (any other: no bound), and
    its magnitude lies in ``0`` or ``SMALLEST .. PHYSICAL_MAX[unit]`` (``top``: this key's own bound and why)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise chk.fail(path, f"expected a number in {unit}, {got(value)}")
    value = float(value)
    if not math.isfinite(value):
        raise chk.fail(path, f"{value} is not finite: expected a finite number in {unit}")
    if kind == ">0" and not value > 0:
        raise chk.fail(path, f"{show(value)} {unit} is not physical: {meaning} must be > 0")
    if kind == ">=0" and not value >= 0:
        raise chk.fail(path, f"{show(value)} {unit} is not physical: {meaning} must be >= 0")
    top, why = top or PHYSICAL_MAX.get(unit, (1e12, "SI units"))
    if value != 0 and not SMALLEST <= abs(value) <= top:
        zero, size = ("", meaning) if kind == ">0" else ("0 or ", meaning if kind == ">=0" else f"|{meaning}|")
        raise chk.fail(path, f"{show(value)} {unit} is not physical: expected {zero}{SMALLEST:g} <= {size} <= "
                             f"{top:.6g} {unit} ({why})")
    return value
