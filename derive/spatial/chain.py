"""URDF-free description of a serial chain, and its build-time numbers (floats).

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

:mod:`derive.spatial.urdf` reads a URDF into a :class:`ChainDescription`,
:func:`planar_description` states ``planar<n>`` as one, and
:mod:`derive.spatial.spatial` turns one into symbolic dynamics. Pure data and
numerics: no I/O, no SymPy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

__all__ = ["Inertial", "Joint", "Attached", "ChainDescription", "BodyNumerics", "ChainNumerics",
           "rpy_matrix", "snap", "chain_numerics", "planar_description", "SNAP", "Vec3"]

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
    parent : str or None
        Parent link name; None: the previous joint's child (the base for the
        first joint), i.e. a serial path. A tree names it (it must be the base
        or the child of an earlier joint).
    """

    name: str
    kind: str
    xyz: Vec3
    rpy: Vec3
    axis: Vec3
    child: str
    inertial: Optional[Inertial] = None
    parent: Optional[str] = None


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
    """Kinematic and inertial description of a serial chain or a tree (URDF conventions).

    Attributes
    ----------
    base : str
        Base link name; fixed; gravity acts along -z of its frame.
    joints : tuple of Joint
        Path from the base to the tip, in order; for a tree (joints naming
        their ``parent``), every parent comes before its children, and q
        follows this order (see :func:`derive.spatial.urdf.parse_urdf`: depth-first,
        tips in the order listed, shared joints first).
    attached : tuple of Attached
        Links rigidly fixed to path links but not on the path.
    tips : tuple of str
        The tip links of a tree (several); empty for a serial path.
    """

    base: str
    joints: Tuple[Joint, ...]
    attached: Tuple[Attached, ...] = ()
    tips: Tuple[str, ...] = ()

    @property
    def revolute_names(self) -> Tuple[str, ...]:
        """Names of the revolute joints in q order."""
        return tuple(j.name for j in self.joints if j.kind == "revolute")


# --------------------------------------------------------------------------------------------
# Build-time numerics (floats)
# --------------------------------------------------------------------------------------------

# 3-vectors and 3x3 matrices are combined in plain Python floats, left to right: numpy's ``@``
# goes through BLAS, whose kernel (FMA or not, summation order) depends on the processor and
# changes the last bit of the baked numbers, and generated/ must be byte-identical everywhere.

def mm(A, B) -> np.ndarray:
    """``A @ B`` for 3x3 matrices, in a fixed order of float operations."""
    return np.array([[float(A[r][0]) * float(B[0][k]) + float(A[r][1]) * float(B[1][k])
                      + float(A[r][2]) * float(B[2][k]) for k in range(3)] for r in range(3)])


def mv(A, v) -> np.ndarray:
    """``A @ v`` for a 3x3 matrix and a 3-vector, in a fixed order of float operations."""
    return np.array([float(A[r][0]) * float(v[0]) + float(A[r][1]) * float(v[1]) + float(A[r][2]) * float(v[2])
                     for r in range(3)])


def dot(a, b) -> float:
    """``a . b`` for 3-vectors, in a fixed order of float operations."""
    return float(a[0]) * float(b[0]) + float(a[1]) * float(b[1]) + float(a[2]) * float(b[2])


def outer(a, b) -> np.ndarray:
    """``a b^T`` for 3-vectors."""
    return np.array([[float(a[r]) * float(b[k]) for k in range(3)] for r in range(3)])


def snap(M: np.ndarray) -> np.ndarray:
    """A float copy of ``M`` with entries within :data:`SNAP` of 0, 1 or -1 made exact."""
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
    return snap(mm(mm(snap(Rz), snap(Ry)), snap(Rx)))


def _axis_frame(axis: Sequence[float]) -> np.ndarray:
    """A rotation ``Ra`` with ``Ra e_z = axis`` (exact for the coordinate axes)."""
    a = np.asarray(axis, float)
    a = a / math.sqrt(dot(a, a))
    a = snap(a)
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
    s, c = math.sqrt(dot(k, k)), a[2]
    k = k / s
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return snap(np.eye(3) + s * Kx + (1 - c) * mm(Kx, Kx))


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
    """All build-time numbers of a chain: one :class:`BodyNumerics` per revolute joint.

    ``parents[i]`` is the index of body ``i``'s parent body (-1: the base);
    ``parents[i] < i``. A serial path has ``parents[i] = i - 1``; body ``i``'s
    ``R0`` and ``p`` are relative to its parent body's frame.
    """

    joint_names: Tuple[str, ...]
    bodies: Tuple[BodyNumerics, ...] = field(default_factory=tuple)
    parents: Tuple[int, ...] = ()
    #: Pose of the tip link frame in the last body frame: rotation (3, 3) and origin (3,).
    tip_R: np.ndarray = field(default_factory=lambda: np.eye(3))
    tip_p: np.ndarray = field(default_factory=lambda: np.zeros(3))
    #: Links with symbolic inertials: (link, body index 1..n, R, p of the link frame in the body frame, Inertial).
    symbolic: Tuple[tuple, ...] = ()




def _inertia_matrix(i6: Sequence[float]) -> np.ndarray:
    ixx, ixy, ixz, iyy, iyz, izz = (float(v) for v in i6)
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


#: A rigid piece of a body: (body index, R, p of the link frame in B_body, inertial, link name).
Piece = Tuple[int, np.ndarray, np.ndarray, Optional[Inertial], str]
#: Pose of a link frame in its body frame: (body index, R, p); body 0 is the base.
Pose = Tuple[int, np.ndarray, np.ndarray]


def _walk_path(desc: ChainDescription) -> Tuple[Dict[str, Pose], List[dict], List[Piece], str]:
    """Poses of the path links, one body per revolute joint, and the path links as pieces."""
    pose: Dict[str, Pose] = {desc.base: (0, np.eye(3), np.zeros(3))}
    bodies: List[dict] = []
    pieces: List[Piece] = []
    parent = desc.base
    for j in desc.joints:
        parent = parent if j.parent is None else j.parent
        if parent not in pose:
            raise ValueError(f"joint {j.name!r}: parent link {parent!r} is neither the base nor the child of an "
                             "earlier joint; expected the joints in tree order (parents first)")
        k, R, p = pose[parent]
        Ro, po = mm(R, rpy_matrix(j.rpy)), p + mv(R, j.xyz)
        if j.kind == "revolute":
            Ra = _axis_frame(j.axis)
            bodies.append({"R0": snap(mm(Ro, Ra)), "p": po, "parent": k - 1})
            k, R, p = len(bodies), Ra.T.copy(), np.zeros(3)  # child link frame in the new body frame
        elif j.kind == "fixed":
            R, p = snap(Ro), po
        else:
            raise ValueError(f"joint {j.name!r}: kind {j.kind!r}; expected 'revolute' or 'fixed'")
        pose[j.child] = (k, R, p)
        pieces.append((k, R, p, j.inertial, j.child))
        parent = j.child
    if not bodies:
        raise ValueError("the chain has no revolute joint")
    return pose, bodies, pieces, parent


def _attached_pieces(desc: ChainDescription, pose: Dict[str, Pose]) -> List[Piece]:
    """The attached links as pieces of the bodies their parents belong to."""
    pieces: List[Piece] = []
    for a in desc.attached:
        if a.parent not in pose:
            raise ValueError(f"attached link {a.name!r}: parent {a.parent!r} is not on the chain")
        k, R, p = pose[a.parent]
        for xyz, rpy in a.origins:
            R, p = snap(mm(R, rpy_matrix(rpy))), p + mv(R, xyz)
        pieces.append((k, R, p, a.inertial, a.name))
    return pieces


def chain_numerics(desc: ChainDescription, symbolic: Sequence[str] = ()) -> ChainNumerics:
    """Merge fixed joints and attached links; align body frames with the joint axes (path or tree).

    Parameters
    ----------
    desc : ChainDescription
    symbolic : sequence of str
        Links whose inertial is left out of the numeric sums (it becomes
        runtime parameters, see :func:`derive.spatial.spatial.make_spatial`); their
        poses are in :attr:`ChainNumerics.symbolic`.

    Returns
    -------
    ChainNumerics
        One body per revolute joint, in q order, with its parent body index.

    Raises
    ------
    ValueError
        If the chain has no revolute joint, a joint kind is unknown, a joint's
        parent link comes later, or an attached link names a parent that is
        not on the chain.
    """
    pose, bodies, pieces, parent = _walk_path(desc)
    pieces += _attached_pieces(desc, pose)

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
        Rc = snap(mm(R, rpy_matrix(inertial.rpy)))
        c = p + mv(R, inertial.xyz)
        m = float(inertial.mass)
        Ic = mm(mm(Rc, _inertia_matrix(inertial.inertia)), Rc.T)
        mass[k] += m
        first[k] = first[k] + m * c
        inert[k] = inert[k] + Ic + m * (dot(c, c) * np.eye(3) - outer(c, c))
    out = tuple(BodyNumerics(R0=b["R0"], p=b["p"], mass=mass[i + 1], first_moment=first[i + 1],
                             inertia_origin=(inert[i + 1] + inert[i + 1].T) / 2)
                for i, b in enumerate(bodies))
    missing = [k for k in symbolic if k not in sym_pieces]
    if missing:
        raise ValueError(f"symbolic inertial of link(s) {missing}: not a link of the chain "
                         f"(expected among {[pc[4] for pc in pieces if pc[0] > 0 and pc[3] is not None]})")
    tip_k, tip_R, tip_p = pose[parent]
    parents = tuple(b["parent"] for b in bodies)
    assert desc.tips or tip_k == len(bodies)
    return ChainNumerics(joint_names=desc.revolute_names, bodies=out, parents=parents, tip_R=tip_R, tip_p=tip_p,
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

