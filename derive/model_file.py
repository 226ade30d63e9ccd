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
``[parameters] g0`` and ``[notes]``); it is built by :func:`derive.spatial.make_spatial`. See
docs/spatial.md and examples/elbow_arm.toml.

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
"""

from __future__ import annotations

import bisect
import difflib
import json
import math
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Tuple, Union

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python < 3.11 only
    import tomli as tomllib

from .models import MODEL_NAMES, FlexibleJointModel, make_planar

__all__ = ["ModelFileError", "ModelSpec", "load_model_file", "parse_model_text", "locate_keys",
           "SI_UNITS", "MAX_LINKS", "UrdfModelSpec"]

MAX_LINKS = 7
NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
MAX_NAME = 64
MAX_DESCRIPTION = 500

#: Parameter groups of a planar chain: prefix -> (SI unit, lower bound kind, meaning).
#: ``">0"``: strictly positive; ``">=0"``: non-negative.
_GROUPS: Dict[str, Tuple[str, str, str]] = {
    "m": ("kg", ">0", "link mass"),
    "l": ("m", ">0", "link length"),
    "r": ("m", ">0", "joint -> centre of mass distance"),
    "I": ("kg m^2", ">0", "link inertia about its centre of mass"),
    "K": ("N m/rad", ">0", "joint stiffness"),
    "Jm": ("kg m^2", ">0", "motor inertia"),
    "Bm": ("N m s/rad", ">=0", "motor viscous damping"),
}
_GRAVITY = ("m/s^2", ">=0", "gravitational acceleration")

#: SI unit of every parameter prefix (and ``g0``), as written in manifests.
SI_UNITS: Dict[str, str] = {**{g: u for g, (u, _, _) in _GROUPS.items()}, "g0": _GRAVITY[0]}

_MODEL_KEYS = ("name", "links", "description")
_PARAM_TABLE_KEYS = ("default", "unit")

Path_ = Union[str, Path]
KeyPath = Tuple[str, ...]


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


@dataclass(frozen=True)
class ModelSpec:
    """A validated model file: everything :func:`derive.models.make_planar` needs."""

    name: str
    links: int
    description: Optional[str]
    defaults: Dict[str, float] = field(default_factory=dict)
    units: Dict[str, str] = field(default_factory=dict)  # parameter name -> SI unit (all params)
    source: str = "<model file>"

    def build(self) -> FlexibleJointModel:
        """The symbolic model (a planar chain with this name, defaults and description)."""
        return make_planar(self.links, name=self.name, defaults=dict(self.defaults),
                           description=self.description)


# --------------------------------------------------------------------------------------------
# Key locations in the raw text
# --------------------------------------------------------------------------------------------

_BARE = re.compile(r"[A-Za-z0-9_-]+")
_SCALAR = re.compile(r"[^,\]}\n#]*")  # numbers, booleans, dates: up to a delimiter
_BASIC_ESCAPE = re.compile(r'\\(?:u[0-9A-Fa-f]{4}|U[0-9A-Fa-f]{8}|.)', re.S)


def _unescape_basic(raw: str) -> str:
    def one(m: "re.Match[str]") -> str:
        s = m.group(0)
        if s[1] in "uU":
            try:
                return chr(int(s[2:], 16))
            except ValueError:
                return s
        return {"b": "\b", "t": "\t", "n": "\n", "f": "\f", "r": "\r", "e": "\x1b",
                '"': '"', "\\": "\\"}.get(s[1], s)
    return _BASIC_ESCAPE.sub(one, raw)


class _Scanner:
    """Finds the line of every key of a (syntactically valid) TOML document."""

    def __init__(self, text: str):
        self.s = text
        self.i = 0
        self.newlines = [k for k, c in enumerate(text) if c == "\n"]
        self.found: Dict[KeyPath, int] = {}

    def line(self, pos: int) -> int:
        return bisect.bisect_right(self.newlines, pos - 1) + 1

    def peek(self, k: int = 1) -> str:
        return self.s[self.i:self.i + k]

    def skip_ws(self, newlines: bool = False) -> None:
        s = self.s
        while self.i < len(s):
            c = s[self.i]
            if c in " \t\r" or (newlines and c == "\n"):
                self.i += 1
            elif c == "#" and newlines:
                while self.i < len(s) and s[self.i] != "\n":
                    self.i += 1
            else:
                break

    def record(self, path: KeyPath, pos: int) -> None:
        ln = self.line(pos)
        for k in range(1, len(path) + 1):
            self.found.setdefault(path[:k], ln)

    def string(self) -> str:
        """Consume a string of any of TOML's four kinds; return its (approximate) value."""
        s = self.s
        for delim in ('"""', "'''"):
            if s.startswith(delim, self.i):
                start = self.i + 3
                j = start
                while True:
                    j = s.find(delim, j)
                    if j < 0:
                        self.i = len(s)
                        return s[start:]
                    backslashes = 0
                    while delim == '"""' and s[j - 1 - backslashes] == "\\" and j - 1 - backslashes >= start:
                        backslashes += 1
                    if backslashes % 2 == 0:
                        break
                    j += 1
                run = j
                while run < len(s) and s[run] == delim[0]:
                    run += 1
                extra = min(run - j, 5) - 3  # up to two quotes right before the closing ones are content
                self.i = j + 3 + extra
                return s[start:j + extra]
        q = s[self.i]
        j = self.i + 1
        while j < len(s) and s[j] != q and s[j] != "\n":
            if q == '"' and s[j] == "\\":
                j += 1
            j += 1
        raw = s[self.i + 1:j]
        self.i = j + 1
        return _unescape_basic(raw) if q == '"' else raw

    def key(self) -> Tuple[KeyPath, int]:
        parts: List[str] = []
        self.skip_ws()
        start = self.i
        while True:
            self.skip_ws()
            if self.peek() in ('"', "'"):
                parts.append(self.string())
            else:
                m = _BARE.match(self.s, self.i)
                if not m:
                    break
                parts.append(m.group(0))
                self.i = m.end()
            self.skip_ws()
            if self.peek() == ".":
                self.i += 1
                continue
            break
        return tuple(parts), start

    def value(self, path: Optional[KeyPath]) -> None:
        self.skip_ws()
        c = self.peek()
        if c in ('"', "'"):
            self.string()
        elif c == "[":
            self.i += 1
            while True:
                self.skip_ws(newlines=True)
                if self.peek() in ("]", ""):
                    self.i += 1
                    return
                self.value(None)
                self.skip_ws(newlines=True)
                if self.peek() == ",":
                    self.i += 1
        elif c == "{":
            self.i += 1
            while True:
                self.skip_ws()
                if self.peek() in ("}", "", "\n"):
                    self.i += 1
                    return
                parts, start = self.key()
                if not parts:  # not valid TOML; bail out of the table
                    self.i += 1
                    continue
                if path is not None:
                    self.record(path + parts, start)
                self.skip_ws()
                if self.peek() == "=":
                    self.i += 1
                self.value(None if path is None else path + parts)
                self.skip_ws()
                if self.peek() == ",":
                    self.i += 1
        else:
            m = _SCALAR.match(self.s, self.i)
            self.i = m.end()

    def run(self) -> Dict[KeyPath, int]:
        s = self.s
        table: KeyPath = ()
        while True:
            self.skip_ws(newlines=True)
            if self.i >= len(s):
                return self.found
            if s.startswith("[[", self.i):
                self.i += 2
                table, start = self.key()
                self.record(table, start)
                self.i = s.find("]]", self.i) + 2 if "]]" in s[self.i:] else len(s)
            elif s[self.i] == "[":
                self.i += 1
                table, start = self.key()
                self.record(table, start)
                self.skip_ws()
                if self.peek() == "]":
                    self.i += 1
            else:
                parts, start = self.key()
                if not parts:  # not valid TOML: skip the line
                    nl = s.find("\n", self.i)
                    self.i = len(s) if nl < 0 else nl + 1
                    continue
                self.record(table + parts, start)
                self.skip_ws()
                if self.peek() == "=":
                    self.i += 1
                self.value(table + parts)


def locate_keys(text: str) -> Dict[KeyPath, int]:
    """Line (1-based) where each key path is first defined, e.g. ``("parameters", "m1") -> 7``.

    Handles table headers (``[parameters.m1]``), arrays of tables, dotted and
    quoted keys (``parameters."m1".default``), inline tables (their keys get
    the line of the inline table) and skips the content of strings (including
    multi-line ones), arrays and comments. Super-tables that are only implied
    (``a`` in ``[a.b]`` or ``a.b = 1``) get the line of their first mention.
    """
    return _Scanner(text).run()


# --------------------------------------------------------------------------------------------
# Parsing and schema
# --------------------------------------------------------------------------------------------

_SYNTAX = re.compile(r"^(?P<msg>.*?)\s*\(at line (?P<line>\d+), column (?P<col>\d+)\)\s*$", re.S)


def _normalize_unit(unit: str) -> str:
    u = unit.strip().replace("²", "^2").replace("**", "^")
    u = re.sub(r"[\s*·.]+", "", u)
    u = u.replace("^2", "2").replace("^-2", "-2").replace("^-1", "-1")
    aliases = {"ms-2": "m/s2", "Nmrad-1": "Nm/rad", "Nmsrad-1": "Nms/rad"}
    return aliases.get(u, u)


def _type_name(v) -> str:
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


def _show(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (dict, list)):
        return _type_name(v)
    return repr(v)


def _got(v) -> str:
    """``got string "3"``, ``got float 3.0``, ``got an array``."""
    if isinstance(v, (dict, list)):
        return f"got {'a table' if isinstance(v, dict) else 'an array'}"
    return f"got {_type_name(v)} {_show(v)}"


def _param_names(n: int) -> List[str]:
    return [f"{g}{i}" for g in _GROUPS for i in range(1, n + 1)] + ["g0"]


def _group_of(name: str) -> str:
    return "g0" if name == "g0" else name.rstrip("0123456789")


def _describe_names(n: int) -> str:
    if n == 1:
        return ", ".join(_param_names(1))
    return ", ".join(f"{g}1..{g}{n}" for g in _GROUPS) + ", g0"


class _Checker:
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
                              ".".join(_quote_key(p) for p in path))


def _quote_key(part: str) -> str:
    return part if _BARE.fullmatch(part) else json.dumps(part, ensure_ascii=False)


def _suggest(word: str, options) -> str:
    close = difflib.get_close_matches(word, list(options), n=1, cutoff=0.6)
    lower = [o for o in options if o.lower() == word.lower()]
    best = lower or close
    return f" (did you mean {best[0]!r}?)" if best else ""


def _check_name(chk: "_Checker", name, builtin: bool) -> None:
    """A C identifier, not reserved, not a built-in model's name (unless ``builtin``)."""
    if not isinstance(name, str):
        raise chk.fail(("model", "name"), f"expected a string, {_got(name)}")
    if not NAME_RE.fullmatch(name) or len(name) > MAX_NAME:
        raise chk.fail(("model", "name"), f"{_show(name)} is not a valid model name: expected a C identifier "
                                          f"[A-Za-z_][A-Za-z0-9_]* of at most {MAX_NAME} characters "
                                          "(it names the output directory and the C functions)")
    if name.startswith("__") or re.match(r"_[A-Z]", name) or name.lower().startswith("casadi"):
        raise chk.fail(("model", "name"), f"{_show(name)} is reserved (C reserves __x and _X names; "
                                          "casadi* names collide with CasADi's generated code)")
    clash = [b for b in MODEL_NAMES if b.lower() == name.lower()]
    if clash and not builtin:
        raise chk.fail(("model", "name"), f"{_show(name)} is a built-in model name ({clash[0]}); "
                                          "choose another name so `fjm_runtime.load` stays unambiguous")


def _check_description(chk: "_Checker", description, path: KeyPath = ("model", "description")) -> None:
    """One printable ASCII line, safe inside C comments (the description goes there)."""
    if description is None:
        return
    if not isinstance(description, str):
        raise chk.fail(path,
                       f"expected a string, {_got(description)}")
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
    try:
        data = tomllib.loads(text)
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
    chk = _Checker(text, source)
    if isinstance(data.get("model"), dict) and "urdf" in data["model"]:
        return _parse_urdf_form(data, chk, Path(base_dir) if base_dir is not None else Path("."), builtin)

    # ---- top level -----------------------------------------------------------------------
    for key in data:
        if key not in ("model", "parameters"):
            hint = (f" (did you mean `{key} = ...` under [model]?)" if key in _MODEL_KEYS
                    else " (parameters go under [parameters])" if _group_of(key) in SI_UNITS
                    else _suggest(key, ("model", "parameters")))
            raise chk.fail((key,), f"unknown key; a model file has the tables [model] and "
                                   f"[parameters] only{hint}")
    if "model" not in data:
        raise ModelFileError("missing required table [model] (with name = \"...\" and links = 1..7)",
                             source, 1, "model")
    model = data["model"]
    if not isinstance(model, dict):
        raise chk.fail(("model",), f"expected a table ([model] with name and links), "
                                   f"{_got(model)}")
    for key in model:
        if key not in _MODEL_KEYS:
            raise chk.fail(("model", key), f"unknown key; [model] allows {', '.join(_MODEL_KEYS)}"
                                           + _suggest(key, _MODEL_KEYS))
    for key in ("name", "links"):
        if key not in model:
            what = ('the model name, e.g. name = "arm3"' if key == "name"
                    else f"the number of links, e.g. links = 3 (1..{MAX_LINKS})")
            raise chk.fail(("model", key), f"missing required key: {what}", line_path=("model",))

    name = model["name"]
    _check_name(chk, name, builtin)

    links = model["links"]
    if isinstance(links, bool) or not isinstance(links, int):
        raise chk.fail(("model", "links"), f"expected an integer 1..{MAX_LINKS}, "
                                           f"{_got(links)}")
    if not 1 <= links <= MAX_LINKS:
        raise chk.fail(("model", "links"), f"{links} is out of range: expected 1..{MAX_LINKS}")

    description = model.get("description")
    _check_description(chk, description)

    # ---- parameters ----------------------------------------------------------------------
    params = data.get("parameters", {})
    if not isinstance(params, dict):
        raise chk.fail(("parameters",), f"expected a table ([parameters] with name = value lines), "
                                        f"{_got(params)}")
    names = _param_names(links)
    defaults: Dict[str, float] = {}
    value_path: Dict[str, KeyPath] = {}
    for key, entry in params.items():
        path: KeyPath = ("parameters", key)
        if key not in names:
            grp = _group_of(key)
            if grp in _GROUPS and key[len(grp):].isdigit():
                why = f"a {links}-link chain has no parameter {key!r}"
            else:
                why = f"{key!r} is not a parameter of a planar chain" + _suggest(key, names)
            raise chk.fail(path, f"unknown parameter: {why}; expected names among "
                                 f"{_describe_names(links)}")
        si = SI_UNITS[_group_of(key)]
        if isinstance(entry, dict):
            for k in entry:
                if k not in _PARAM_TABLE_KEYS:
                    raise chk.fail(path + (k,), f"unknown key; a parameter table allows "
                                                f"{', '.join(_PARAM_TABLE_KEYS)}" + _suggest(k, _PARAM_TABLE_KEYS))
            if "default" not in entry:
                raise chk.fail(path + ("default",), f"missing required key: the default value in {si}",
                               line_path=path)
            vpath = path + ("default",)
            value = entry["default"]
            if "unit" in entry:
                unit = entry["unit"]
                if not isinstance(unit, str):
                    raise chk.fail(path + ("unit",), f"expected a string (e.g. {si!r}), "
                                                     f"{_got(unit)}")
                if _normalize_unit(unit) != _normalize_unit(si):
                    raise chk.fail(path + ("unit",),
                                   f"unit {_show(unit)} is not fjm's unit for {key}: fjm uses SI units, "
                                   f"{key} must be given in {si!r}; convert the value")
        else:
            vpath, value = path, entry
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise chk.fail(vpath, f"expected a number in {si}, {_got(value)}")
        value = float(value)
        if not math.isfinite(value):
            raise chk.fail(vpath, f"{value} is not finite: expected a finite number in {si}")
        kind, meaning = ((_GROUPS[_group_of(key)][1], _GROUPS[_group_of(key)][2]) if key != "g0"
                         else (_GRAVITY[1], _GRAVITY[2]))
        if kind == ">0" and not value > 0:
            raise chk.fail(vpath, f"{_show(value)} {si} is not physical: {meaning} must be > 0")
        if kind == ">=0" and not value >= 0:
            raise chk.fail(vpath, f"{_show(value)} {si} is not physical: {meaning} must be >= 0")
        defaults[key] = value
        value_path[key] = vpath

    # r_i <= l_i on the effective defaults (file values over planar<n> defaults).
    base = {p.name: p.default for p in make_planar(links).params}
    for i in range(1, links + 1):
        r, l = f"r{i}", f"l{i}"
        rv, lv = defaults.get(r, base[r]), defaults.get(l, base[l])
        if rv > lv:
            if r in defaults:
                origin = "" if l in defaults else " (default)"
                raise chk.fail(value_path[r], f"{_show(rv)} m > {l} = {_show(lv)} m{origin}: the centre of "
                                              f"mass must lie on the link (expected {r} <= {l})")
            raise chk.fail(value_path[l], f"{_show(lv)} m < {r} = {_show(rv)} m (default): the centre of mass "
                                          f"must lie on the link (expected {l} >= {r}; set {r} too)")

    units = {n_: SI_UNITS[_group_of(n_)] for n_ in names}
    return ModelSpec(name=name, links=links, description=description,
                     defaults={k: defaults[k] for k in names if k in defaults}, units=units, source=source)


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


# --------------------------------------------------------------------------------------------
# URDF form
# --------------------------------------------------------------------------------------------

REPO = Path(__file__).resolve().parent.parent
_URDF_MODEL_KEYS = ("name", "urdf", "base", "tip", "description", "symbolic")
_URDF_TOP = ("model", "joints", "parameters", "payload", "notes")
#: Elastic parameters per joint: key -> (SI unit, bound kind, meaning, default or None = required).
_ELASTIC: Dict[str, Tuple[str, str, str, Optional[float]]] = {
    "K": ("N m/rad", ">0", "joint stiffness", None),
    "Jm": ("kg m^2", ">0", "reflected motor inertia", None),
    "Bm": ("N m s/rad", ">=0", "motor viscous damping", 0.0),
}
DEFAULT_G0 = 9.81


@dataclass(frozen=True)
class UrdfModelSpec:
    """A validated URDF model file: a spatial chain with elastic joints.

    Attributes
    ----------
    name : str
    urdf : pathlib.Path
        The URDF file (resolved).
    base, tip : str
    joints : tuple of str
        URDF joint names in q order.
    K, Jm, Bm : tuple of float
        Per-joint defaults, in q order.
    g0 : float
    description : str or None
    notes : dict str -> str
        Text appended to the meaning of ``K``, ``Jm``, ``Bm`` (sources of illustrative values).
    source : str
    """

    name: str
    urdf: Path
    base: str
    tip: str
    joints: Tuple[str, ...]
    K: Tuple[float, ...]
    Jm: Tuple[float, ...]
    Bm: Tuple[float, ...]
    g0: float
    description: Optional[str]
    notes: Dict[str, str] = field(default_factory=dict)
    source: str = "<model file>"
    payload: Optional[Tuple[float, Tuple[float, float, float]]] = None  # (mass, com in the tip frame)
    symbolic: Tuple[str, ...] = ()  # links whose inertials are runtime parameters

    def build(self) -> FlexibleJointModel:
        """The symbolic model (:func:`derive.spatial.make_spatial` of the URDF chain)."""
        from .spatial import elastic_params, inertial_params, make_spatial, payload_params
        from .urdf import load_urdf

        chain = load_urdf(self.urdf, self.base, self.tip, source=_repo_relative(self.urdf))
        n = len(chain.joints)
        params = elastic_params(n, self.K, self.Jm, self.Bm, self.g0, chain.joints,
                                {k: f"; {v}" for k, v in self.notes.items()})
        if self.payload is not None:
            params = params + payload_params(self.payload[0], self.payload[1], self.tip)
        params = params + inertial_params(chain.description, self.symbolic)
        description = self.description or (
            f"Spatial serial chain of {n} revolute joints from the URDF {_repo_relative(self.urdf)} "
            f"(robot {chain.robot}, {self.base} -> {self.tip}), flexible joints, gravity g0 along -z "
            f"of {self.base}.")
        model = make_spatial(chain.description, self.name, params, description, symbolic=self.symbolic)
        src = {"urdf": _repo_relative(self.urdf), "sha256": chain.sha256, "base": self.base,
               "tip": self.tip, "joints": list(chain.joints)}
        if chain.ignored:
            src["ignored_links"] = list(chain.ignored)
        from dataclasses import replace
        return replace(model, source=src)


def _repo_relative(path: Path) -> str:
    """``path`` relative to the repository root (POSIX), or its file name if outside it."""
    resolved = Path(path).resolve()
    try:
        return resolved.relative_to(REPO).as_posix()
    except ValueError:
        return resolved.name


def _number(chk: "_Checker", path: KeyPath, value, unit: str, kind: str, meaning: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise chk.fail(path, f"expected a number in {unit}, {_got(value)}")
    value = float(value)
    if not math.isfinite(value):
        raise chk.fail(path, f"{value} is not finite: expected a finite number in {unit}")
    if kind == ">0" and not value > 0:
        raise chk.fail(path, f"{_show(value)} {unit} is not physical: {meaning} must be > 0")
    if kind == ">=0" and not value >= 0:
        raise chk.fail(path, f"{_show(value)} {unit} is not physical: {meaning} must be >= 0")
    return value


def _parse_urdf_form(data: dict, chk: "_Checker", base_dir: Path, builtin: bool) -> UrdfModelSpec:
    """The URDF form of a model file (see docs/spatial.md)::

        [model]
        name = "arm"
        urdf = "arm.urdf"          # relative to the model file
        base = "base_link"
        tip = "tool0"
        [joints.default]           # every chain joint, unless overridden
        K = 5000.0                 # N m/rad
        Jm = 0.2                   # kg m^2
        Bm = 0.0                   # N m s/rad (optional, default 0)
        [joints.elbow]             # a URDF joint name on the chain
        K = 2000.0
        [parameters]
        g0 = 9.81                  # optional
        [payload]                  # optional: parameters m_load, x_load, y_load, z_load
        mass = 0.5                 # kg (default of m_load), a point mass fixed to the tip link
        com = [0.0, 0.0, 0.1]      # m, in the tip link frame
        [notes]                    # optional text appended to the parameter meanings
        K = "illustrative, see ..."
    """
    from .urdf import UrdfError, load_urdf

    for key in data:
        if key not in _URDF_TOP:
            raise chk.fail((key,), "unknown key; a URDF model file has the tables "
                                   f"{', '.join('[' + t + ']' for t in _URDF_TOP)} only" + _suggest(key, _URDF_TOP))
    model = data["model"]
    for key in model:
        if key not in _URDF_MODEL_KEYS:
            raise chk.fail(("model", key), f"unknown key; [model] of the URDF form allows "
                                           f"{', '.join(_URDF_MODEL_KEYS)}" + _suggest(key, _URDF_MODEL_KEYS))
    for key in ("name", "urdf", "base", "tip"):
        if key not in model:
            raise chk.fail(("model", key), f"missing required key: {key} = \"...\" (a string)",
                           line_path=("model",))
        if not isinstance(model[key], str) or not model[key]:
            raise chk.fail(("model", key), f"expected a non-empty string, {_got(model[key])}")
    _check_name(chk, model["name"], builtin)
    _check_description(chk, model.get("description"))
    urdf = (base_dir / model["urdf"]).resolve()
    if not urdf.is_file():
        raise chk.fail(("model", "urdf"), f"URDF file {model['urdf']!r} not found (looked for {urdf}); "
                                          "expected a path relative to the model file")
    try:
        chain = load_urdf(urdf, model["base"], model["tip"], source=str(urdf))
    except UrdfError as exc:
        raise chk.fail(("model", "urdf"), f"cannot use the URDF: {exc}") from None
    names = chain.joints

    symbolic = model.get("symbolic", [])
    if not isinstance(symbolic, list) or not all(isinstance(v, str) for v in symbolic):
        raise chk.fail(("model", "symbolic"), f"expected an array of link names, {_got(symbolic)}")
    for link in symbolic:
        if not re.fullmatch(r"[A-Za-z0-9_]+", link) or symbolic.count(link) > 1:
            raise chk.fail(("model", "symbolic"), f"{_show(link)}: expected distinct link names of letters, "
                                                  "digits and _ (they become parameter names m_<link>, ...)")
    try:
        from .spatial import chain_numerics
        chain_numerics(chain.description, tuple(symbolic))
    except ValueError as exc:
        raise chk.fail(("model", "symbolic"), str(exc)) from None

    joints = data.get("joints", {})
    if not isinstance(joints, dict):
        raise chk.fail(("joints",), f"expected tables [joints.default] and [joints.<URDF joint name>], {_got(joints)}")
    values: Dict[str, Dict[str, float]] = {}
    for jname, entry in joints.items():
        path: KeyPath = ("joints", jname)
        if jname != "default" and jname not in names:
            raise chk.fail(path, f"no revolute joint {jname!r} on the chain {model['base']} -> {model['tip']}; "
                                 f"expected 'default' or one of {', '.join(names)}" + _suggest(jname, names))
        if not isinstance(entry, dict):
            raise chk.fail(path, f"expected a table with K, Jm, Bm, {_got(entry)}")
        values[jname] = {}
        for key, val in entry.items():
            if key not in _ELASTIC:
                raise chk.fail(path + (key,), f"unknown key; a joint table allows {', '.join(_ELASTIC)}"
                                              + _suggest(key, _ELASTIC))
            unit, kind, meaning, _ = _ELASTIC[key]
            values[jname][key] = _number(chk, path + (key,), val, unit, kind, meaning)
    per: Dict[str, List[float]] = {k: [] for k in _ELASTIC}
    for jname in names:
        for key, (unit, _, meaning, default) in _ELASTIC.items():
            v = values.get(jname, {}).get(key, values.get("default", {}).get(key, default))
            if v is None:
                raise chk.fail(("joints", jname, key),
                               f"missing {meaning} of joint {jname!r}: expected {key} = <number in {unit}> in "
                               f"[joints.{jname}] or [joints.default]", line_path=("joints",))
            per[key].append(v)

    params = data.get("parameters", {})
    if not isinstance(params, dict):
        raise chk.fail(("parameters",), f"expected a table, {_got(params)}")
    for key in params:
        if key != "g0":
            raise chk.fail(("parameters", key), "unknown parameter; the URDF form takes g0 only here "
                                                "(elastic parameters go in [joints.*], inertials in the URDF)")
    g0 = _number(chk, ("parameters", "g0"), params.get("g0", DEFAULT_G0), "m/s^2", ">=0",
                 "gravitational acceleration")

    notes = data.get("notes", {})
    if not isinstance(notes, dict):
        raise chk.fail(("notes",), f"expected a table of strings keyed K, Jm, Bm, {_got(notes)}")
    for key, val in notes.items():
        if key not in _ELASTIC:
            raise chk.fail(("notes", key), f"unknown key; [notes] allows {', '.join(_ELASTIC)}")
        _check_description(chk, val, ("notes", key))
    payload = None
    if "payload" in data:
        table = data["payload"]
        if not isinstance(table, dict):
            raise chk.fail(("payload",), f"expected a table with mass and com, {_got(table)}")
        for key in table:
            if key not in ("mass", "com"):
                raise chk.fail(("payload", key), "unknown key; [payload] allows mass, com")
        for key in ("mass", "com"):
            if key not in table:
                raise chk.fail(("payload", key), f"missing required key: {key}", line_path=("payload",))
        mass = _number(chk, ("payload", "mass"), table["mass"], "kg", ">=0", "payload mass")
        com = table["com"]
        if not isinstance(com, list) or len(com) != 3:
            raise chk.fail(("payload", "com"), f"expected an array of 3 numbers (m, in the tip link frame), "
                                               f"{_got(com)}")
        com = tuple(_number(chk, ("payload", "com"), v, "m", "any", "payload position") for v in com)
        payload = (mass, com)
    return UrdfModelSpec(name=model["name"], urdf=urdf, base=model["base"], tip=model["tip"], joints=names,
                         K=tuple(per["K"]), Jm=tuple(per["Jm"]), Bm=tuple(per["Bm"]), g0=g0,
                         description=model.get("description"), notes=dict(notes), source=chk.source,
                         payload=payload, symbolic=tuple(symbolic))
