"""The drive tables of a model file: spring laws (``[spring]``) and motor friction (``[friction]``).

A one-link planar file has one of each::

    [spring]                  # optional; without it the spring is linear, K1 of [parameters]
    law = "three_segment"     # "linear" (K1), "cubic" (k1, k3) or "three_segment"
    range = 0.01              # declared deflection range |q_m - q| <= range, rad (psi' > 0 is checked on it)
    K_1 = 1.3e4               # three_segment: segment stiffnesses, N m/rad (K_1 <= K_2 <= K_3)
    K_2 = 1.7e4
    K_3 = 2.0e4
    T_1 = 14.0                # torque breakpoints, N m (0 < T_1 < T_2)
    T_2 = 48.0
    w_blend = 2e-4            # blend width around each breakpoint, rad
    # cubic: k1 (N m/rad, > 0), k3 (N m/rad^3)

    [friction]                # optional: Coulomb and Stribeck motor friction (link side)
    F_c = 0.5                 # Coulomb level, N m (>= 0)
    F_s = 0.8                 # static level, N m (>= 0; default F_c: no Stribeck hump)
    v_s = 0.1                 # Stribeck velocity, rad/s (> 0; default 0.1)
    v_c = 0.01                # regularization velocity of tanh(v / v_c), rad/s (> 0; default 0.01)

A URDF file has them per joint, as its ``[joints.*]``: ``[spring.default]`` and ``[spring.<URDF joint>]``
(keys of the joint's table over the default's), the same for ``[friction.*]``
(:func:`parse_joint_drive_tables`); a planar file of several links the same with joint numbers
(``[spring.default]``, ``[spring.2]``). The coefficients become runtime parameters of the same names, suffixed
by the joint number when the model has several joints (``K_1_3``, ``F_c_3``; defaults from the file). The
law's own check (``psi' > 0`` on the range, breakpoints in order) is reported at the ``law`` line.
"""

from __future__ import annotations

import math
from typing import Dict, List, Optional, Sequence, Tuple

from ..core.domains import FRICTION_DOMAINS, SPRING_DOMAINS
from ..core.friction import FRICTION_PARAMETERS
from ..core.spring_laws import LAW_COEFFICIENTS, SPRING_KINDS, SPRING_PARAMETERS, SpringError
from .schema import Checker, got, number, optional_table, show, suggest

__all__ = ["DRIVE_TABLES", "SpringSpec", "parse_spring_table", "parse_friction_table", "parse_joint_drive_tables",
           "SPRING_COEFFICIENTS", "FRICTION_COEFFICIENTS"]

DRIVE_TABLES = ("spring", "friction")
#: Largest declared deflection range of a spring, rad (the linear law's default).
MAX_DEFLECTION = math.pi

#: The bound each coefficient must meet in a file (``number``'s kinds; ``"any"``: none).
_BOUNDS = {**SPRING_DOMAINS, **FRICTION_DOMAINS}

#: Coefficients of each law: key -> (unit, bound, meaning). ``linear`` takes K1 from [parameters].
SPRING_COEFFICIENTS: Dict[str, Dict[str, Tuple[str, str, str]]] = {
    law: {c: (SPRING_PARAMETERS[c][1], _BOUNDS[c], SPRING_PARAMETERS[c][0]) for c in names}
    for law, names in LAW_COEFFICIENTS.items()}

#: ``[friction]``: key -> (unit, bound, meaning, default or None when required; F_s defaults to F_c).
FRICTION_COEFFICIENTS: Dict[str, Tuple[str, str, str, Optional[float]]] = {
    name: (unit, _BOUNDS[name], meaning, default)
    for (name, meaning, unit), default in zip(FRICTION_PARAMETERS, (None, None, 0.1, 0.01))}


class SpringSpec:
    """A validated ``[spring]`` table: ``kind``, ``coefficients`` (name -> float), ``deflection_range`` (rad)."""

    def __init__(self, kind: str, coefficients: Dict[str, float], deflection_range: float):
        self.kind, self.coefficients, self.deflection_range = kind, dict(coefficients), float(deflection_range)

    def __eq__(self, other) -> bool:
        return isinstance(other, SpringSpec) and vars(self) == vars(other)

    def __repr__(self) -> str:
        return f"SpringSpec({self.kind!r}, {self.coefficients!r}, {self.deflection_range!r})"


def _table(data: dict, chk: Checker, name: str, links: int) -> Optional[dict]:
    table = optional_table(data, chk, name)
    if table is not None and links != 1:
        raise chk.fail((name,), f"a flat [{name}] table is for one link; this file has links = {links}: give "
                                f"[{name}.default] and [{name}.<joint number>] tables (per joint, 1..{links})")
    return table


def parse_spring_table(data: dict, chk: Checker, links: int) -> Optional[SpringSpec]:
    """``[spring]`` of a parsed one-link file, checked (unknown key, missing coefficient, unit bound)."""
    table = _table(data, chk, "spring", links)
    return None if table is None else _spring_spec(table, chk, lambda key: ("spring", key), ("spring",))


def _spring_spec(table: dict, chk: Checker, where, line_path) -> SpringSpec:
    """One spring table (``where(key)``: the key path of ``key`` in the file, for errors)."""
    law = table.get("law")
    if "law" not in table:
        raise chk.fail(where("law"), f"missing required key: law = one of {', '.join(map(repr, SPRING_KINDS))}",
                       line_path=line_path)
    if law not in SPRING_KINDS:
        raise chk.fail(where("law"), f"{show(law)}: expected one of {', '.join(map(repr, SPRING_KINDS))}"
                                     + (suggest(law, SPRING_KINDS) if isinstance(law, str) else ""))
    coefficients = SPRING_COEFFICIENTS[law]
    allowed = ("law", "range") + tuple(coefficients)
    for key in table:
        if key not in allowed:
            extra = " (the linear law's stiffness is K1 under [parameters])" if law == "linear" else ""
            raise chk.fail(where(key), f"unknown key for law = {show(law)}; expected {', '.join(allowed)}{extra}"
                                       + suggest(key, allowed))
    if "range" not in table and law != "linear":
        raise chk.fail(where("range"), "missing required key: the declared deflection range in rad "
                                       "(|q_m - q| <= range; psi' > 0 is checked on it)", line_path=line_path)
    rng = number(chk, where("range"), table.get("range", math.pi), "rad", ">0", "the deflection range",
                 top=(MAX_DEFLECTION, "pi: a spring deflected half a turn is broken; a harmonic drive deflects "
                                      "~0.01 rad"))
    values = {}
    for key, (unit, bound, meaning) in coefficients.items():
        if key not in table:
            raise chk.fail(where(key), f"missing required key: {meaning} in {unit}", line_path=line_path)
        values[key] = number(chk, where(key), table[key], unit, bound, meaning)
    return SpringSpec(law, values, rng)


def parse_friction_table(data: dict, chk: Checker, links: int) -> Optional[Dict[str, float]]:
    """``[friction]`` of a parsed one-link file: ``{F_c, F_s, v_s, v_c}`` (``F_s`` defaults to ``F_c``)."""
    table = _table(data, chk, "friction", links)
    return None if table is None else _friction(table, chk, lambda key: ("friction", key), ("friction",))


def _friction(table: dict, chk: Checker, where, line_path) -> Dict[str, float]:
    """One friction table (``where(key)``: the key path of ``key`` in the file, for errors)."""
    for key in table:
        if key not in FRICTION_COEFFICIENTS:
            raise chk.fail(where(key), f"unknown key; a friction table allows {', '.join(FRICTION_COEFFICIENTS)}"
                                       + suggest(key, FRICTION_COEFFICIENTS))
    if "F_c" not in table:
        raise chk.fail(where("F_c"), "missing required key: the Coulomb level F_c in N m", line_path=line_path)
    out = {}
    for key, (unit, bound, meaning, default) in FRICTION_COEFFICIENTS.items():
        default = out["F_c"] if key == "F_s" else default
        out[key] = number(chk, where(key), table.get(key, default), unit, bound, meaning)
    if out["F_s"] < out["F_c"]:
        raise chk.fail(where("F_s"), f"{show(out['F_s'])} N m is below F_c = {show(out['F_c'])} N m: expected "
                                     "F_s >= F_c (static friction at least the Coulomb level; F_s = F_c: no "
                                     "Stribeck hump)")
    return out


def parse_joint_drive_tables(data: dict, chk: Checker, joints: Sequence[str]
                             ) -> Tuple[Optional[List[SpringSpec]], Optional[List[Optional[Dict[str, float]]]]]:
    """``[spring.*]`` and ``[friction.*]`` of a URDF or several-link model file: per joint in q order.

    ``joints``: the URDF joint names, or ``"1" .. "n"`` for a planar chain. ``[spring.default]`` applies to
    every joint, ``[spring.<joint>]`` overrides its keys for one
    (a joint table with its own ``law`` replaces the default table). Without any spring table the springs
    are the linear ``K`` of ``[joints.*]``; with friction tables only, a joint without one (and no default)
    has no friction. Returns ``(springs, frictions)``, each None when the file has no such table.
    """
    out = []
    for name, parse in (("spring", _spring_spec), ("friction", _friction)):
        tables = data.get(name)
        if tables is None:
            out.append(None)
            continue
        if not isinstance(tables, dict) or not all(isinstance(t, dict) for t in tables.values()):
            raise chk.fail((name,), f"expected tables [{name}.default] and [{name}.<joint>] (joints: "
                                    f"{', '.join(joints)}), {got(tables)}")
        for jname in tables:
            if jname != "default" and jname not in joints:
                raise chk.fail((name, jname), f"no revolute joint {jname!r} on the chain; expected 'default' or one "
                                              f"of {', '.join(joints)}" + suggest(jname, joints))
        default = tables.get("default", {})
        per = []
        for jname in joints:
            own = tables.get(jname)
            if own is None and "default" not in tables:
                per.append(None)
                continue
            own = own or {}
            merged = dict(own) if ("law" in own and own.get("law") != default.get("law")) else {**default, **own}

            def where(key, own=own, jname=jname, name=name):
                return (name, jname if key in own else "default", key)
            per.append(parse(merged, chk, where, (name, jname if jname in tables else "default")))
        for j, (jname, spec) in enumerate(zip(joints, per), 1):
            if spec is not None:
                _check_law(chk, name, j, jname, jname if jname in tables else "default", spec)
        if name == "spring" and any(s is None for s in per):
            missing = [j for j, s in zip(joints, per) if s is None]
            raise chk.fail((name,), f"no spring law for joint(s) {', '.join(missing)}: expected a [spring.default] "
                                    "table or one per joint")
        out.append(per)
    return out[0], out[1]


def _check_law(chk: Checker, table: str, joint: int, jname: str, where: str, spec) -> None:
    """The law's own check on one joint's values (``psi' > 0`` on the range, breakpoints in order; friction
    levels), as an error at the table's ``law`` (spring) or at the table (friction)."""
    from ..core.friction import FrictionError, MotorFriction, check_friction
    import sympy as sp
    try:
        if table == "spring":
            names = LAW_COEFFICIENTS[spec.kind] or ("K",)
            values = dict(spec.coefficients) if spec.kind != "linear" else {"K": 1.0}
            law = SPRING_KINDS[spec.kind](joint, *(sp.Symbol(c) for c in names), spec.deflection_range)
            law.check(jname, values)
        else:
            check_friction(jname, MotorFriction(joint, *(sp.Symbol(c) for c, _, _ in FRICTION_PARAMETERS)), spec)
    except (SpringError, FrictionError) as err:
        raise chk.fail((table, where, "law") if table == "spring" else (table, where),
                       f"joint {jname}: " + str(err).split(": ", 1)[-1], line_path=(table, where)) from None


def spring_error(chk: Checker, err: SpringError):
    """A law's own check (:mod:`derive.core.spring_laws`) as a model-file error at the ``law`` line."""
    return chk.fail(("spring", "law"), str(err).split(": ", 1)[-1])
