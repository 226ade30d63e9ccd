"""The URDF form of a model file: a spatial arm from a URDF file with elastic joints.

The format (see docs/spatial.md and examples/elbow_arm.toml)::

    [model]
    name = "arm"
    urdf = "arm.urdf"          # relative to the model file
    base = "base_link"
    tip = "tool0"              # or several: tips = ["left_hand", "right_hand"] (a tree, see below)
    symbolic = ["link3"]       # optional: links whose inertials are runtime parameters
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
    [rotors]                   # optional: the complete model (docs/complete-model.md)
    gear_ratio = [100.0, 100.0]      # per joint, > 0: defaults of the parameters N1..Nn
    mass = [0.0, 0.0]                # optional, kg, >= 0 (default 0): joins the carrying link
    transverse_inertia = [1e-6, 1e-6]  # optional, kg m^2, >= 0 (default I_a / 2 = Jm / (2 N^2))
    reduced_model = "arm"            # optional: the reduced model whose laws to use

A tree: ``tips = [...]`` names several tip links (``tip``, if given as well,
must be one of them); the joints on the paths from the base to each tip form
the model, in q order depth-first in the order of ``tips`` (joints shared with
an earlier tip's path first, once). A tree takes no ``[payload]`` and no
``[rotors]``.

The URDF is read by :mod:`derive.spatial.urdf`; :meth:`UrdfModelSpec.build` builds
the model with :func:`derive.spatial.spatial.make_spatial`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Dict, List, Optional, Tuple

from ..spatial.chain import chain_numerics
from ..core.model_base import FlexibleJointModel
from ..core.rotors import Rotors, gear_params
from ..spatial.spatial import make_spatial
from ..spatial.spatial_params import elastic_params, inertial_params, payload_params
from ..spatial.urdf import UrdfChain, UrdfError, load_urdf
from .drive_tables import SpringSpec, parse_joint_drive_tables
from .robot_facts import FACT_TABLES, robot_facts
from .schema import Checker, check_description, check_name, got, number, show, suggest
from .toml_keys import KeyPath

__all__ = ["UrdfModelSpec", "parse_urdf_form", "DEFAULT_G0"]

#: The repository root (URDF paths in manifests are relative to it).
REPO = Path(__file__).resolve().parent.parent.parent
URDF_MODEL_KEYS = ("name", "urdf", "base", "tip", "tips", "description", "symbolic")
URDF_TOP = ("model", "joints", "parameters", "payload", "notes", "rotors", "spring", "friction") + FACT_TABLES
#: Keys of ``[rotors]``.
ROTOR_KEYS = ("gear_ratio", "mass", "transverse_inertia", "reduced_model")
#: Elastic parameters per joint: key -> (SI unit, bound kind, meaning, default or None = required).
ELASTIC: Dict[str, Tuple[str, str, str, Optional[float]]] = {
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
    rotors: Optional[Rotors] = None  # the complete model's rotors ([rotors]), None: the reduced model
    reduced_model: Optional[str] = None
    tips: Tuple[str, ...] = ()  # several tips: a tree (``tip`` is then one of them or empty)
    springs: Optional[Tuple[SpringSpec, ...]] = None  # [spring.*] per joint (derive.model_file.drive_tables)
    frictions: Optional[Tuple[Optional[Dict[str, float]], ...]] = None  # [friction.*] per joint
    facts: Optional[Dict[str, object]] = None  # manifest "limits" and "task" (derive.model_file.robot_facts)
    urdf_given: str = ""  # [model] urdf as the model file writes it (relative to the model file)

    def build(self) -> FlexibleJointModel:
        """The symbolic model (:func:`derive.spatial.spatial.make_spatial` of the URDF chain or tree)."""
        ends = self.tips or self.tip
        chain = load_urdf(self.urdf, self.base, ends, source=_repo_relative(self.urdf))
        n = len(chain.joints)
        # a joint with a nonlinear spring law has no K (None): its placeholder is replaced by the law's
        # coefficients (derive.core.spring.with_drives)
        K = tuple(1.0 if k is None else k for k in self.K)
        params = elastic_params(n, K, self.Jm, self.Bm, self.g0, chain.joints,
                                {k: f"; {v}" for k, v in self.notes.items()})
        if self.payload is not None:
            params = params + payload_params(self.payload[0], self.payload[1], self.tip)
        params = params + inertial_params(chain.description, self.symbolic)
        rotors = self.rotors.resolve(self.Jm) if self.rotors is not None else None
        if rotors is not None:
            params = params + gear_params(rotors.gear_ratio)
        description = self.description or (
            f"Spatial serial chain of {n} revolute joints from the URDF {_repo_relative(self.urdf)} "
            f"(robot {chain.robot}, {self.base} -> {', '.join(self.tips) or self.tip}), flexible joints, "
            "gravity g0 along -z "
            f"of {self.base}.")
        model = make_spatial(chain.description, self.name, params, description, symbolic=self.symbolic,
                             rotors=rotors, reduced_model=self.reduced_model)
        src = {"urdf": _urdf_label(self.urdf, self.urdf_given), "sha256": chain.sha256, "base": self.base,
               **({"tips": list(self.tips)} if self.tips else {"tip": self.tip}), "joints": list(chain.joints),
               "limits": urdf_limits(chain)}
        if chain.ignored:
            src["ignored_links"] = list(chain.ignored)
        model = replace(model, source=src, urdf_file=str(self.urdf))
        if self.springs is not None or self.frictions is not None:
            from ..core.spring import with_drives
            springs = self.springs or tuple(SpringSpec("linear", {}, 3.141592653589793) for _ in range(n))
            model = with_drives(model, [(s.kind, s.coefficients, s.deflection_range) for s in springs],
                                None if self.frictions is None else list(self.frictions))
        return replace(model, robot_facts=self.facts or None)


#: Units of the ``limits`` lists of a URDF model's manifest ``source``.
LIMIT_UNITS = {"effort": "N m", "velocity": "rad/s", "lower": "rad", "upper": "rad"}


def urdf_limits(chain: UrdfChain) -> Dict[str, object]:
    """The URDF's ``<limit>`` per joint in q order, for the manifest (``source["limits"]``).

    Returns
    -------
    dict
        ``effort``, ``velocity``, ``lower``, ``upper``: lists of length n (float, or None where the
        URDF states nothing), and ``unit``: the unit of each list. The numbers are the URDF's as
        written (link side); placeholders (Baxter's head: effort 50000 N m) are kept, the consumer
        decides what to do with them.
    """
    out: Dict[str, object] = {key: [getattr(lim, key) for lim in chain.limits] for key in LIMIT_UNITS}
    out["unit"] = dict(LIMIT_UNITS)
    return out


def _urdf_label(path: Path, given: str) -> str:
    """How the manifest and chain.json name the URDF: relative to the repository root for a built-in
    model, else as the model file gives it (relative to the model file; its file name if not given)."""
    resolved = Path(path).resolve()
    try:
        return resolved.relative_to(REPO).as_posix()
    except ValueError:
        return given or resolved.name


def _repo_relative(path: Path) -> str:
    """``path`` relative to the repository root (POSIX), or its file name if outside it."""
    resolved = Path(path).resolve()
    try:
        return resolved.relative_to(REPO).as_posix()
    except ValueError:
        return resolved.name


def _model_table(data: dict, chk: Checker, builtin: bool) -> dict:
    """The top level and ``[model]`` of the URDF form (keys, required strings, name, description)."""
    for key in data:
        if key not in URDF_TOP:
            raise chk.fail((key,), "unknown key; a URDF model file has the tables "
                                   f"{', '.join('[' + t + ']' for t in URDF_TOP)} only" + suggest(key, URDF_TOP))
    model = data["model"]
    for key in model:
        if key not in URDF_MODEL_KEYS:
            raise chk.fail(("model", key), f"unknown key; [model] of the URDF form allows "
                                           f"{', '.join(URDF_MODEL_KEYS)}" + suggest(key, URDF_MODEL_KEYS))
    for key in ("name", "urdf", "base") + (() if "tips" in model else ("tip",)):
        if key not in model:
            raise chk.fail(("model", key), f"missing required key: {key} = \"...\" (a string)",
                           line_path=("model",))
        if not isinstance(model[key], str) or not model[key]:
            raise chk.fail(("model", key), f"expected a non-empty string, {got(model[key])}")
    _tips(chk, model)
    check_name(chk, model["name"], builtin)
    check_description(chk, model.get("description"))
    return model


def _tips(chk: Checker, model: dict) -> None:
    """``[model] tips`` (optional): distinct link names, at least two; ``tip`` beside it must be one of them."""
    if "tips" not in model:
        return
    tips = model["tips"]
    if (not isinstance(tips, list) or len(tips) < 2 or not all(isinstance(t, str) and t for t in tips)
            or len(set(tips)) != len(tips)):
        raise chk.fail(("model", "tips"), f"expected an array of at least two distinct link names, {got(tips)}")
    if "tip" in model and model["tip"] not in tips:
        raise chk.fail(("model", "tip"), f"{show(model['tip'])} is not among tips {tips}; expected one of them "
                                         "(or leave tip out)")


def _ends(model: dict):
    """The tip link, or the tuple of tips of a tree."""
    return tuple(model["tips"]) if "tips" in model else model["tip"]


def _load_chain(chk: Checker, model: dict, base_dir: Path) -> Tuple[Path, UrdfChain]:
    """The URDF file (resolved) and its ``base -> tip`` chain."""
    urdf = (base_dir / model["urdf"]).resolve()
    if not urdf.is_file():
        raise chk.fail(("model", "urdf"), f"URDF file {model['urdf']!r} not found (looked for {urdf}); "
                                          "expected a path relative to the model file")
    try:
        chain = load_urdf(urdf, model["base"], _ends(model), source=str(urdf))
    except UrdfError as exc:
        raise chk.fail(("model", "urdf"), f"cannot use the URDF: {exc}") from None
    return urdf, chain


def _symbolic_links(chk: Checker, model: dict, chain: UrdfChain) -> Tuple[str, ...]:
    """``[model] symbolic``: distinct link names of the chain with an inertial."""
    symbolic = model.get("symbolic", [])
    if not isinstance(symbolic, list) or not all(isinstance(v, str) for v in symbolic):
        raise chk.fail(("model", "symbolic"), f"expected an array of link names, {got(symbolic)}")
    for link in symbolic:
        if not re.fullmatch(r"[A-Za-z0-9_]+", link) or symbolic.count(link) > 1:
            raise chk.fail(("model", "symbolic"), f"{show(link)}: expected distinct link names of letters, "
                                                  "digits and _ (they become parameter names m_<link>, ...)")
    try:
        chain_numerics(chain.description, tuple(symbolic))
    except ValueError as exc:
        raise chk.fail(("model", "symbolic"), str(exc)) from None
    return tuple(symbolic)


def _joint_values(chk: Checker, data: dict, model: dict, names: Tuple[str, ...],
                  nonlinear=frozenset()) -> Dict[str, List[float]]:
    """``[joints.*]``: K, Jm, Bm per chain joint in q order (joint table over default over built-in).

    Joints in ``nonlinear`` have a spring law of ``[spring.*]`` in place of ``K``: their table may not
    give one, and their ``K`` is None.
    """
    joints = data.get("joints", {})
    if not isinstance(joints, dict):
        raise chk.fail(("joints",), f"expected tables [joints.default] and [joints.<URDF joint name>], {got(joints)}")
    values: Dict[str, Dict[str, float]] = {}
    for jname, entry in joints.items():
        path: KeyPath = ("joints", jname)
        if jname != "default" and jname not in names:
            raise chk.fail(path, f"no revolute joint {jname!r} on the chain {model['base']} -> "
                                 f"{', '.join(model['tips']) if 'tips' in model else model['tip']}; "
                                 f"expected 'default' or one of {', '.join(names)}" + suggest(jname, names))
        if not isinstance(entry, dict):
            raise chk.fail(path, f"expected a table with K, Jm, Bm, {got(entry)}")
        values[jname] = {}
        for key, val in entry.items():
            if key not in ELASTIC:
                raise chk.fail(path + (key,), f"unknown key; a joint table allows {', '.join(ELASTIC)}"
                                              + suggest(key, ELASTIC))
            unit, kind, meaning, _ = ELASTIC[key]
            values[jname][key] = number(chk, path + (key,), val, unit, kind, meaning)
    per: Dict[str, List[float]] = {k: [] for k in ELASTIC}
    for jname in names:
        if jname in nonlinear and "K" in values.get(jname, {}):
            raise chk.fail(("joints", jname, "K"), f"joint {jname!r} has a nonlinear spring law ([spring.*]), "
                                                   "which replaces its stiffness K; remove K here")
        for key, (unit, _, meaning, default) in ELASTIC.items():
            if key == "K" and jname in nonlinear:
                per[key].append(None)
                continue
            v = values.get(jname, {}).get(key, values.get("default", {}).get(key, default))
            if v is None:
                raise chk.fail(("joints", jname, key),
                               f"missing {meaning} of joint {jname!r}: expected {key} = <number in {unit}> in "
                               f"[joints.{jname}] or [joints.default]", line_path=("joints",))
            per[key].append(v)
    return per


def _gravity_and_notes(chk: Checker, data: dict) -> Tuple[float, Dict[str, str]]:
    """``[parameters] g0`` (optional) and ``[notes]`` (optional strings keyed K, Jm, Bm)."""
    params = data.get("parameters", {})
    if not isinstance(params, dict):
        raise chk.fail(("parameters",), f"expected a table, {got(params)}")
    for key in params:
        if key != "g0":
            raise chk.fail(("parameters", key), "unknown parameter; the URDF form takes g0 only here "
                                                "(elastic parameters go in [joints.*], inertials in the URDF)")
    g0 = number(chk, ("parameters", "g0"), params.get("g0", DEFAULT_G0), "m/s^2", ">=0",
                "gravitational acceleration")

    notes = data.get("notes", {})
    if not isinstance(notes, dict):
        raise chk.fail(("notes",), f"expected a table of strings keyed K, Jm, Bm, {got(notes)}")
    for key, val in notes.items():
        if key not in ELASTIC:
            raise chk.fail(("notes", key), f"unknown key; [notes] allows {', '.join(ELASTIC)}")
        check_description(chk, val, ("notes", key))
    return g0, dict(notes)


def _payload(chk: Checker, data: dict) -> Optional[Tuple[float, Tuple[float, ...]]]:
    """``[payload]`` (optional): the point mass and its position in the tip link frame."""
    if "payload" not in data:
        return None
    table = data["payload"]
    if not isinstance(table, dict):
        raise chk.fail(("payload",), f"expected a table with mass and com, {got(table)}")
    for key in table:
        if key not in ("mass", "com"):
            raise chk.fail(("payload", key), "unknown key; [payload] allows mass, com")
    for key in ("mass", "com"):
        if key not in table:
            raise chk.fail(("payload", key), f"missing required key: {key}", line_path=("payload",))
    mass = number(chk, ("payload", "mass"), table["mass"], "kg", ">=0", "payload mass")
    com = table["com"]
    if not isinstance(com, list) or len(com) != 3:
        raise chk.fail(("payload", "com"), f"expected an array of 3 numbers (m, in the tip link frame), "
                                           f"{got(com)}")
    com = tuple(number(chk, ("payload", "com"), v, "m", "any", "payload position") for v in com)
    return (mass, com)


def _rotors(chk: Checker, data: dict, n: int) -> Tuple[Optional[Rotors], Optional[str]]:
    """``[rotors]`` (optional): per-joint gear ratios, masses, transverse inertias; the reduced model's name."""
    if "rotors" not in data:
        return None, None
    table = data["rotors"]
    if not isinstance(table, dict):
        raise chk.fail(("rotors",), f"expected a table with gear_ratio (and mass, transverse_inertia), {got(table)}")
    for key in table:
        if key not in ROTOR_KEYS:
            raise chk.fail(("rotors", key), f"unknown key; [rotors] allows {', '.join(ROTOR_KEYS)}"
                           + suggest(key, ROTOR_KEYS))
    if "gear_ratio" not in table:
        raise chk.fail(("rotors", "gear_ratio"), f"missing required key: gear_ratio = [...] ({n} numbers > 0)",
                       line_path=("rotors",))

    def per_joint(key: str, unit: str, kind: str, meaning: str, default):
        values = table.get(key, [default] * n)
        if not isinstance(values, list) or len(values) != n:
            raise chk.fail(("rotors", key), f"expected an array of {n} numbers in {unit} (one per joint), "
                                            f"{got(values)}")
        return tuple(v if v is None else number(chk, ("rotors", key), v, unit, kind, meaning) for v in values)

    reduced = table.get("reduced_model")
    if reduced is not None and (not isinstance(reduced, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", reduced)):
        raise chk.fail(("rotors", "reduced_model"), f"expected a model name (letters, digits, _), {got(reduced)}")
    return Rotors(per_joint("gear_ratio", "1", ">0", "gear ratio", None),
                  per_joint("mass", "kg", ">=0", "rotor mass", 0.0),
                  per_joint("transverse_inertia", "kg m^2", ">=0", "rotor transverse inertia", None)), reduced


def parse_urdf_form(data: dict, chk: Checker, base_dir: Path, builtin: bool) -> UrdfModelSpec:
    """The URDF form of a parsed model file (see the module docstring for the format).

    Raises
    ------
    ModelFileError
        Unknown table or key, wrong type or range, a URDF that cannot be used,
        a joint without its elastic parameters.
    """
    model = _model_table(data, chk, builtin)
    urdf, chain = _load_chain(chk, model, base_dir)
    names = chain.joints
    symbolic = _symbolic_links(chk, model, chain)
    springs, frictions = parse_joint_drive_tables(data, chk, names)
    nonlinear = {j for j, s in zip(names, springs or ()) if s.kind != "linear"}
    per = _joint_values(chk, data, model, names, nonlinear)
    g0, notes = _gravity_and_notes(chk, data)
    payload = _payload(chk, data)
    rotors, reduced = _rotors(chk, data, len(names))
    if "tips" in model:
        for key in ("payload", "rotors"):
            if key in data:
                raise chk.fail((key,), f"[{key}] is for a serial chain; this model names several tips (a tree)")
    return UrdfModelSpec(rotors=rotors, reduced_model=reduced, name=model["name"], urdf=urdf, base=model["base"],
                         tip=model.get("tip", ""), tips=tuple(model.get("tips", ())), joints=names,
                         K=tuple(per["K"]), Jm=tuple(per["Jm"]), Bm=tuple(per["Bm"]), g0=g0,
                         description=model.get("description"), notes=notes, source=chk.source,
                         payload=payload, symbolic=symbolic, urdf_given=str(model["urdf"]),
                         springs=None if springs is None else tuple(springs),
                         frictions=None if frictions is None else tuple(frictions),
                         facts=robot_facts(data, chk, names, urdf_limits(chain)))
