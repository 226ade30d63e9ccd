"""The drive tables of a one-link model file: ``[spring]`` (the joint's spring law) and ``[friction]``.

::

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

The coefficients become runtime parameters of the same names (defaults from the file). Such a model
is derived by :func:`derive.core.spring.linearize_spring` (one joint only, for now). The law's own
check (``psi' > 0`` on the range, breakpoints in order) is reported at the ``law`` line.
"""

from __future__ import annotations

from typing import Dict, Optional, Tuple

from ..core.friction import FRICTION_PARAMETERS
from ..core.spring_laws import LAW_COEFFICIENTS, SPRING_KINDS, SPRING_PARAMETERS, SpringError
from .schema import Checker, got, number, show, suggest

__all__ = ["DRIVE_TABLES", "SpringSpec", "parse_spring_table", "parse_friction_table", "SPRING_COEFFICIENTS",
           "FRICTION_COEFFICIENTS"]

DRIVE_TABLES = ("spring", "friction")

#: The bound each coefficient must meet in a file (``number``'s kinds; ``"any"``: none).
_BOUNDS = {"k1": ">0", "k3": "any", "K_1": ">0", "K_2": ">0", "K_3": ">0", "T_1": ">0", "T_2": ">0", "w_blend": ">0",
           "F_c": ">=0", "F_s": ">=0", "v_s": ">0", "v_c": ">0"}

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
    if name not in data:
        return None
    table = data[name]
    if not isinstance(table, dict):
        raise chk.fail((name,), f"expected a table ([{name}] with key = value lines), {got(table)}")
    if links != 1:
        raise chk.fail((name,), f"a [{name}] table needs a one-link chain (links = 1): nonlinear springs and "
                                f"motor friction are derived for one joint for now; this file has links = {links}")
    return table


def parse_spring_table(data: dict, chk: Checker, links: int) -> Optional[SpringSpec]:
    """``[spring]`` of a parsed file, checked (unknown key, missing coefficient, unit bound, psi' > 0)."""
    table = _table(data, chk, "spring", links)
    if table is None:
        return None
    law = table.get("law")
    if "law" not in table:
        raise chk.fail(("spring", "law"), f"missing required key: law = one of {', '.join(map(repr, SPRING_KINDS))}",
                       line_path=("spring",))
    if law not in SPRING_KINDS:
        raise chk.fail(("spring", "law"), f"{show(law)}: expected one of {', '.join(map(repr, SPRING_KINDS))}"
                                          + (suggest(law, SPRING_KINDS) if isinstance(law, str) else ""))
    coefficients = SPRING_COEFFICIENTS[law]
    allowed = ("law", "range") + tuple(coefficients)
    for key in table:
        if key not in allowed:
            extra = " (the linear law's stiffness is K1 under [parameters])" if law == "linear" else ""
            raise chk.fail(("spring", key), f"unknown key for law = {show(law)}; expected {', '.join(allowed)}{extra}"
                                            + suggest(key, allowed))
    if "range" not in table and law != "linear":
        raise chk.fail(("spring", "range"), "missing required key: the declared deflection range in rad "
                                            "(|q_m - q| <= range; psi' > 0 is checked on it)", line_path=("spring",))
    rng = number(chk, ("spring", "range"), table.get("range", 3.141592653589793), "rad", ">0",
                 "the deflection range")
    values = {}
    for key, (unit, bound, meaning) in coefficients.items():
        if key not in table:
            raise chk.fail(("spring", key), f"missing required key: {meaning} in {unit}", line_path=("spring",))
        values[key] = number(chk, ("spring", key), table[key], unit, bound, meaning)
    return SpringSpec(law, values, rng)


def parse_friction_table(data: dict, chk: Checker, links: int) -> Optional[Dict[str, float]]:
    """``[friction]`` of a parsed file: ``{F_c, F_s, v_s, v_c}`` (``F_s`` defaults to ``F_c``)."""
    table = _table(data, chk, "friction", links)
    if table is None:
        return None
    for key in table:
        if key not in FRICTION_COEFFICIENTS:
            raise chk.fail(("friction", key), f"unknown key; [friction] allows {', '.join(FRICTION_COEFFICIENTS)}"
                                              + suggest(key, FRICTION_COEFFICIENTS))
    if "F_c" not in table:
        raise chk.fail(("friction", "F_c"), "missing required key: the Coulomb level F_c in N m",
                       line_path=("friction",))
    out = {}
    for key, (unit, bound, meaning, default) in FRICTION_COEFFICIENTS.items():
        default = out["F_c"] if key == "F_s" else default
        out[key] = number(chk, ("friction", key), table.get(key, default), unit, bound, meaning)
    return out


def spring_error(chk: Checker, err: SpringError):
    """A law's own check (:mod:`derive.core.spring_laws`) as a model-file error at the ``law`` line."""
    return chk.fail(("spring", "law"), str(err).split(": ", 1)[-1])
