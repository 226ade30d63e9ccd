"""The manifest's ``parameters`` entries and ``drives`` table: what each runtime parameter is.

Each ``parameters`` entry::

    {"name", "default", "meaning", "unit",
     "domain": ">0" | ">=0" | "any"   (derive.core.domains),
     "joint": 1-based joint number, "role": "spring" | "rotor_inertia" | "damping" | "friction" | "gear_ratio",
     "coefficient": the law's coefficient name (spring and friction roles only: "K", "k3", "K_2", "F_c", ...)}

``joint``, ``role`` and ``coefficient`` are absent for link and gravity parameters. ``drives`` holds one
entry per elastic joint, in q order::

    {"joint": 1-based number, "name": joint name (URDF or chain.json),
     "spring": {"law": "linear" | "cubic" | "three_segment", "parameters": [names in the law's coefficient
                order: ("K",) for linear, derive.core.spring_laws.LAW_COEFFICIENTS otherwise],
                "torque_scale": [the names that scale psi together, TORQUE_SCALE_COEFFICIENTS]},
     "rotor_inertia": name, "damping": name,
     "friction": null or {"law": "coulomb_stribeck_tanh", "parameters": [F_c, F_s, v_s, v_c names]},
     "gear_ratio": null or name (complete models)}

Both are read from the model's chain description (:func:`derive.emit.chain_json.chain_document`), the one
place that states the roles.
"""

from __future__ import annotations

from typing import Dict, List, Optional, Tuple

from ..core.domains import parameter_domain
from ..core.friction import FRICTION_PARAMETERS
from ..core.model_base import FlexibleJointModel
from ..core.spring_laws import LAW_COEFFICIENTS, TORQUE_SCALE_COEFFICIENTS
from .chain_json import chain_document

__all__ = ["drive_table", "parameter_entries"]


def drive_table(m: FlexibleJointModel) -> List[dict]:
    """The manifest's ``drives`` list of model ``m`` (module docstring); empty without a chain description."""
    doc = chain_document(m)
    if doc is None:
        return []
    gears = {r["joint"]: r["gear_ratio"] for r in doc.get("rotors", ())}
    out = []
    for j, e in enumerate(doc["elastic"], start=1):
        law = e["spring"]["law"] if "spring" in e else "linear"
        names = [e["spring"][c] for c in _spring_roles(e["spring"], law)] if "spring" in e else [e["K"]]
        by_coefficient = dict(zip(("K",) if law == "linear" else LAW_COEFFICIENTS[law], names))
        spring = {"law": law, "parameters": names,
                  "torque_scale": [by_coefficient[c] for c in TORQUE_SCALE_COEFFICIENTS[law]]}
        fr = e.get("friction")
        friction = None if fr is None else {
            "law": fr["law"], "parameters": [fr[name] for name, _, _ in FRICTION_PARAMETERS]}
        out.append({"joint": j, "name": e["joint"], "spring": spring, "rotor_inertia": e["Jm"], "damping": e["Bm"],
                    "friction": friction, "gear_ratio": gears.get(e["joint"])})
    return out


def _spring_roles(spring: dict, law: str) -> Tuple[str, ...]:
    """The chain.json keys of a law's coefficients in :data:`LAW_COEFFICIENTS` order (``width`` is ``w_blend``)."""
    keys = [k for k in spring if k != "law"]
    if len(keys) != len(LAW_COEFFICIENTS[law]):
        raise ValueError(f"spring law {law!r}: chain.json names {keys}, expected {LAW_COEFFICIENTS[law]}")
    return tuple(keys)


def _roles(drives: List[dict]) -> Dict[str, Tuple[int, str, Optional[str]]]:
    """Parameter name -> (joint, role, coefficient) for every drive parameter."""
    roles = {}
    for d in drives:
        law = d["spring"]["law"]
        coefficients = ("K",) if law == "linear" else LAW_COEFFICIENTS[law]
        for name, c in zip(d["spring"]["parameters"], coefficients):
            roles[name] = (d["joint"], "spring", c)
        roles[d["rotor_inertia"]] = (d["joint"], "rotor_inertia", None)
        roles[d["damping"]] = (d["joint"], "damping", None)
        if d["friction"] is not None:
            for name, (c, _, _) in zip(d["friction"]["parameters"], FRICTION_PARAMETERS):
                roles[name] = (d["joint"], "friction", c)
        if d["gear_ratio"] is not None:
            roles[d["gear_ratio"]] = (d["joint"], "gear_ratio", None)
    return roles


def parameter_entries(m: FlexibleJointModel, drives: List[dict]) -> List[dict]:
    """The manifest's ``parameters`` list of model ``m`` given its :func:`drive_table` (module docstring)."""
    roles = _roles(drives)
    out = []
    for p in m.params:
        joint, role, coefficient = roles.get(p.name, (None, None, None))
        entry = {"name": p.name, "default": p.default, "meaning": p.meaning, "unit": p.unit,
                 "domain": parameter_domain(p.name, role, coefficient)}
        if role is not None:
            entry.update({"joint": joint, "role": role, **({"coefficient": coefficient} if coefficient else {})})
        out.append(entry)
    return out
