"""The plant of a design: the controller's NOMINAL parameters and the spread of the TRUE plant draws.

A :class:`PlantSpread` holds both. Without a parameter file it is today's box: every joint
stiffness ``K x U[0.7, 1.3]`` (a nonlinear spring: its whole curve, drawn by its small-deflection
stiffness ``K_1`` or ``k1``, the other torque coefficients following), every motor inertia ``J_m x U[0.8, 1.2]``, a payload
``m_load ~ U[0, 1]`` kg on models that have one, the rest at the model's defaults. A parameter
file (``fjm design --params FILE``, :func:`load_params_file`; format in docs/design-command.md)
sets nominal values in the model-file form and the spread::

    [parameters]              # the controller's nominal values (bare number: SI unit)
    Jm1 = 0.195
    Jm5 = { default = 0.074, unit = "kg m^2" }

    [spread]                  # the TRUE plant draws around the nominal
    stiffness = 0.3           # every K: nominal x U[1 - 0.3, 1 + 0.3]
    motor_inertia = 0.2       # every J_m
    K7 = 0.4                  # one parameter by name (relative half-width)
    m_load = [0.0, 2.0]       # an absolute range [lo, hi], SI unit

:func:`draw_params` turns a spread into rows: first the corners of the box (stiffness all low,
all high, alternating; then the same three with the other spread parameters at their low and at
their high end), then uniform draws; ``fresh=True`` gives draws of an independent stream (no
corners) for the re-check on plants the search never saw.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Optional, Tuple

import numpy as np

from ...drives import drive_indices, spring_scale_groups
from ...sim.preset_file import read_toml_file
from ...validation import FjmValueError, check_domains, check_magnitudes

__all__ = ["GROUPS", "PlantSpread", "default_spread", "draw_params", "load_params_file"]

#: Group keys of ``[spread]``: every joint stiffness, every motor inertia.
GROUPS = ("stiffness", "motor_inertia")
#: Default relative half-widths of the groups, and the default payload range (kg).
DEFAULT_GROUP_SPREAD = {"stiffness": 0.3, "motor_inertia": 0.2}
DEFAULT_PAYLOAD = (0.0, 1.0)
#: Stream of :func:`draw_params` ``fresh=True`` (a SeedSequence key next to the design's seed).
FRESH_STREAM = 0x5EED


@dataclass(frozen=True)
class PlantSpread:
    """Nominal values and the spread of the TRUE draws.

    Attributes
    ----------
    nominal : dict str -> float
        Every parameter's nominal value (the controller's; the draws' centre).
    relative : dict str -> float
        Relative half-width per parameter: TRUE = nominal x U[1 - s, 1 + s] (0 <= s < 1).
    absolute : dict str -> (float, float)
        Absolute range per parameter: TRUE ~ U[lo, hi] (not also in ``relative``).
    source : str
        ``'default'`` or the parameter file's path.
    overrides : dict str -> float
        The nominal values the file set (the design file records them).
    """

    nominal: Dict[str, float]
    relative: Dict[str, float] = field(default_factory=dict)
    absolute: Dict[str, Tuple[float, float]] = field(default_factory=dict)
    source: str = "default"
    overrides: Dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict:
        """JSON record: source, the overridden nominal values, relative and absolute spreads."""
        return {"source": self.source, "nominal": dict(self.overrides),
                "relative": dict(self.relative), "absolute": {k: list(v) for k, v in self.absolute.items()}}


def default_spread(model, nominal: Optional[Dict[str, float]] = None) -> PlantSpread:
    """Today's box around ``nominal`` (default: the model's defaults)."""
    nom = dict(model.default_params)
    nom.update(nominal or {})
    iK, iJ = drive_indices(model, "stiffness"), drive_indices(model, "rotor_inertia")
    names = list(model.param_names)
    rel = {names[i]: DEFAULT_GROUP_SPREAD["stiffness"] for i in iK}
    rel.update({names[i]: DEFAULT_GROUP_SPREAD["motor_inertia"] for i in iJ})
    absolute = {"m_load": DEFAULT_PAYLOAD} if "m_load" in names else {}
    return PlantSpread(nominal=nom, relative=rel, absolute=absolute)


def _bounds(model, spread: PlantSpread, idx):
    """Per index in ``idx``: ``(lo, hi, is_relative)`` in factor space (relative) or SI (absolute)."""
    if idx is PAYLOAD_SLOT:
        return 0.0, 1.0, True
    names = list(model.param_names)
    lo, hi, rel = [], [], []
    for i in idx:
        name = names[i]
        if name in spread.absolute:
            a, b = spread.absolute[name]
            lo.append(a), hi.append(b), rel.append(False)
        else:
            s = spread.relative.get(name, 0.0)
            lo.append(1.0 - s), hi.append(1.0 + s), rel.append(True)
    return np.array(lo), np.array(hi), np.array(rel, dtype=bool)


def _blocks(model, spread: PlantSpread):
    """Index blocks in draw order: stiffnesses, motor inertias, payload, every other spread parameter."""
    iK, iJ = (list(map(int, drive_indices(model, role))) for role in ("stiffness", "rotor_inertia"))
    names = list(model.param_names)
    iL = [names.index("m_load")] if "m_load" in spread.absolute or "m_load" in spread.relative else []
    taken = set(iK) | set(iJ) | set(iL)
    others = [i for i, nm in enumerate(names) if i not in taken and
              (nm in spread.absolute or spread.relative.get(nm, 0.0) > 0)]
    return [b for b in (iK, iJ, iL or PAYLOAD_SLOT, others) if b]


#: The payload's place in a row's draws when no payload is drawn: one number is drawn and dropped,
#: so the rows of a model without ``m_load`` are those of the former box too.
PAYLOAD_SLOT = ["payload slot"]


def _apply(p, idx, vals, rel) -> None:
    if idx is PAYLOAD_SLOT:
        return
    idx = np.asarray(idx)
    p[idx] = np.where(rel, p[idx] * vals, vals)


def draw_params(model, count: int, seed: int, spread: Optional[PlantSpread] = None,
                fresh: bool = False) -> np.ndarray:
    """TRUE parameter rows; shape (count, n_params).

    Rows ``0..8`` (``fresh=False``) are the corners: the stiffness block at its low end, high end,
    alternating low/high by joint, with every other relative spread at its nominal and every
    absolute range (the payload) at its low end; then the same three stiffness corners with the
    relative spreads at their low end and then at their high end, the absolute ranges at their
    high end. Then uniform draws, one generator call per block (stiffnesses, motor
    inertias, payload (one number drawn and dropped when the payload has no spread or the model none),
    others) per row. With the default spread the rows are those of the former hard-coded box bit for bit.

    Parameters
    ----------
    model : fjm_runtime.Model
    count : int
    seed : int
    spread : PlantSpread, optional
        Default :func:`default_spread`.
    fresh : bool
        Draws of an independent stream (``SeedSequence([seed, FRESH_STREAM])``), no corners: plants
        that no search on ``seed`` evaluated.
    """
    spread = default_spread(model) if spread is None else spread
    n = int(model.n)
    p0 = np.asarray(model.params_array(spread.nominal), dtype=float)
    blocks = _blocks(model, spread)
    bounds = [_bounds(model, spread, b) for b in blocks]
    iK = list(map(int, drive_indices(model, "stiffness")))
    groups = spring_scale_groups(model)
    kb = _bounds(model, spread, iK)
    alt = np.where(np.arange(n) % 2 == 0, kb[0], kb[1])
    k_corners = (kb[0], kb[1], alt)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), FRESH_STREAM]) if fresh else int(seed))
    n_corners = 0 if fresh else 9
    rows = []
    for r in range(int(count)):
        p = p0.copy()
        if r < n_corners:
            end = r // 3           # relative: 0 nominal, 1 low, 2 high end; absolute: 0 low, 1 and 2 high end
            for b, (lo, hi, rel) in zip(blocks, bounds):
                if b == iK:
                    continue
                vals = np.where(rel, 1.0, lo) if end == 0 else np.where(rel, lo, hi) if end == 1 else hi
                _apply(p, b, vals, rel)
            _apply(p, iK, k_corners[r % 3], kb[2])
        else:
            for b, (lo, hi, rel) in zip(blocks, bounds):
                _apply(p, b, rng.uniform(lo, hi), rel)
        rows.append(_follow(p, p0, groups))
    return np.vstack(rows)


def _follow(p, p0, groups):
    """``p`` with each nonlinear spring's other torque coefficients scaled as its drawn small-deflection stiffness
    (:func:`~fjm_runtime.drives.spring_scale_groups`): the whole curve x the factor, its shape kept."""
    for grp in groups:
        if len(grp) > 1:
            p[grp[1:]] = p0[grp[1:]] * (p[grp[0]] / p0[grp[0]])
    return p


# -- the parameter file ------------------------------------------------------------------------------

def _key_lines(text: str) -> Dict[Tuple[str, str], int]:
    """Line of each ``(table, key)`` of a simple TOML file (``[t]`` then ``key = ...``, or ``[t.key]``)."""
    out: Dict[Tuple[str, str], int] = {}
    table = ""
    for no, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        m = re.match(r"^\[\s*([A-Za-z0-9_\-]+)(?:\s*\.\s*([A-Za-z0-9_\-\"]+))?\s*\]$", line)
        if m:
            table = m.group(1)
            if m.group(2):
                out.setdefault((table, m.group(2).strip('"')), no)
                table = f"{table}.{m.group(2)}"
            else:
                out.setdefault((table, ""), no)
            continue
        m = re.match(r"^\"?([A-Za-z0-9_\-]+)\"?\s*(?:\.|=)", line)
        if m and "." not in table:
            out.setdefault((table, m.group(1)), no)
    return out


class _Where:
    """``file:line: table.key`` prefixes of the one-line errors."""

    def __init__(self, path: Path, text: str):
        self.path, self.lines = path, _key_lines(text)

    def __call__(self, table: str, key: str = "") -> str:
        line = self.lines.get((table, key)) or self.lines.get((table, ""))
        at = f"{self.path}:{line}" if line else f"{self.path}"
        return f"{at}: {table}.{key}" if key else f"{at}: [{table}]"


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _units(model) -> Dict[str, str]:
    return {p["name"]: p.get("unit", "") for p in model.manifest.get("parameters", [])}


def _nominal_entry(where, model, key, entry, units) -> float:
    if key not in model.param_names:
        raise FjmValueError(f"{where('parameters', key)}: not a parameter of {model.name}; expected one of "
                            f"{', '.join(model.param_names)}")
    if isinstance(entry, dict):
        extra = sorted(set(entry) - {"default", "unit"})
        if extra or "default" not in entry:
            raise FjmValueError(f"{where('parameters', key)}: table with keys {sorted(entry)}; expected "
                                "{ default = NUMBER, unit = \"...\" }")
        unit = entry.get("unit", units.get(key, ""))
        if unit != units.get(key, unit):
            raise FjmValueError(f"{where('parameters', key)}: unit {unit!r}; expected {units[key]!r} "
                                "(SI, the model's unit: values are not converted)")
        entry = entry["default"]
    if not _number(entry):
        raise FjmValueError(f"{where('parameters', key)}: {entry!r}; expected a finite number "
                            "(or { default = NUMBER, unit = \"...\" })")
    return float(entry)


def _spread_entry(where, model, key, v):
    iK, iJ = drive_indices(model, "stiffness"), drive_indices(model, "rotor_inertia")
    names = list(model.param_names)
    if key not in GROUPS and key not in names:
        raise FjmValueError(f"{where('spread', key)}: not a group ({', '.join(GROUPS)}) or a parameter of "
                            f"{model.name}; expected one of them")
    if _number(v):
        if not 0.0 <= v < 1.0:
            raise FjmValueError(f"{where('spread', key)}: {v!r}; expected a relative half-width 0 <= s < 1 "
                                "(TRUE = nominal x U[1 - s, 1 + s]) or a range [lo, hi]")
        return float(v)
    if key not in GROUPS and isinstance(v, list) and len(v) == 2 and all(_number(x) for x in v) and v[0] <= v[1]:
        positive = key in [names[i] for i in list(iK) + list(iJ)]
        if (positive and v[0] <= 0) or v[0] < 0 and key == "m_load":
            raise FjmValueError(f"{where('spread', key)}: range {v!r}; expected lo > 0 for a stiffness or an "
                                "inertia, lo >= 0 for a payload mass")
        check_magnitudes([key, key], v, f"{where('spread', key)}: range ")       # within the parameter's
        check_domains(model.parameter_info, [key, key], v, f"{where('spread', key)}: range")  # domain, physical
        return (float(v[0]), float(v[1]))
    want = "a relative half-width 0 <= s < 1" + ("" if key in GROUPS else " or a range [lo, hi] with lo <= hi")
    raise FjmValueError(f"{where('spread', key)}: {v!r}; expected {want}")


def load_params_file(path, model) -> PlantSpread:
    """A :class:`PlantSpread` from a parameter file (module docstring; docs/design-command.md).

    Raises
    ------
    FjmValueError
        One line ``FILE:LINE: table.key: problem; expected ...`` (or ``FILE: ...`` without a line).
    """
    p, text, data = read_toml_file(path, lambda p: f"--params {p}: not found; expected a TOML parameter file "
                                                   "(docs/design-command.md)")
    where = _Where(p, text)
    extra = sorted(set(data) - {"parameters", "spread"})
    if extra:
        raise FjmValueError(f"{where(extra[0])}: unknown table; expected [parameters] and/or [spread]")
    for table in ("parameters", "spread"):
        if not isinstance(data.get(table, {}), dict):
            raise FjmValueError(f"{p}: {table} = {data[table]!r}; expected a table [{table}]")
    units = _units(model)
    overrides = {k: _nominal_entry(where, model, k, v, units) for k, v in data.get("parameters", {}).items()}
    iK, iJ = drive_indices(model, "stiffness"), drive_indices(model, "rotor_inertia")
    names = list(model.param_names)
    for i in list(iK) + list(iJ):
        if names[i] in overrides and overrides[names[i]] <= 0:
            raise FjmValueError(f"{where('parameters', names[i])}: {overrides[names[i]]!r}; expected a value > 0")
    try:
        model.params_array({**model.default_params, **overrides})
    except FjmValueError as exc:
        raise FjmValueError(f"{where('parameters')}: {exc}") from None
    spread = default_spread(model, overrides)
    rel, absolute = dict(spread.relative), dict(spread.absolute)
    entries = data.get("spread", {})
    groups = {"stiffness": [names[i] for i in iK], "motor_inertia": [names[i] for i in iJ]}
    for key in GROUPS:                      # groups first: a parameter by name overrides its group
        if key in entries:
            s = _spread_entry(where, model, key, entries[key])
            for nm in groups[key]:
                rel[nm] = s
                absolute.pop(nm, None)
    for key, v in entries.items():
        if key in GROUPS:
            continue
        s = _spread_entry(where, model, key, v)
        if isinstance(s, tuple):
            absolute[key] = s
            rel.pop(key, None)
        else:
            rel[key] = s
            absolute.pop(key, None)
    return PlantSpread(nominal=spread.nominal, relative=rel, absolute=absolute, source=str(p), overrides=overrides)
