"""A robot's own facts in its model file: ``[limits]`` and ``[task]``, carried into the manifest.

Both forms of a model file may state them (examples/ur5e.toml, derive/robots/*/*.toml)::

    [limits]                  # optional; a joint not stated keeps its URDF <limit> (none in the planar form)
    effort = 50.0             # N m: one number for every joint,
    velocity = [2.0, 2.0]     # rad/s: an array of n numbers in q order,
    torque_rate = { default = 1000.0, head_pan = 200.0 }   # N m/s: or a table by joint ("default": the rest)

    [task]                    # optional: the task the model's demo and `fjm design` run
    kind = "sines"            # q_d = offset + amplitude sin(omega t + phase), per joint
    description = "..."       # optional, one line (recorded as the design's reference kind)
    offset = [0.0, -0.785]    # rad (default 0)
    amplitude = 0.3           # rad, >= 0
    omega = [1.0, 1.2]        # rad/s, >= 0
    phase = -1.5707963267948966   # rad (default 0); -pi/2 starts every joint at rest at offset - amplitude
    start = "rest"            # at rest on the reference at t = 0, holding gravity (nominal parameters)

    # or kind = "poses": poses = [[...], [...]] (rad, n numbers each) and durations = [...] (s, > 0, one per
    # move between consecutive poses; 9th-order smooth steps, then the last pose held)

Per-joint values take the forms of ``effort`` above; tables are keyed by the URDF joint names (the planar
form: joint numbers ``"1"``..``"n"``, as ``[spring.<joint>]``). :func:`robot_facts` returns the manifest
entries ``limits`` (every key with ``unit``, ``values`` (None: no limit) and ``from`` per joint: ``"urdf"``,
``"model file"`` or None) and ``task`` (per-joint arrays expanded, with units).
"""

from __future__ import annotations

from typing import Dict, List, Optional, Sequence, Tuple

from .schema import Checker, check_description, got, number, optional_table, show, suggest
from .toml_keys import KeyPath

__all__ = ["FACT_TABLES", "LIMIT_KEYS", "TASK_KINDS", "robot_facts"]

#: Top-level tables of this module (both forms allow them).
FACT_TABLES = ("limits", "task")
#: ``[limits]`` keys: (unit, meaning, the URDF's ``<limit>`` attribute or None).
LIMIT_KEYS: Dict[str, Tuple[str, str, Optional[str]]] = {
    "effort": ("N m", "effort limit", "effort"),
    "velocity": ("rad/s", "velocity limit", "velocity"),
    "torque_rate": ("N m/s", "torque-rate limit", None),
}
#: ``[task]`` kinds and their keys: key -> (unit, bound, meaning, default or None when required).
TASK_KINDS: Dict[str, Dict[str, Tuple[str, str, str, Optional[float]]]] = {
    "sines": {"offset": ("rad", "any", "sine centre", 0.0), "amplitude": ("rad", ">=0", "sine amplitude", None),
              "omega": ("rad/s", ">=0", "sine angular frequency", None), "phase": ("rad", "any", "sine phase", 0.0)},
    "poses": {},
}
TASK_COMMON = ("kind", "description", "start")
START = ("rest",)


def per_joint(chk: Checker, path: KeyPath, value, joints: Sequence[str], unit: str, kind: str,
              meaning: str) -> List[Optional[float]]:
    """One number, an array of n numbers or a table by joint name (and ``default``), as n values (None:
    not stated for that joint)."""
    n = len(joints)
    if isinstance(value, dict):
        for key in value:
            if key != "default" and key not in joints:
                raise chk.fail(path + (key,), f"no joint {key!r}; expected 'default' or one of "
                                              f"{', '.join(joints)}" + suggest(key, list(joints)))
        vals = {k: number(chk, path + (k,), v, unit, kind, meaning) for k, v in value.items()}
        return [vals.get(j, vals.get("default")) for j in joints]
    if isinstance(value, list):
        if len(value) != n:
            raise chk.fail(path, f"expected {n} numbers in {unit} (one per joint, q order), got an array of "
                                 f"{len(value)}")
        return [number(chk, path, v, unit, kind, meaning) for v in value]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise chk.fail(path, f"expected a number in {unit}, an array of {n} or a table by joint name, {got(value)}")
    return [number(chk, path, value, unit, kind, meaning)] * n


def _table(data: dict, chk: Checker, name: str, keys: Sequence[str]) -> Optional[dict]:
    table = optional_table(data, chk, name)
    for key in table or ():
        if key not in keys:
            raise chk.fail((name, key), f"unknown key; [{name}] allows {', '.join(keys)}" + suggest(key, keys))
    return table


def _limits(data: dict, chk: Checker, joints: Sequence[str], urdf: Optional[dict]) -> Optional[dict]:
    """The manifest ``limits``: ``[limits]`` over the URDF's ``<limit>``; None when neither states any."""
    table = _table(data, chk, "limits", tuple(LIMIT_KEYS))
    if table is None and urdf is None:
        return None
    table = table or {}
    out: Dict[str, object] = {}
    for key, (unit, meaning, attr) in LIMIT_KEYS.items():
        stated = per_joint(chk, ("limits", key), table[key], joints, unit, ">0", meaning) if key in table \
            else [None] * len(joints)
        base = list(urdf[attr]) if urdf is not None and attr is not None else [None] * len(joints)
        values = [s if s is not None else b for s, b in zip(stated, base)]
        origin = ["model file" if s is not None else "urdf" if b is not None else None for s, b in zip(stated, base)]
        out[key] = {"unit": unit, "values": values, "from": origin}
    if urdf is not None:
        out["position"] = {"unit": "rad", "lower": list(urdf["lower"]), "upper": list(urdf["upper"]),
                           "from": ["urdf" if lo is not None or up is not None else None
                                    for lo, up in zip(urdf["lower"], urdf["upper"])]}
    return out


def _poses(chk: Checker, table: dict, n: int) -> Dict[str, object]:
    """``poses`` (k arrays of n angles, rad) and ``durations`` (k - 1 move times, s, > 0)."""
    poses = table.get("poses")
    if not isinstance(poses, list) or not poses or not all(isinstance(p, list) and len(p) == n for p in poses):
        raise chk.fail(("task", "poses"), f"expected an array of poses, each an array of {n} angles in rad, "
                                          f"{got(poses) if 'poses' in table else 'nothing'}", line_path=("task",))
    durations = table.get("durations", [])
    if not isinstance(durations, list) or len(durations) != len(poses) - 1:
        raise chk.fail(("task", "durations"), f"expected an array of {len(poses) - 1} move times in s (one per "
                                              f"move between consecutive poses), {got(durations)}",
                       line_path=("task",))
    return {"poses": [[number(chk, ("task", "poses"), v, "rad", "any", "pose angle") for v in p] for p in poses],
            "durations": [number(chk, ("task", "durations"), v, "s", ">0", "move time") for v in durations],
            "unit": {"poses": "rad", "durations": "s"}}


def _task(data: dict, chk: Checker, joints: Sequence[str]) -> Optional[dict]:
    """The manifest ``task`` (per-joint arrays expanded), None when the file states none."""
    keys = TASK_COMMON + tuple(k for kind in TASK_KINDS.values() for k in kind) + ("poses", "durations")
    table = _table(data, chk, "task", keys)
    if table is None:
        return None
    kind = table.get("kind")
    if kind not in TASK_KINDS:
        raise chk.fail(("task", "kind"), f"{show(kind) if 'kind' in table else 'missing'}: expected kind = one "
                                         f"of {', '.join(repr(k) for k in TASK_KINDS)}",
                       line_path=None if "kind" in table else ("task",))
    start = table.get("start", START[0])
    if start not in START:
        raise chk.fail(("task", "start"), f"{show(start)}: expected one of {', '.join(repr(s) for s in START)} "
                                          "(at rest on the reference at t = 0, holding gravity)")
    check_description(chk, table.get("description"), ("task", "description"))
    other = [k for k in keys if k in table and k not in TASK_COMMON and k not in TASK_KINDS[kind]
             and not (kind == "poses" and k in ("poses", "durations"))]
    if other:
        raise chk.fail(("task", other[0]), f"not a key of kind = {show(kind)}; it takes "
                                           f"{', '.join(TASK_KINDS[kind]) or 'poses, durations'}")
    out: Dict[str, object] = {"kind": kind, **({"description": table["description"]} if "description" in table
                                                else {}), "start": start}
    if kind == "poses":
        return {**out, **_poses(chk, table, len(joints))}
    for key, (unit, bound, meaning, default) in TASK_KINDS[kind].items():
        if key not in table and default is None:
            raise chk.fail(("task", key), f"missing {meaning}: expected {key} = <number in {unit}, an array of "
                                          f"{len(joints)} or a table by joint>", line_path=("task",))
        vals = per_joint(chk, ("task", key), table.get(key, default), joints, unit, bound, meaning)
        missing = [j for j, v in zip(joints, vals) if v is None]
        if missing:
            raise chk.fail(("task", key), f"no {meaning} for joint {missing[0]!r}: expected it or a default")
        out[key] = vals
    out["unit"] = {key: unit for key, (unit, _, _, _) in TASK_KINDS[kind].items()}
    return out


def robot_facts(data: dict, chk: Checker, joints: Sequence[str], urdf: Optional[dict] = None) -> Dict[str, dict]:
    """The manifest entries ``limits`` and ``task`` of a parsed model file (each left out when absent).

    Parameters
    ----------
    data : dict
        The parsed TOML document.
    chk : Checker
    joints : sequence of str
        Joint names in q order (URDF names; the planar form: ``"1"``..``"n"``).
    urdf : dict, optional
        The URDF's ``<limit>`` per joint (:func:`derive.model_file.urdf_form.urdf_limits`); None without a URDF.

    Raises
    ------
    ModelFileError
        Unknown key, wrong type or count, a limit <= 0, a task without its required keys.
    """
    facts = {"limits": _limits(data, chk, joints, urdf), "task": _task(data, chk, joints)}
    return {k: v for k, v in facts.items() if v is not None}
