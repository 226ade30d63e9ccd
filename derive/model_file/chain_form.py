"""The planar-chain form of a model file: ``[model] name, links`` and ``[parameters]``.

The chain is :func:`derive.planar.planar.make_planar` with the file's name,
description and parameter defaults (see :mod:`derive.model_file` for the
format). Every value is checked: type, finite, physical sign, fjm's SI unit,
and ``r_i <= l_i`` (the centre of mass lies on the link).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from typing import Dict, Optional, Tuple

from ..core.model_base import PLANAR_GROUPS, FlexibleJointModel, param_group, planar_param_names
from ..planar.planar import make_planar
from .drive_tables import (DRIVE_TABLES, SpringSpec, parse_friction_table, parse_joint_drive_tables, parse_spring_table,
                           spring_error)
from .robot_facts import FACT_TABLES, robot_facts
from .schema import Checker, ModelFileError, check_description, check_name, got, number, show, suggest
from .toml_keys import KeyPath

__all__ = ["ModelSpec", "parse_chain_form", "SI_UNITS", "MAX_LINKS", "GROUPS"]

MAX_LINKS = 7

#: Parameter groups of a planar chain: prefix -> (SI unit, lower bound kind, meaning).
#: ``">0"``: strictly positive; ``">=0"``: non-negative.
GROUPS: Dict[str, Tuple[str, str, str]] = {
    "m": ("kg", ">0", "link mass"),
    "l": ("m", ">0", "link length"),
    "r": ("m", ">0", "joint -> centre of mass distance"),
    "I": ("kg m^2", ">0", "link inertia about its centre of mass"),
    "K": ("N m/rad", ">0", "joint stiffness"),
    "Jm": ("kg m^2", ">0", "motor inertia"),
    "Bm": ("N m s/rad", ">=0", "motor viscous damping"),
}
assert tuple(GROUPS) == PLANAR_GROUPS
GRAVITY = ("m/s^2", ">=0", "gravitational acceleration")

#: SI unit of every parameter prefix (and ``g0``), as written in manifests.
SI_UNITS: Dict[str, str] = {**{g: u for g, (u, _, _) in GROUPS.items()}, "g0": GRAVITY[0]}

MODEL_KEYS = ("name", "links", "description")
PARAM_TABLE_KEYS = ("default", "unit")


@dataclass(frozen=True)
class ModelSpec:
    """A validated model file: everything :func:`derive.planar.planar.make_planar` needs."""

    name: str
    links: int
    description: Optional[str]
    defaults: Dict[str, float] = field(default_factory=dict)
    units: Dict[str, str] = field(default_factory=dict)  # parameter name -> SI unit (all params)
    source: str = "<model file>"
    spring: Optional[SpringSpec] = None  # [spring] (one link; derive.model_file.drive_tables)
    friction: Optional[Dict[str, float]] = None  # [friction]: F_c, F_s, v_s, v_c
    springs: Optional[Tuple[SpringSpec, ...]] = None  # [spring.*] per joint (several links)
    frictions: Optional[Tuple[Optional[Dict[str, float]], ...]] = None  # [friction.*] per joint (several links)
    facts: Optional[Dict[str, object]] = None  # manifest "limits" and "task" (derive.model_file.robot_facts)

    def drives(self):
        """``(springs, frictions)`` per joint (each None without such tables), one link or several."""
        if self.links == 1:
            return (None if self.spring is None else (self.spring,),
                    None if self.friction is None else (self.friction,))
        return self.springs, self.frictions

    def build(self) -> FlexibleJointModel:
        """The symbolic model (a planar chain with this name, defaults and description; its drives when
        the file has spring or friction tables: :func:`derive.core.spring.with_drives`)."""
        chain = make_planar(self.links, name=self.name, defaults=dict(self.defaults),
                            description=self.description)
        springs, frictions = self.drives()
        if springs is not None or frictions is not None:
            from ..core.spring import with_drives
            springs = springs or (SpringSpec("linear", {}, 3.141592653589793),) * self.links
            chain = with_drives(chain, [(s.kind, s.coefficients, s.deflection_range) for s in springs],
                                None if frictions is None else list(frictions),
                                description=self.description or _drive_description(self.links, springs, frictions))
        return replace(chain, robot_facts=self.facts or None)


def _drive_description(links: int, springs, frictions) -> str:
    names = {"linear": "linear spring K", "cubic": "cubic spring k1 phi + k3 phi^3",
             "three_segment": "three-segment (datasheet) spring"}
    kinds = sorted({s.kind for s in springs}, key=list(names).index)
    law = " / ".join(names[k] for k in kinds) + ("s" if links > 1 else "")
    return (f"{links}-link planar chain from a model file with {'a ' if links == 1 else ''}{law}"
            + (" and Coulomb/Stribeck motor friction" if frictions is not None else "") + ".")


def _normalize_unit(unit: str) -> str:
    u = unit.strip().replace("²", "^2").replace("**", "^")
    u = re.sub(r"[\s*·.]+", "", u)
    u = u.replace("^2", "2").replace("^-2", "-2").replace("^-1", "-1")
    aliases = {"ms-2": "m/s2", "Nmrad-1": "Nm/rad", "Nmsrad-1": "Nms/rad"}
    return aliases.get(u, u)


def _describe_names(n: int) -> str:
    if n == 1:
        return ", ".join(planar_param_names(1))
    return ", ".join(f"{g}1..{g}{n}" for g in GROUPS) + ", g0"


def _model_table(data: dict, chk: Checker, builtin: bool) -> Tuple[str, int, Optional[str]]:
    """The top level and ``[model]``: name, number of links, description."""
    for key in data:
        if key not in ("model", "parameters") + DRIVE_TABLES + FACT_TABLES:
            hint = (f" (did you mean `{key} = ...` under [model]?)" if key in MODEL_KEYS
                    else " (parameters go under [parameters])" if param_group(key) in SI_UNITS
                    else suggest(key, ("model", "parameters") + DRIVE_TABLES + FACT_TABLES))
            raise chk.fail((key,), f"unknown key; a model file has the tables [model], [parameters], [spring], "
                                   f"[friction], [limits] and [task] only{hint}")
    if "model" not in data:
        raise ModelFileError("missing required table [model] (with name = \"...\" and links = 1..7)",
                             chk.source, 1, "model")
    model = data["model"]
    if not isinstance(model, dict):
        raise chk.fail(("model",), f"expected a table ([model] with name and links), "
                                   f"{got(model)}")
    for key in model:
        if key not in MODEL_KEYS:
            raise chk.fail(("model", key), f"unknown key; [model] allows {', '.join(MODEL_KEYS)}"
                                           + suggest(key, MODEL_KEYS))
    for key in ("name", "links"):
        if key not in model:
            what = ('the model name, e.g. name = "arm3"' if key == "name"
                    else f"the number of links, e.g. links = 3 (1..{MAX_LINKS})")
            raise chk.fail(("model", key), f"missing required key: {what}", line_path=("model",))

    name = model["name"]
    check_name(chk, name, builtin)

    links = model["links"]
    if isinstance(links, bool) or not isinstance(links, int):
        raise chk.fail(("model", "links"), f"expected an integer 1..{MAX_LINKS}, "
                                           f"{got(links)}")
    if not 1 <= links <= MAX_LINKS:
        raise chk.fail(("model", "links"), f"{links} is out of range: expected 1..{MAX_LINKS}")

    description = model.get("description")
    check_description(chk, description)
    return name, links, description


def _parameter_value(chk: Checker, key: str, entry, path: KeyPath) -> Tuple[KeyPath, float]:
    """One ``[parameters]`` entry (a number, or a table with default and unit): its value path and value."""
    si = SI_UNITS[param_group(key)]
    if isinstance(entry, dict):
        for k in entry:
            if k not in PARAM_TABLE_KEYS:
                raise chk.fail(path + (k,), f"unknown key; a parameter table allows "
                                            f"{', '.join(PARAM_TABLE_KEYS)}" + suggest(k, PARAM_TABLE_KEYS))
        if "default" not in entry:
            raise chk.fail(path + ("default",), f"missing required key: the default value in {si}",
                           line_path=path)
        vpath = path + ("default",)
        value = entry["default"]
        if "unit" in entry:
            unit = entry["unit"]
            if not isinstance(unit, str):
                raise chk.fail(path + ("unit",), f"expected a string (e.g. {si!r}), "
                                                 f"{got(unit)}")
            if _normalize_unit(unit) != _normalize_unit(si):
                raise chk.fail(path + ("unit",),
                               f"unit {show(unit)} is not fjm's unit for {key}: fjm uses SI units, "
                               f"{key} must be given in {si!r}; convert the value")
    else:
        vpath, value = path, entry
    kind, meaning = ((GROUPS[param_group(key)][1], GROUPS[param_group(key)][2]) if key != "g0"
                     else (GRAVITY[1], GRAVITY[2]))
    return vpath, number(chk, vpath, value, si, kind, meaning)


def _parameter_defaults(data: dict, chk: Checker, links: int) -> Tuple[Dict[str, float], Dict[str, KeyPath]]:
    """``[parameters]``: the defaults given, and where each value is."""
    params = data.get("parameters", {})
    if not isinstance(params, dict):
        raise chk.fail(("parameters",), f"expected a table ([parameters] with name = value lines), "
                                        f"{got(params)}")
    names = planar_param_names(links)
    defaults: Dict[str, float] = {}
    value_path: Dict[str, KeyPath] = {}
    for key, entry in params.items():
        path: KeyPath = ("parameters", key)
        if key not in names:
            grp = param_group(key)
            if grp in GROUPS and key[len(grp):].isdigit():
                why = f"a {links}-link chain has no parameter {key!r}"
            else:
                why = f"{key!r} is not a parameter of a planar chain" + suggest(key, names)
            raise chk.fail(path, f"unknown parameter: {why}; expected names among "
                                 f"{_describe_names(links)}")
        value_path[key], defaults[key] = _parameter_value(chk, key, entry, path)
    return defaults, value_path


def _check_com_on_links(chk: Checker, links: int, defaults: Dict[str, float],
                        value_path: Dict[str, KeyPath]) -> None:
    """``r_i <= l_i`` on the effective defaults (file values over ``planar<n>`` defaults)."""
    base = {p.name: p.default for p in make_planar(links).params}
    for i in range(1, links + 1):
        r, l = f"r{i}", f"l{i}"
        rv, lv = defaults.get(r, base[r]), defaults.get(l, base[l])
        if rv > lv:
            if r in defaults:
                origin = "" if l in defaults else " (default)"
                raise chk.fail(value_path[r], f"{show(rv)} m > {l} = {show(lv)} m{origin}: the centre of "
                                              f"mass must lie on the link (expected {r} <= {l})")
            raise chk.fail(value_path[l], f"{show(lv)} m < {r} = {show(rv)} m (default): the centre of mass "
                                          f"must lie on the link (expected {l} >= {r}; set {r} too)")


def parse_chain_form(data: dict, chk: Checker, builtin: bool) -> ModelSpec:
    """The planar-chain form of a parsed model file (see :mod:`derive.model_file`).

    Raises
    ------
    ModelFileError
        Unknown table or key, wrong type, value out of range, non-physical
        default, unit that is not fjm's SI unit, missing required key.
    """
    name, links, description = _model_table(data, chk, builtin)
    defaults, value_path = _parameter_defaults(data, chk, links)
    _check_com_on_links(chk, links, defaults, value_path)
    names = planar_param_names(links)
    units = {n_: SI_UNITS[param_group(n_)] for n_ in names}
    spring = friction = springs = frictions = None
    if links == 1:
        spring = parse_spring_table(data, chk, links)
        friction = parse_friction_table(data, chk, links)
    elif any(isinstance(data.get(t), dict) and data[t] and all(isinstance(v, dict) for v in data[t].values())
             for t in DRIVE_TABLES):
        springs, frictions = parse_joint_drive_tables(data, chk, tuple(str(j) for j in range(1, links + 1)))
    else:  # a flat table on several links: one-line error
        parse_spring_table(data, chk, links), parse_friction_table(data, chk, links)
    for j, s in enumerate((spring,) if links == 1 else (springs or ()), 1):
        if s is not None and s.kind != "linear" and f"K{j}" in defaults:
            where = "[spring]" if links == 1 else f"[spring.*] of joint {j}"
            raise chk.fail(value_path[f"K{j}"], f"the {where} law {s.kind!r} replaces the linear stiffness K{j}; "
                                                f"give its coefficients ({', '.join(s.coefficients)}) there")
    spec = ModelSpec(name=name, links=links, description=description,
                     defaults={k: defaults[k] for k in names if k in defaults}, units=units, source=chk.source,
                     spring=spring, friction=friction, springs=None if springs is None else tuple(springs),
                     frictions=None if frictions is None else tuple(frictions),
                     facts=robot_facts(data, chk, tuple(str(j) for j in range(1, links + 1))))
    if links == 1 and (spring is not None or friction is not None):
        from ..core.friction import FrictionError
        from ..core.spring_laws import SpringError
        try:
            spec.build()  # the law's own checks on the file's values (psi' > 0 on the range, order)
        except SpringError as err:
            raise spring_error(chk, err) from None
        except FrictionError as err:
            raise chk.fail(("friction",), str(err).split(": ", 1)[-1]) from None
    return spec
