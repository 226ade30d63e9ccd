"""``generated/<model>/chain.json``: the model's kinematic and inertial chain, for exporters.

The runtime never imports SymPy or :mod:`derive`, yet an exporter (the MJCF
export of :mod:`fjm_runtime.export`) needs the rigid-body tree the equations
came from. This module writes it as plain data, one entry per rigid body in
tree order (parents first)::

    {"model", "kind": "urdf" | "planar" | "link1", "base",
     "gravity": {"direction": [3], "magnitude": VALUE},
     "joints": [q-order joint names],
     "elastic": [{"joint", "K", "Jm", "Bm"} parameter names per joint, q order; a nonlinear spring
                 has "spring": {"law": "cubic", "k1", "k3"} (psi = k1 phi + k3 phi^3) in place of "K";
                 motor friction beside "Bm": "friction": {"law": "coulomb_stribeck_tanh", "F_c", "F_s", "v_s",
                 "v_c"}, F(v) = (F_c + (F_s - F_c) exp(-(v/v_s)^2)) tanh(v/v_c) at the link-side motor
                 velocity v (derive.core.friction)],
     "bodies": [{"name", "parent" ("world" = the base frame), "joint" (name or null: welded),
                 "xyz": [3 VALUE], "R": [[3] x 3], "axis": [3] or null,
                 "inertial": null or {"mass": VALUE, "xyz": [3 VALUE], "R": [[3] x 3],
                                      "inertia": [ixx, ixy, ixz, iyy, iyz, izz] VALUEs}}]}

Poses follow URDF: ``xyz`` and ``R`` place the body (joint) frame in its
parent body frame at ``q = 0``, the joint turns about ``axis`` (in the body
frame); the inertial gives the mass, the centre of mass ``xyz`` and the frame
``R`` (both in the body frame) in which ``inertia`` is the tensor about the
centre of mass (URDF component order). A VALUE is a float, or
``{"poly": [[coefficient, [parameter names]], ...]}`` -- a sum of monomials
in the runtime parameters (``param_names``), e.g. ``-l1`` or
``J_l - M L L``; nothing is evaluated from text. Rotations are the snapped
matrices of :mod:`derive.spatial.chain` (the same numbers the derivation baked).

Models: URDF arms (their ``source`` URDF, re-read and checked against its
sha256, wherever the model file is: ``urdf`` names it relative to the repository for a built-in model,
else as the model file gives it, relative to the model file; payload ``m_load, x_load, y_load, z_load`` as a point-mass body on the
tip link; links with symbolic inertials name their parameters), ``planar<n>``
(every m, l, r, I is a parameter; gravity along -y, q = 0 hangs down) and
``link1`` (mass M at distance L, inertia ``J_l - M L^2`` about its centre,
gravity along -y; ``link1_hd`` the same with its cubic spring). Other models get no chain.json. A complete model
(docs/complete-model.md) adds ``"rotors": [{"joint", "gear_ratio" (parameter
name), "mass", "transverse_inertia" (kg m^2; null: ``J_m / (2 N^2)``)}]``:
rotor ``i`` rides on the parent of joint ``i``'s body at the joint's origin and
spins about its axis.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Dict, List, Optional, Sequence

from ..spatial.chain import ChainDescription, Inertial, mm, mv, rpy_matrix
from ..core.model_base import FlexibleJointModel, planar_param_names
from ..spatial.spatial_params import INERTIAL_FIELDS, PAYLOAD

__all__ = ["chain_document", "write_chain_json", "CHAIN_FILE"]

#: File name inside ``generated/<model>/``.
CHAIN_FILE = "chain.json"

_REPO = Path(__file__).resolve().parent.parent.parent
_EYE = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]


def _p(*terms) -> Dict[str, list]:
    """A VALUE that is a sum of monomials: ``_p((coef, name, name, ...), ...)``."""
    return {"poly": [[float(t[0]), list(t[1:])] for t in terms]}


def _mat(R) -> List[List[float]]:
    return [[float(R[r][k]) + 0.0 for k in range(3)] for r in range(3)]


def _vec(v) -> List[float]:
    return [float(x) + 0.0 for x in v]


def _elastic(names: Sequence[str], K: Sequence[str], Jm: Sequence[str], Bm: Sequence[str]) -> List[dict]:
    return [{"joint": j, "K": k, "Jm": jm, "Bm": bm} for j, k, jm, bm in zip(names, K, Jm, Bm)]


def _link1(m: FlexibleJointModel) -> dict:
    body = {"name": "link1", "parent": "world", "joint": "joint1", "xyz": [0.0, 0.0, 0.0], "R": _EYE,
            "axis": [0.0, 0.0, 1.0],
            "inertial": {"mass": _p((1, "M")), "xyz": [0.0, _p((-1, "L")), 0.0], "R": _EYE,
                         "inertia": [_p((1, "J_l"), (-1, "M", "L", "L")), 0.0, 0.0,
                                     _p((1, "J_l"), (-1, "M", "L", "L")), 0.0,
                                     _p((1, "J_l"), (-1, "M", "L", "L"))]}}
    return {"kind": "link1", "base": "world", "gravity": {"direction": [0.0, -1.0, 0.0], "magnitude": _p((1, "g0"))},
            "joints": ["joint1"], "elastic": _elastic(["joint1"], ["K"], ["J_m"], ["B_m"]), "bodies": [body]}


def _planar(m: FlexibleJointModel) -> dict:
    n = m.n
    bodies = []
    for i in range(1, n + 1):
        inertia = _p((1, f"I{i}"))
        bodies.append({
            "name": f"link{i}", "parent": "world" if i == 1 else f"link{i - 1}", "joint": f"joint{i}",
            "xyz": [0.0, 0.0 if i == 1 else _p((-1, f"l{i - 1}")), 0.0], "R": _EYE, "axis": [0.0, 0.0, 1.0],
            "inertial": {"mass": _p((1, f"m{i}")), "xyz": [0.0, _p((-1, f"r{i}")), 0.0], "R": _EYE,
                         "inertia": [inertia, 0.0, 0.0, inertia, 0.0, inertia]}})
    names = [f"joint{i}" for i in range(1, n + 1)]
    return {"kind": "planar", "base": "world",
            "gravity": {"direction": [0.0, -1.0, 0.0], "magnitude": _p((1, "g0"))}, "joints": names,
            "elastic": _elastic(names, *([f"{g}{i}" for i in range(1, n + 1)] for g in ("K", "Jm", "Bm"))),
            "bodies": bodies}


def _inertial(inertial: Optional[Inertial], link: str, symbolic: bool) -> Optional[dict]:
    """An inertial entry; a symbolic link's numbers are its parameters ``m_<link>, cx_<link>, ...``."""
    if inertial is None:
        return None
    if symbolic:
        f = [_p((1, f"{name}_{link}")) for name, _, _ in INERTIAL_FIELDS]
        return {"mass": f[0], "xyz": f[1:4], "R": _mat(rpy_matrix(inertial.rpy)), "inertia": f[4:10]}
    return {"mass": float(inertial.mass), "xyz": _vec(inertial.xyz), "R": _mat(rpy_matrix(inertial.rpy)),
            "inertia": _vec(inertial.inertia)}


def _urdf_bodies(desc: ChainDescription, symbolic: Sequence[str]) -> List[dict]:
    """Path links (one body per joint, fixed ones welded), then the attached links."""
    bodies = []
    parent = "world"
    for j in desc.joints:
        if j.parent is not None:  # a tree names each joint's parent link
            parent = "world" if j.parent == desc.base else j.parent
        revolute = j.kind == "revolute"
        norm = math.sqrt(sum(float(a) * float(a) for a in j.axis))
        bodies.append({"name": j.child, "parent": parent, "joint": j.name if revolute else None,
                       "xyz": _vec(j.xyz), "R": _mat(rpy_matrix(j.rpy)),
                       "axis": [float(a) / norm + 0.0 for a in j.axis] if revolute else None,
                       "inertial": _inertial(j.inertial, j.child, j.child in symbolic)})
        parent = j.child
    for a in desc.attached:
        R, p = _EYE, [0.0, 0.0, 0.0]
        for xyz, rpy in a.origins:  # compose the fixed joints from the parent link to this one
            R, p = mm(R, rpy_matrix(rpy)), [p[r] + mv(R, xyz)[r] for r in range(3)]
        bodies.append({"name": a.name, "parent": "world" if a.parent == desc.base else a.parent, "joint": None,
                       "xyz": _vec(p), "R": _mat(R), "axis": None,
                       "inertial": _inertial(a.inertial, a.name, a.name in symbolic)})
    return bodies


def _urdf(m: FlexibleJointModel) -> dict:
    from ..spatial.urdf import load_urdf  # build time only; the formula models do not need the URDF reader
    src = m.source
    # the URDF the model was built from (a model file anywhere), else the repository's (built-in models)
    path = Path(m.urdf_file) if getattr(m, "urdf_file", None) else _REPO / str(src["urdf"])
    if not path.is_file() or hashlib.sha256(path.read_bytes()).hexdigest() != src.get("sha256"):
        raise ValueError(f"model {m.name}: URDF {path} is missing or changed since it was read (sha256 "
                         f"{src.get('sha256')}); expected the file the model was derived from")
    chain = load_urdf(path, str(src["base"]), src.get("tips") or str(src["tip"]), source=str(src["urdf"]))
    names = set(m.param_names)
    symbolic = sorted(p[2:] for p in names if p.startswith("m_") and p != "m_load" and f"izz_{p[2:]}" in names)
    bodies = _urdf_bodies(chain.description, symbolic)
    if all(p in names for p in PAYLOAD):
        bodies.append({"name": f"{src['tip']}_payload", "parent": "world" if src["tip"] == src["base"] else src["tip"],
                       "joint": None, "xyz": [_p((1, f"{a}_load")) for a in "xyz"], "R": _EYE, "axis": None,
                       "inertial": {"mass": _p((1, "m_load")), "xyz": [0.0, 0.0, 0.0], "R": _EYE,
                                    "inertia": [0.0] * 6}})
    n = m.n
    return {"kind": "urdf", "base": str(src["base"]), "urdf": str(src["urdf"]), "sha256": src["sha256"],
            "gravity": {"direction": [0.0, 0.0, -1.0], "magnitude": _p((1, "g0"))}, "joints": list(chain.joints),
            "elastic": _elastic(chain.joints, *([f"{g}{i}" for i in range(1, n + 1)] for g in ("K", "Jm", "Bm"))),
            "bodies": bodies}


def _rotors(m: FlexibleJointModel, joints: Sequence[str]) -> List[dict]:
    """Rotor ``i`` rides on the parent body of joint ``i``'s body at its origin, spinning about its axis."""
    rotors = getattr(m, "rotors", None)
    n = len(joints)
    mass = [0.0] * n if rotors is None else [float(v) for v in rotors.mass]
    it = [None] * n if rotors is None else [None if v is None else float(v) for v in rotors.transverse_inertia]
    return [{"joint": j, "gear_ratio": f"N{i + 1}", "mass": mass[i], "transverse_inertia": it[i]}
            for i, j in enumerate(joints)]


def chain_document(m: FlexibleJointModel) -> Optional[dict]:
    """The chain.json content of model ``m`` (see the module docstring), or None if it has none.

    Parameters
    ----------
    m : FlexibleJointModel

    Returns
    -------
    dict or None
    """
    # a nonlinear spring's coefficients stand where its K stood (link1_hd, the drive model files)
    nonlinear = [s for s in (m.springs or ()) if s.kind != "linear"]
    spring_names = {str(c) for s in nonlinear for c in s.parameters}
    names = [x for x in m.param_names if x not in spring_names]
    K_slot = ["K"] if not nonlinear else []
    planar = [x for x in planar_param_names(m.n) if x not in {f"K{s.joint}" for s in nonlinear}]
    if m.source is not None and "urdf" in m.source:
        body = _urdf(m)
    elif names[:len(planar)] == planar:
        body = _planar(m)
    elif m.n == 1 and names[:7 - 1 + len(K_slot)] == ["J_l", "J_m", *K_slot, "M", "g0", "L", "B_m"]:
        body = _link1(m)
    else:
        body = None
    if body is None:
        return None
    for s in m.springs or ():
        if s.kind != "linear":
            e = body["elastic"][s.joint - 1]
            law = {"law": s.kind, **{role: str(sym) for role, sym in s.roles().items()}}
            body["elastic"][s.joint - 1] = {"joint": e["joint"], "spring": law,
                                            **{k: v for k, v in e.items() if k not in ("joint", "K")}}
    for fr in getattr(m, "frictions", None) or ():
        body["elastic"][fr.joint - 1]["friction"] = {"law": "coulomb_stribeck_tanh", **{
            role: str(getattr(fr, role)) for role in ("F_c", "F_s", "v_s", "v_c")}}
    if getattr(m, "coupling", None) is not None:  # a complete model: its rotors (docs/complete-model.md)
        body["rotors"] = _rotors(m, body["joints"])
    return {"header": "generated by `make derive`, do not edit", "model": m.name,
            "meaning": "rigid-body tree of the model (URDF conventions; VALUE = float or sum of parameter "
                       "monomials {'poly': [[coefficient, [names]]]})", **body}


def write_chain_json(m: FlexibleJointModel, outdir: Path) -> Optional[Path]:
    """Write ``outdir/chain.json`` for model ``m`` if it has a chain description; returns the path or None."""
    doc = chain_document(m)
    if doc is None:
        return None
    path = Path(outdir) / CHAIN_FILE
    path.write_text(_dumps(doc) + "\n")
    return path


def _dumps(obj, indent: str = "") -> str:
    """JSON with every value that fits in 110 characters on one line (short files, easy diffs)."""
    flat = json.dumps(obj)
    if len(indent) + len(flat) <= 110 or not isinstance(obj, (dict, list)) or not obj:
        return flat
    inner = indent + " "
    if isinstance(obj, dict):
        items = [f"{inner}{json.dumps(k)}: {_dumps(v, inner)}" for k, v in obj.items()]
        return "{\n" + ",\n".join(items) + "\n" + indent + "}"
    return "[\n" + ",\n".join(inner + _dumps(v, inner) for v in obj) + "\n" + indent + "]"
