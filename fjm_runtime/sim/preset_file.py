"""A loop model's TOML file (a sensor or a command interface): a preset as the base, then field overrides.

:func:`read_preset_file` reads the file and its base preset with the one-line errors both file kinds
share (file not found, not TOML, unknown preset); the caller checks and applies its own keys.
:func:`read_toml_file` is its first step, shared with the other TOML files a user gives (``--params``).
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Dict, Mapping, Tuple

from ..validation import FjmValueError

__all__ = ["read_preset_file", "read_toml_file"]


def read_preset_file(path, what: str, presets: Mapping[str, Callable], default: str,
                     make=lambda build: build()) -> Tuple[Path, Dict, Dict]:
    """``(p, base, data)``: the file's path, its preset's fields and the file's other keys.

    Parameters
    ----------
    path : str or Path
        The TOML file.
    what : str
        How errors name the file kind (``"sensor file"``, ``"interface file"``).
    presets : mapping name -> constructor
        The presets a file may start from (``preset = NAME``).
    default : str
        The preset of a file that names none.
    make : callable
        ``make(constructor) -> model`` (e.g. to pass a seed); the model has ``as_dict()``.

    Returns
    -------
    p : Path
    base : dict
        The preset's fields (``as_dict()``) with ``name`` set to the file's stem.
    data : dict
        The file's keys other than ``preset``.

    Raises
    ------
    FjmValueError
        One line naming the file: not found, not valid TOML, or an unknown preset.
    """
    p, _, data = read_toml_file(path, lambda p: f"{what} {p}: not found (expected a preset name among "
                                                f"{sorted(presets)} or a TOML file)", f"{what} ")
    base_name = data.pop("preset", default)
    if not isinstance(base_name, str) or base_name not in presets:
        raise FjmValueError(f"{what} {p}: preset = {base_name!r}; expected one of {sorted(presets)}")
    base = make(presets[base_name]).as_dict()
    base["name"] = p.stem
    return p, base, data


def read_toml_file(path, missing: Callable[[Path], str], label: str = "") -> Tuple[Path, str, Dict]:
    """``(p, text, data)``: a TOML file's path, text and table, with one-line errors.

    Parameters
    ----------
    path : str or Path
    missing : callable
        ``missing(p)``: the message when ``p`` is no file.
    label : str
        Put before the path in the message of a file that is not TOML (e.g. ``"sensor file "``).

    Raises
    ------
    FjmValueError
        ``missing(p)``, or ``{label}{p}: not valid TOML (...)``.
    """
    try:
        import tomllib
    except ImportError:  # Python < 3.11
        import tomli as tomllib
    p = Path(path)
    if not p.is_file():
        raise FjmValueError(missing(p))
    try:
        text = p.read_text()
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise FjmValueError(f"{label}{p}: not valid TOML ({exc})") from None
    return p, text, data
