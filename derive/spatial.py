"""Spatial serial chains of revolute joints: D(q), h(q, dq) and the potential as a Program.

A chain is described kinematically as in URDF (see :class:`ChainDescription`):
the path from the base link to the tip link is a sequence of joints, each
``revolute`` or ``fixed``, with its origin (``xyz``, ``rpy``) in the parent
link frame, its axis in the joint frame, and the inertial of its child link
(mass, centre of mass ``xyz``/``rpy`` in the link frame, inertia tensor about
the centre of mass in that frame). Rigid bodies hanging off the path by fixed
joints (a gripper's fingers) are :class:`Attached` to a path link. Gravity
``g0`` acts along ``-z`` of the base link frame. URDF conventions throughout:
``R(rpy) = Rz(yaw) Ry(pitch) Rx(roll)`` and, per joint,
``T_parent_child(q) = T(origin) Rot(axis, q)``.

Build-time numerics (:func:`chain_numerics`, floats): fixed joints are merged
into the moving body they hang on; every moving body ``i`` gets a frame ``B_i``
whose z axis is its joint axis (``B_i = child frame * Ra`` with ``Ra e_z =
axis``), so that the joint transform is a constant ``(R0_i, p_i)`` followed by
``Rz(q_i)``, and its inertia is summarized by 10 numbers about the origin of
``B_i``: mass ``m``, first moment ``h = m c`` and rotational inertia ``I_o``.
Rotation entries within 1e-12 of 0 or +-1 are snapped to the exact integer
(URDF files write multiples of pi/2 as decimals), which keeps the sparse
structure of typical arms (the Panda's constant rotations are permutations).

Symbolic part (:func:`make_spatial`): a straight-line :class:`Program` with
named intermediates --

* ``c_i = cos q_i``, ``s_i = sin q_i`` with the derivative rules
  ``dc = -s dq``, ``ds = c dq``; the rotations ``R_i = R0_i Rz(q_i)`` are linear
  in them;
* ``D`` by the composite-rigid-body algorithm (composite inertias in body
  frames, one force propagation per entry below the diagonal);
* ``h = C dq + G`` by recursive Newton-Euler with ``ddq = 0`` and the base
  accelerated upwards by ``g0`` (gravity);
* the potential from the world height of every body's centre of mass.

The result is a :class:`derive.models.FlexibleJointModel`, so linearization
and emission are exactly those of the planar chains. Pure math: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import sympy as sp

from .models import FlexibleJointModel, Param, _state_symbols
from .program import Program

__all__ = ["Inertial", "Joint", "Attached", "ChainDescription", "BodyNumerics", "ChainNumerics",
           "rpy_matrix", "chain_numerics", "planar_description",
           "payload_params", "PAYLOAD", "inertial_params", "INERTIAL_FIELDS", "make_spatial", "elastic_params", "SNAP"]

Vec3 = Tuple[float, float, float]

#: Rotation entries closer than this to 0 or +-1 become exact (see the module docstring).
SNAP = 1e-12


@dataclass(frozen=True)
class Inertial:
    """URDF ``<inertial>``: mass, centre-of-mass frame and inertia about the centre of mass.

    Attributes
    ----------
    mass : float
        kg, > 0 for a body (0 only for a massless frame with zero inertia).
    xyz, rpy : tuple of 3 floats
        Centre-of-mass frame in the link frame (m, rad).
    inertia : tuple of 6 floats
        ``(ixx, ixy, ixz, iyy, iyz, izz)`` about the centre of mass, in the
        centre-of-mass frame (kg m^2).
    """

    mass: float
    xyz: Vec3 = (0.0, 0.0, 0.0)
    rpy: Vec3 = (0.0, 0.0, 0.0)
    inertia: Tuple[float, float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Joint:
    """One joint on the base -> tip path.

    Attributes
    ----------
    name : str
    kind : {"revolute", "fixed"}
        (URDF ``continuous`` joints are ``revolute`` here.)
    xyz, rpy : tuple of 3 floats
        Joint origin in the parent link frame.
    axis : tuple of 3 floats
        Rotation axis in the joint frame (normalized here); ignored if fixed.
    child : str
        Child link name.
    inertial : Inertial or None
        The child link's inertial; None for a massless link.
    """

    name: str
    kind: str
    xyz: Vec3
    rpy: Vec3
    axis: Vec3
    child: str
    inertial: Optional[Inertial] = None


@dataclass(frozen=True)
class Attached:
    """A link fixed (through one or more fixed joints) to a link of the path.

    Attributes
    ----------
    name : str
        Link name (for messages).
    parent : str
        The path link it hangs on.
    origins : tuple of (xyz, rpy)
        The fixed joints' origins from ``parent`` to this link, in order.
    inertial : Inertial or None
    """

    name: str
    parent: str
    origins: Tuple[Tuple[Vec3, Vec3], ...]
    inertial: Optional[Inertial] = None


@dataclass(frozen=True)
class ChainDescription:
    """Kinematic and inertial description of a serial chain (URDF conventions).

    Attributes
    ----------
    base : str
        Base link name; fixed; gravity acts along -z of its frame.
    joints : tuple of Joint
        Path from the base to the tip, in order.
    attached : tuple of Attached
        Links rigidly fixed to path links but not on the path.
    """

    base: str
    joints: Tuple[Joint, ...]
    attached: Tuple[Attached, ...] = ()

    @property
    def revolute_names(self) -> Tuple[str, ...]:
        """Names of the revolute joints in q order."""
        return tuple(j.name for j in self.joints if j.kind == "revolute")


# --------------------------------------------------------------------------------------------
# Build-time numerics (floats)
# --------------------------------------------------------------------------------------------

def _snap(M: np.ndarray) -> np.ndarray:
    out = np.array(M, dtype=float)
    for target in (0.0, 1.0, -1.0):
        out[np.abs(out - target) < SNAP] = target
    return out


def rpy_matrix(rpy: Sequence[float]) -> np.ndarray:
    """URDF rotation ``Rz(yaw) Ry(pitch) Rx(roll)``, entries snapped (see :data:`SNAP`).

    Returns
    -------
    numpy.ndarray, shape (3, 3)
    """
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp_, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp_], [0, 1, 0], [-sp_, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return _snap(_snap(Rz) @ _snap(Ry) @ _snap(Rx))


def _axis_frame(axis: Sequence[float]) -> np.ndarray:
    """A rotation ``Ra`` with ``Ra e_z = axis`` (exact for the coordinate axes)."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    a = _snap(a)
    if np.allclose(a, [0, 0, 1], atol=0):
        return np.eye(3)
    if np.allclose(a, [0, 0, -1], atol=0):
        return np.diag([1.0, -1.0, -1.0])
    if np.allclose(a, [1, 0, 0], atol=0):
        return np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])  # Ry(pi/2)
    if np.allclose(a, [-1, 0, 0], atol=0):
        return np.array([[0.0, 0, -1], [0, 1, 0], [1, 0, 0]])  # Ry(-pi/2)
    if np.allclose(a, [0, 1, 0], atol=0):
        return np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # Rx(-pi/2)
    if np.allclose(a, [0, -1, 0], atol=0):
        return np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # Rx(pi/2)
    # General axis: rotate e_z onto a about e_z x a (Rodrigues).
    k = np.cross([0.0, 0.0, 1.0], a)
    s, c = np.linalg.norm(k), a[2]
    k = k / s
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return _snap(np.eye(3) + s * Kx + (1 - c) * Kx @ Kx)


@dataclass(frozen=True)
class BodyNumerics:
    """Numbers of moving body ``i`` (in its frame ``B_i``, z = joint axis).

    Attributes
    ----------
    R0 : numpy.ndarray, shape (3, 3)
        Constant rotation from the previous body frame (or the base) to ``B_i`` at ``q_i = 0``.
    p : numpy.ndarray, shape (3,)
        Origin of ``B_i`` in the previous body frame.
    mass : float
    first_moment : numpy.ndarray, shape (3,)
        ``m c`` (centre of mass ``c`` in ``B_i``).
    inertia_origin : numpy.ndarray, shape (3, 3)
        Rotational inertia about the origin of ``B_i``.
    """

    R0: np.ndarray
    p: np.ndarray
    mass: float
    first_moment: np.ndarray
    inertia_origin: np.ndarray


@dataclass(frozen=True)
class ChainNumerics:
    """All build-time numbers of a chain: one :class:`BodyNumerics` per revolute joint."""

    joint_names: Tuple[str, ...]
    bodies: Tuple[BodyNumerics, ...] = field(default_factory=tuple)
    #: Pose of the tip link frame in the last body frame: rotation (3, 3) and origin (3,).
    tip_R: np.ndarray = field(default_factory=lambda: np.eye(3))
    tip_p: np.ndarray = field(default_factory=lambda: np.zeros(3))
    #: Links with symbolic inertials: (link, body index 1..n, R, p of the link frame in the body frame, Inertial).
    symbolic: Tuple[tuple, ...] = ()


def _inertia_matrix(i6: Sequence[float]) -> np.ndarray:
    ixx, ixy, ixz, iyy, iyz, izz = (float(v) for v in i6)
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


def chain_numerics(desc: ChainDescription, symbolic: Sequence[str] = ()) -> ChainNumerics:
    """Merge fixed joints and attached links; align body frames with the joint axes.

    Parameters
    ----------
    desc : ChainDescription
    symbolic : sequence of str
        Links whose inertial is left out of the numeric sums (it becomes
        runtime parameters, see :func:`make_spatial`); their poses are in
        :attr:`ChainNumerics.symbolic`.

    Returns
    -------
    ChainNumerics
        One body per revolute joint, in q order.

    Raises
    ------
    ValueError
        If the chain has no revolute joint, a joint kind is unknown, or an
        attached link names a parent that is not on the path.
    """
    # Per path link: (body index, R, p) = pose of the link frame in B_body (body 0 = base).
    pose: Dict[str, Tuple[int, np.ndarray, np.ndarray]] = {desc.base: (0, np.eye(3), np.zeros(3))}
    bodies: List[dict] = []
    pieces: List[Tuple[int, np.ndarray, np.ndarray, Optional[Inertial], str]] = []
    parent = desc.base
    for j in desc.joints:
        k, R, p = pose[parent]
        Ro, po = R @ rpy_matrix(j.rpy), p + R @ np.asarray(j.xyz, float)
        if j.kind == "revolute":
            Ra = _axis_frame(j.axis)
            bodies.append({"R0": _snap(Ro @ Ra), "p": po})
            k, R, p = len(bodies), Ra.T.copy(), np.zeros(3)  # child link frame in the new body frame
        elif j.kind == "fixed":
            R, p = _snap(Ro), po
        else:
            raise ValueError(f"joint {j.name!r}: kind {j.kind!r}; expected 'revolute' or 'fixed'")
        pose[j.child] = (k, R, p)
        pieces.append((k, R, p, j.inertial, j.child))
        parent = j.child
    if not bodies:
        raise ValueError("the chain has no revolute joint")
    for a in desc.attached:
        if a.parent not in pose:
            raise ValueError(f"attached link {a.name!r}: parent {a.parent!r} is not on the chain")
        k, R, p = pose[a.parent]
        for xyz, rpy in a.origins:
            R, p = _snap(R @ rpy_matrix(rpy)), p + R @ np.asarray(xyz, float)
        pieces.append((k, R, p, a.inertial, a.name))

    mass = [0.0] * (len(bodies) + 1)
    first = [np.zeros(3) for _ in range(len(bodies) + 1)]
    inert = [np.zeros((3, 3)) for _ in range(len(bodies) + 1)]
    sym_pieces = {}
    for k, R, p, inertial, link in pieces:
        if link in symbolic:
            if k == 0 or inertial is None:
                raise ValueError(f"symbolic inertial of link {link!r}: expected a moving link with an <inertial> "
                                 "(on the chain or fixed to it)")
            sym_pieces[link] = (k, R, p, inertial)
            continue
        if inertial is None or inertial.mass == 0:
            continue
        Rc = _snap(R @ rpy_matrix(inertial.rpy))
        c = p + R @ np.asarray(inertial.xyz, float)
        m = float(inertial.mass)
        Ic = Rc @ _inertia_matrix(inertial.inertia) @ Rc.T
        mass[k] += m
        first[k] = first[k] + m * c
        inert[k] = inert[k] + Ic + m * (float(c @ c) * np.eye(3) - np.outer(c, c))
    out = tuple(BodyNumerics(R0=b["R0"], p=b["p"], mass=mass[i + 1], first_moment=first[i + 1],
                             inertia_origin=(inert[i + 1] + inert[i + 1].T) / 2)
                for i, b in enumerate(bodies))
    missing = [k for k in symbolic if k not in sym_pieces]
    if missing:
        raise ValueError(f"symbolic inertial of link(s) {missing}: not a link of the chain "
                         f"(expected among {[pc[4] for pc in pieces if pc[0] > 0 and pc[3] is not None]})")
    tip_k, tip_R, tip_p = pose[parent]
    assert tip_k == len(bodies)
    return ChainNumerics(joint_names=desc.revolute_names, bodies=out, tip_R=tip_R, tip_p=tip_p,
                         symbolic=tuple((link, *sym_pieces[link]) for link in symbolic))


def planar_description(n: int, m: Sequence[float], l: Sequence[float], r: Sequence[float],
                       I: Sequence[float]) -> ChainDescription:
    """``planar<n>`` as a spatial chain: joints about z, links along -y at q = 0.

    The first joint's origin is rotated by ``rpy = (pi/2, 0, 0)`` so that the
    chain's y axis is the base's z axis: gravity along -z of the base is
    gravity along -y of the plane, as in ``planar<n>``. Link ``i`` has mass
    ``m_i``, length ``l_i``, centre of mass at ``r_i`` from its joint and
    inertia ``I_i`` about its centre of mass (about every axis: only ``izz``
    enters planar motion).

    Returns
    -------
    ChainDescription
    """
    joints = []
    for i in range(n):
        joints.append(Joint(
            name=f"joint{i + 1}", kind="revolute",
            xyz=(0.0, 0.0, 0.0) if i == 0 else (0.0, -float(l[i - 1]), 0.0),
            rpy=(math.pi / 2, 0.0, 0.0) if i == 0 else (0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0),
            child=f"link{i + 1}",
            inertial=Inertial(mass=float(m[i]), xyz=(0.0, -float(r[i]), 0.0),
                              inertia=(float(I[i]), 0.0, 0.0, float(I[i]), 0.0, float(I[i])))))
    return ChainDescription(base="base", joints=tuple(joints))


# --------------------------------------------------------------------------------------------
# Symbolic dynamics
# --------------------------------------------------------------------------------------------

def _num(v: float) -> sp.Expr:
    """Exact integer for integral values (0, +-1 above all), else the double as a Float."""
    v = float(v)
    if v == int(v) and abs(v) < 2 ** 31:
        return sp.Integer(int(v))
    return sp.Float(v)


#: Optional tip payload parameters (a point mass in the tip link frame), after g0.
PAYLOAD: Tuple[str, ...] = ("m_load", "x_load", "y_load", "z_load")


def payload_params(mass: float, com: Sequence[float], tip: str) -> Tuple[Param, ...]:
    """Parameters ``m_load, x_load, y_load, z_load``: a point payload fixed to the tip link.

    Parameters
    ----------
    mass : float
        Default payload mass (kg, >= 0).
    com : sequence of 3 floats
        Default position of the payload in the tip link frame (m).
    tip : str
        Tip link name, quoted in the meanings.
    """
    return (Param("m_load", float(mass), f"payload mass, a point mass fixed to the tip link {tip} (>= 0)", "kg"),
            *(Param(f"{a}_load", float(v), f"payload position along {a} of the tip link {tip} frame", "m")
              for a, v in zip("xyz", com)))


#: Inertial parameters of a link listed in ``symbolic`` (suffix ``_<link>``).
INERTIAL_FIELDS: Tuple[Tuple[str, str, str], ...] = (
    ("m", "mass of link {l}", "kg"),
    ("cx", "centre of mass of link {l}, x in the link frame", "m"),
    ("cy", "centre of mass of link {l}, y in the link frame", "m"),
    ("cz", "centre of mass of link {l}, z in the link frame", "m"),
    ("ixx", "inertia of link {l} about its centre of mass, xx (URDF inertial frame)", "kg m^2"),
    ("ixy", "inertia of link {l} about its centre of mass, xy (URDF inertial frame)", "kg m^2"),
    ("ixz", "inertia of link {l} about its centre of mass, xz (URDF inertial frame)", "kg m^2"),
    ("iyy", "inertia of link {l} about its centre of mass, yy (URDF inertial frame)", "kg m^2"),
    ("iyz", "inertia of link {l} about its centre of mass, yz (URDF inertial frame)", "kg m^2"),
    ("izz", "inertia of link {l} about its centre of mass, zz (URDF inertial frame)", "kg m^2"),
)


def inertial_params(desc: ChainDescription, links: Sequence[str]) -> Tuple[Param, ...]:
    """Parameters ``m_<link>, cx_<link>, ..., izz_<link>`` with the URDF values as defaults.

    The inertial frame's orientation (``rpy``) stays baked; the centre of mass
    is in the link frame, the tensor in the inertial frame (URDF conventions).
    """
    num = chain_numerics(desc, links)
    out = []
    for link, _, _, _, inertial in num.symbolic:
        values = (inertial.mass, *inertial.xyz, *inertial.inertia)
        out += [Param(f"{f}_{link}", float(v), meaning.format(l=link), unit)
                for (f, meaning, unit), v in zip(INERTIAL_FIELDS, values)]
    return tuple(out)


def elastic_params(n: int, K: Sequence[float], Jm: Sequence[float], Bm: Sequence[float],
                   g0: float = 9.81, joint_names: Sequence[str] = None,
                   sources: Dict[str, str] = None) -> Tuple[Param, ...]:
    """Parameter table ``K1..Kn, Jm1..Jmn, Bm1..Bmn, g0`` of a spatial chain.

    Parameters
    ----------
    n : int
    K, Jm, Bm : sequence of float, length n
        Defaults (N m/rad, kg m^2, N m s/rad).
    g0 : float
    joint_names : sequence of str, optional
        URDF joint names, quoted in the meanings.
    sources : dict str -> str, optional
        Extra text appended to the meaning of ``K`` and ``Jm`` (e.g. where the
        illustrative values come from).
    """
    names = list(joint_names) if joint_names is not None else [str(i + 1) for i in range(n)]
    sources = sources or {}
    groups = [("K", K, "stiffness of joint {i} ({j})", "N m/rad"),
              ("Jm", Jm, "reflected inertia of motor {i} ({j})", "kg m^2"),
              ("Bm", Bm, "viscous damping of motor {i} ({j})", "N m s/rad")]
    params = []
    for g, values, meaning, unit in groups:
        for i in range(n):
            text = meaning.format(i=i + 1, j=names[i]) + sources.get(g, "")
            params.append(Param(f"{g}{i + 1}", float(values[i]), text, unit))
    params.append(Param("g0", float(g0), "gravitational acceleration along -z of the base frame", "m/s^2"))
    return tuple(params)


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _dot(a, b):
    return sp.Add(*[x * y for x, y in zip(a, b)])


def _matvec(M, v):
    return [sp.Add(*[M[r][k] * v[k] for k in range(3)]) for r in range(3)]


def _matTvec(M, v):
    return [sp.Add(*[M[k][r] * v[k] for k in range(3)]) for r in range(3)]


def make_spatial(desc: ChainDescription, name: str, params: Tuple[Param, ...],
                 description: str, symbolic: Sequence[str] = ()) -> FlexibleJointModel:
    """Flexible-joint model of a spatial serial chain of revolute joints.

    Parameters
    ----------
    desc : ChainDescription
        Kinematics and inertials; numbers are baked into the model.
    name : str
        Model name (a C identifier).
    params : tuple of Param
        ``K1..Kn, Jm1..Jmn, Bm1..Bmn, g0`` (see :func:`elastic_params`),
        optionally followed by the payload (:func:`payload_params`), then by
        the inertial parameters of the ``symbolic`` links (:func:`inertial_params`).
    description : str
        One paragraph for the report and manifest.
    symbolic : sequence of str
        Links whose inertials are runtime parameters instead of baked numbers.

    Returns
    -------
    FlexibleJointModel
        ``D`` (n, n), ``h`` (n, 1) and the potential as symbols of its
        :class:`Program` (see the module docstring for the algorithms).
    """
    num = chain_numerics(desc, symbolic)
    n = len(num.bodies)
    expected = [f"{g}{i}" for g in ("K", "Jm", "Bm") for i in range(1, n + 1)] + ["g0"]
    inertial_names = [f"{f}_{link}" for link in symbolic for f, _, _ in INERTIAL_FIELDS]
    names = [p.name for p in params]
    payload = names[len(expected):len(expected) + len(PAYLOAD)] == list(PAYLOAD)
    if names != expected + (list(PAYLOAD) if payload else []) + inertial_names:
        raise ValueError(f"{name}: parameters must be {expected} (optionally followed by {list(PAYLOAD)}) "
                         f"and then {inertial_names}, got {names}")
    sym = {p.name: sp.Symbol(p.name, real=True) for p in params}
    g0 = sym["g0"]
    q, dq, qm, dqm = _state_symbols(n)
    prog = Program()

    def d(label: str, e):
        """Name ``e`` unless it is a single term (a symbol times constants costs nothing to repeat)."""
        e = sp.sympify(e)
        if e.is_Atom or (e.is_Mul and sum(1 for a in e.args if not a.is_Number) <= 1):
            return e
        return prog.define(label, e)

    def dvec(label: str, v):
        return [d(f"{label}{'xyz'[k]}", v[k]) for k in range(3)]

    # Joint trig with derivative rules, and the rotations R_i = R0_i Rz(q_i) (linear in c_i, s_i).
    cs: List[Tuple[sp.Expr, sp.Expr]] = []
    for i in range(n):
        box: Dict[str, sp.Expr] = {}
        box["c"] = prog.define(f"c{i + 1}", sp.cos(q[i]), rule=lambda dd, i=i, b=box: -b["s"] * dd(q[i]))
        box["s"] = prog.define(f"s{i + 1}", sp.sin(q[i]), rule=lambda dd, i=i, b=box: b["c"] * dd(q[i]))
        cs.append((box["c"], box["s"]))
    R: List[List[List[sp.Expr]]] = []
    P: List[List[sp.Expr]] = []
    for i, b in enumerate(num.bodies):
        c, s = cs[i]
        R0 = [[_num(b.R0[r, k]) for k in range(3)] for r in range(3)]
        Ri = [[d(f"R{i + 1}_{r + 1}1", R0[r][0] * c + R0[r][1] * s),
               d(f"R{i + 1}_{r + 1}2", R0[r][1] * c - R0[r][0] * s),
               R0[r][2]] for r in range(3)]
        R.append(Ri)
        P.append([_num(v) for v in b.p])
    mass = [_num(b.mass) for b in num.bodies]
    hmom = [[_num(v) for v in b.first_moment] for b in num.bodies]
    Io = [[[_num(b.inertia_origin[r, k]) for k in range(3)] for r in range(3)] for b in num.bodies]
    for link, k, Rl, pl, inertial in num.symbolic:  # inertials as parameters join their body
        ms = sym[f"m_{link}"]
        cl = [sym[f"c{a}_{link}"] for a in "xyz"]
        c = [d(f"cB_{link}_{'xyz'[r]}", sp.Add(*[_num(Rl[r, j]) * cl[j] for j in range(3)]) + _num(pl[r]))
             for r in range(3)]
        Rc = _snap(Rl @ rpy_matrix(inertial.rpy))
        i6 = [sym[f"i{a}_{link}"] for a in ("xx", "xy", "xz", "yy", "yz", "zz")]
        Ic = [[i6[0], i6[1], i6[2]], [i6[1], i6[3], i6[4]], [i6[2], i6[4], i6[5]]]
        RIc = [[sp.Add(*[_num(Rc[r, a]) * Ic[a][b] * _num(Rc[j, b]) for a in range(3) for b in range(3)])
                for j in range(3)] for r in range(3)]
        b = k - 1
        mass[b] = d(f"mb_{link}", mass[b] + ms)
        hmom[b] = [d(f"hb_{link}_{'xyz'[r]}", hmom[b][r] + ms * c[r]) for r in range(3)]
        cc = c[0] ** 2 + c[1] ** 2 + c[2] ** 2
        Io[b] = [[d(f"Iob_{link}_{r + 1}{j + 1}", Io[b][r][j] + RIc[r][j] + ms * ((cc if r == j else 0) - c[r] * c[j]))
                  if j >= r else None for j in range(3)] for r in range(3)]
        for r in range(3):
            for j in range(r):
                Io[b][r][j] = Io[b][j][r]
    if payload:  # a point mass m_load at c_load (tip link frame) joins the last body
        mp = sym["m_load"]
        c = [sp.Add(*[_num(num.tip_R[r, k]) * sym[f"{'xyz'[k]}_load"] for k in range(3)]) + _num(num.tip_p[r])
             for r in range(3)]
        c = [d(f"cload{'xyz'[r]}", c[r]) for r in range(3)]
        last = n - 1
        mass[last] = d("mlast", mass[last] + mp)
        hmom[last] = [d(f"hlast{'xyz'[r]}", hmom[last][r] + mp * c[r]) for r in range(3)]
        cc = c[0] ** 2 + c[1] ** 2 + c[2] ** 2
        Io[last] = [[d(f"Iolast{r + 1}{k + 1}", Io[last][r][k] + mp * ((cc if r == k else 0) - c[r] * c[k]))
                     if k >= r else None for k in range(3)] for r in range(3)]
        for r in range(3):
            for k in range(r):
                Io[last][r][k] = Io[last][k][r]

    # ---- h: recursive Newton-Euler, ddq = 0, base accelerated by +g0 e_z (gravity) --------
    zero = [sp.Integer(0)] * 3
    w_prev, dw_prev, a_prev = zero, zero, [sp.Integer(0), sp.Integer(0), g0]
    forces, moments = [], []
    for i in range(n):
        Ri, p = R[i], P[i]
        acc = [a_prev[k] + t for k, t in enumerate(_cross(dw_prev, p))]
        if any(v != 0 for v in w_prev):
            wxp = dvec(f"wp{i + 1}", _cross(w_prev, p))
            acc = [acc[k] + t for k, t in enumerate(_cross(w_prev, wxp))]
        acc = dvec(f"acc{i}_", acc)
        a_i = dvec(f"a{i + 1}", _matTvec(Ri, acc))
        wr = dvec(f"wr{i + 1}", _matTvec(Ri, w_prev))  # previous rate in this body's frame
        w_i = [wr[0], wr[1], d(f"w{i + 1}z", wr[2] + dq[i])]
        dwr = _matTvec(Ri, dw_prev)
        dw_i = dvec(f"dw{i + 1}", [dwr[0] + wr[1] * dq[i], dwr[1] - wr[0] * dq[i], dwr[2]])
        h_i, I_i, m_i = hmom[i], Io[i], mass[i]
        wxh = dvec(f"wh{i + 1}", _cross(w_i, h_i))
        f_i = [m_i * a_i[k] + t + u for k, (t, u) in enumerate(zip(_cross(dw_i, h_i), _cross(w_i, wxh)))]
        Iw = dvec(f"Iw{i + 1}", _matvec(I_i, w_i))
        n_i = [t + u + v for t, u, v in zip(_matvec(I_i, dw_i), _cross(w_i, Iw), _cross(h_i, a_i))]
        forces.append(dvec(f"fb{i + 1}", f_i))
        moments.append(dvec(f"nb{i + 1}", n_i))
        w_prev, dw_prev, a_prev = w_i, dw_i, a_i
    h = sp.zeros(n, 1)
    F, N = forces[-1], moments[-1]
    h[n - 1] = N[2]
    for i in reversed(range(n - 1)):
        RF = dvec(f"RF{i + 2}", _matvec(R[i + 1], F))
        RN = _matvec(R[i + 1], N)
        pxf = _cross(P[i + 1], RF)
        F = dvec(f"F{i + 1}", [forces[i][k] + RF[k] for k in range(3)])
        N = dvec(f"N{i + 1}", [moments[i][k] + RN[k] + pxf[k] for k in range(3)])
        h[i] = N[2]

    # ---- D: composite-rigid-body algorithm -------------------------------------------------
    # Composite inertia (m, h, I_o) of bodies i..n about the origin of B_i, in B_i.
    Dm = sp.zeros(n, n)
    cm, ch, cI = mass[n - 1], hmom[n - 1], Io[n - 1]
    composite = [None] * n
    composite[n - 1] = (cm, ch, cI)
    for i in reversed(range(n - 1)):
        Rn, p = R[i + 1], P[i + 1]
        c, s = cs[i + 1]
        # Rz(q) I Rz(q)^T, then the constant R0 (exact zeros/ones keep it sparse).
        A = cI
        cc, ss, csq = d(f"cc{i + 2}", c * c), d(f"ss{i + 2}", s * s), d(f"cs{i + 2}", c * s)
        B = [[None] * 3 for _ in range(3)]
        B[0][0] = cc * A[0][0] - 2 * csq * A[0][1] + ss * A[1][1]
        B[1][1] = ss * A[0][0] + 2 * csq * A[0][1] + cc * A[1][1]
        B[0][1] = B[1][0] = csq * (A[0][0] - A[1][1]) + (cc - ss) * A[0][1]
        B[0][2] = B[2][0] = c * A[0][2] - s * A[1][2]
        B[1][2] = B[2][1] = s * A[0][2] + c * A[1][2]
        B[2][2] = A[2][2]
        B = [[d(f"Bz{i + 2}_{r + 1}{k + 1}", B[r][k]) if k >= r else None for k in range(3)] for r in range(3)]
        for r in range(3):
            for k in range(r):
                B[r][k] = B[k][r]
        R0 = [[_num(num.bodies[i + 1].R0[r, k]) for k in range(3)] for r in range(3)]
        RIR = [[sp.Add(*[R0[r][a] * B[a][b] * R0[k][b] for a in range(3) for b in range(3)])
                for k in range(3)] for r in range(3)]
        hR = dvec(f"hR{i + 2}", _matvec(Rn, ch))
        pn = sum(float(v) ** 2 for v in num.bodies[i + 1].p)
        diag = d(f"hp{i + 2}", 2 * _dot(p, hR) + cm * _num(pn))
        I_new = [[Io[i][r][k] + RIR[r][k] + (diag if r == k else 0)
                  - (p[r] * hR[k] + hR[r] * p[k] + cm * p[r] * p[k]) for k in range(3)] for r in range(3)]
        cI = [[d(f"Ic{i + 1}_{r + 1}{k + 1}", I_new[r][k]) if k >= r else None for k in range(3)]
              for r in range(3)]
        for r in range(3):
            for k in range(r):
                cI[r][k] = cI[k][r]
        ch = dvec(f"hc{i + 1}", [hmom[i][k] + hR[k] + cm * p[k] for k in range(3)])
        cm = mass[i] + cm
        composite[i] = (cm, ch, cI)
    for i in range(n):
        _, hc, Ic = composite[i]
        nv = [Ic[0][2], Ic[1][2], Ic[2][2]]
        fv = [-hc[1], hc[0], sp.Integer(0)]  # e_z x ... : force of the unit joint rate, -h x e_z
        Dm[i, i] = Ic[2][2]
        for j in reversed(range(i)):
            Rn, p = R[j + 1], P[j + 1]
            fv2 = _matvec(Rn, fv)
            nv2 = [a + b for a, b in zip(_matvec(Rn, nv), _cross(p, fv2))]
            if j > 0:
                fv = dvec(f"cf{i + 1}_{j + 1}", fv2)
                nv = dvec(f"cn{i + 1}_{j + 1}", nv2)
                Dm[i, j] = Dm[j, i] = nv[2]
            else:
                Dm[i, j] = Dm[j, i] = d(f"D{i + 1}_{j + 1}", nv2[2])
    for i in range(n):  # name every entry (the derivations differentiate D entry by entry)
        for j in range(i + 1):
            e = Dm[i, j]
            if not e.is_Atom and e not in prog:
                Dm[i, j] = Dm[j, i] = prog.define(f"Dm{i + 1}_{j + 1}", e)

    # ---- potential: g0 times the height of every centre of mass ----------------------------
    zrow, zpos = [sp.Integer(0), sp.Integer(0), sp.Integer(1)], sp.Integer(0)
    V = sp.Integer(0)
    for i in range(n):
        zpos = d(f"zo{i + 1}", zpos + _dot(zrow, P[i]))
        zrow = dvec(f"zr{i + 1}", [sp.Add(*[zrow[k] * R[i][k][c] for k in range(3)]) for c in range(3)])
        V += mass[i] * zpos + _dot(zrow, hmom[i])
    V = g0 * d("Vg", V)

    return FlexibleJointModel(
        name=name, n=n, params=tuple(params), q=q, dq=dq, qm=qm, dqm=dqm,
        D=Dm, h=h, potential=V,
        K=tuple(sym[f"K{i}"] for i in range(1, n + 1)),
        Jm=tuple(sym[f"Jm{i}"] for i in range(1, n + 1)),
        Bm=tuple(sym[f"Bm{i}"] for i in range(1, n + 1)),
        description=description, program=prog,
    )


def make_spatial_jacobian(desc: ChainDescription, name: str, params: Tuple[Param, ...],
                          description: str) -> FlexibleJointModel:
    """The same model in the Jacobian (Lagrangian) form, kept for comparison and cross-checks.

    World-frame kinematics (rotations ``W_k``, origins ``o_k``, axes ``z_k``,
    centres of mass ``c_k``) as named symbols;
    ``D = sum_k m_k Jv_k^T Jv_k + Jw_k^T (W_k Ic_k W_k^T) Jw_k`` with
    ``Jv_k[:, j] = z_j x (c_k - o_j)``, ``Jw_k[:, j] = z_j`` (j <= k); and
    ``h = D' dq - 1/2 d/dq (dq^T D dq) + dV/dq`` by directional derivatives
    of D. :func:`make_spatial` (CRBA + RNEA) is the emitted form: see
    docs/spatial.md for the operation counts of both.
    """
    from .lie import DirectionalDerivative

    if any(p.name in PAYLOAD for p in params):
        raise ValueError(f"{name}: the Jacobian form takes no payload parameters")
    base = make_spatial(desc, name, params, description)  # for the parameters and state symbols
    num = chain_numerics(desc)
    n = base.n
    prog = Program()
    q, dq = base.q, base.dq
    g0 = sp.Symbol("g0", real=True)

    def d(label, e):
        e = sp.sympify(e)
        if e.is_Atom or (e.is_Mul and sum(1 for a in e.args if not a.is_Number) <= 1):
            return e
        return prog.define(label, e)

    cs = []
    for i in range(n):
        box: Dict[str, sp.Expr] = {}
        box["c"] = prog.define(f"c{i + 1}", sp.cos(q[i]), rule=lambda dd, i=i, b=box: -b["s"] * dd(q[i]))
        box["s"] = prog.define(f"s{i + 1}", sp.sin(q[i]), rule=lambda dd, i=i, b=box: b["c"] * dd(q[i]))
        cs.append((box["c"], box["s"]))
    W = [[sp.Integer(int(r == k)) for k in range(3)] for r in range(3)]
    o = [sp.Integer(0)] * 3
    zs, os_, cms, Iws = [], [], [], []
    for i, b in enumerate(num.bodies):
        c, s = cs[i]
        R0 = [[_num(b.R0[r, k]) for k in range(3)] for r in range(3)]
        Ri = [[R0[r][0] * c + R0[r][1] * s, R0[r][1] * c - R0[r][0] * s, R0[r][2]] for r in range(3)]
        o = [d(f"o{i + 1}{'xyz'[r]}", o[r] + sp.Add(*[W[r][k] * _num(b.p[k]) for k in range(3)])) for r in range(3)]
        W = [[d(f"W{i + 1}_{r + 1}{k + 1}", sp.Add(*[W[r][a] * Ri[a][k] for a in range(3)])) for k in range(3)]
             for r in range(3)]
        com = b.first_moment / b.mass
        cms.append([d(f"cm{i + 1}{'xyz'[r]}", o[r] + sp.Add(*[W[r][k] * _num(com[k]) for k in range(3)]))
                    for r in range(3)])
        Ic = b.inertia_origin - b.mass * (float(com @ com) * np.eye(3) - np.outer(com, com))
        WI = [[sp.Add(*[W[r][a] * _num(Ic[a, k]) for a in range(3)]) for k in range(3)] for r in range(3)]
        Iws.append([[d(f"Iw{i + 1}_{r + 1}{k + 1}", sp.Add(*[WI[r][a] * W[k][a] for a in range(3)]))
                     if k >= r else None for k in range(3)] for r in range(3)])
        for r in range(3):
            for k in range(r):
                Iws[-1][r][k] = Iws[-1][k][r]
        zs.append([W[r][2] for r in range(3)])
        os_.append(o)
    D = sp.zeros(n, n)
    for k in range(n):
        m = _num(num.bodies[k].mass)
        Jv = [dvec for dvec in ([d(f"Jv{k + 1}_{j + 1}{'xyz'[r]}", e) for r, e in enumerate(
            _cross(zs[j], [cms[k][a] - os_[j][a] for a in range(3)]))] for j in range(k + 1))]
        for a in range(k + 1):
            Iz = _matvec(Iws[k], zs[a])
            for b_ in range(a + 1):
                D[a, b_] += m * _dot(Jv[a], Jv[b_]) + _dot(zs[b_], Iz)
    for a in range(n):
        for b_ in range(a + 1):
            D[a, b_] = D[b_, a] = prog.define(f"Dj{a + 1}_{b_ + 1}", D[a, b_])
    V = g0 * d("Vj", sp.Add(*[_num(num.bodies[k].mass) * cms[k][2] for k in range(n)]))
    dt = DirectionalDerivative({q[i]: dq[i] for i in range(n)}, program=prog, tag="jt")
    Ddot = dt(D)
    dqv = sp.Matrix(dq)
    h = Ddot * dqv
    for i in range(n):
        di = DirectionalDerivative({q[i]: sp.Integer(1)}, program=prog, tag=f"jq{i + 1}")
        h[i] = prog.define(f"hj{i + 1}", h[i] - (dqv.T * di(D) * dqv)[0, 0] / 2 + di(V))
    from dataclasses import replace
    return replace(base, D=D, h=h, potential=V, program=prog)
