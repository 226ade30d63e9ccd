"""Where each key of a TOML document is: :func:`locate_keys` (TOML parsers do not report it).

A small scanner over the raw text of a syntactically valid document: table
headers, arrays of tables, dotted and quoted keys, inline tables, and the
content of strings (including multi-line ones), arrays and comments, which
it skips. Used for the ``<file>:<line>: <key>:`` of every model-file error.
"""

from __future__ import annotations

import bisect
import re
from typing import Dict, List, Optional, Tuple

__all__ = ["KeyPath", "BARE_KEY", "locate_keys"]

KeyPath = Tuple[str, ...]

#: A bare TOML key.
BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")
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
                m = BARE_KEY.match(self.s, self.i)
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
