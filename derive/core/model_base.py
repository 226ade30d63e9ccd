"""The model contract: :class:`Param`, :class:`FlexibleJointModel`, state symbols, parameter names.

Every model is the flexible-joint system of docs/design.md ("The model")::

    D(q) ddq + h(q, dq) + K (q - q_m) = 0,        h = C(q, dq) dq + G(q)
    J_m ddq_m + B_m dq_m - K (q - q_m) = u         (K, J_m, B_m diagonal)

with state ``x = [q; dq; q_m; dq_m]`` (four blocks of ``n``). A model supplies
the symbolic pieces (D, h, the diagonals of K, J_m, B_m) and a parameter table.
The builders live in :mod:`derive.planar.planar` (``link1``, ``planar<n>``) and
:mod:`derive.spatial.spatial` (URDF arms); :mod:`derive.registry` maps names to them.
This module is pure data and math: no I/O, no printing.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

import sympy as sp

from .program import Program

__all__ = ["Param", "RigidBody", "FlexibleJointModel", "state_symbols", "PLANAR_GROUPS", "ELASTIC_GROUPS",
           "planar_param_names", "elastic_param_names", "param_group", "coriolis_gravity",
           "SPATIAL_NAMES", "MODEL_NAMES", "COMPLETE_NAMES", "SPRING_NAMES"]

#: Built-in spatial arms: each is the URDF model file ``derive/robots/<name>/<name>.toml``.
SPATIAL_NAMES: Tuple[str, ...] = ("elbow3", "panda", "baxter")

#: Names of the built-in models (:func:`derive.registry.build` builds each one).
#: Built-in complete models (rotor gyroscopics, docs/complete-model.md) and their reduced models.
COMPLETE_NAMES: Tuple[str, ...] = ("link1_complete", "planar2_complete", "panda_complete")

#: Built-in models with nonlinear joint springs (:mod:`derive.core.spring`).
SPRING_NAMES: Tuple[str, ...] = ("link1_hd", "arm1_hd", "panda_hd")

MODEL_NAMES: Tuple[str, ...] = (("link1",) + tuple(f"planar{n}" for n in range(1, 8)) + SPATIAL_NAMES
                                + COMPLETE_NAMES + SPRING_NAMES)

#: Per-link parameter groups of ``planar<n>``, in ``param_names`` order (then ``g0``).
PLANAR_GROUPS: Tuple[str, ...] = ("m", "l", "r", "I", "K", "Jm", "Bm")

#: Per-joint parameter groups of a spatial chain, in ``param_names`` order (then ``g0``).
ELASTIC_GROUPS: Tuple[str, ...] = ("K", "Jm", "Bm")


@dataclass(frozen=True)
class Param:
    """One model parameter: symbol name, default value, meaning and SI unit."""

    name: str
    default: float
    meaning: str
    unit: str


@dataclass(frozen=True)
class RigidBody:
    """One moving body of a spatial chain or tree, as the emitter's time-derivative recursion needs it.

    Body ``i`` turns about the z axis of its frame ``B_i``; its rotation to the parent frame is
    ``R0 Rz(q_i)`` and its origin in the parent frame is ``p`` (:mod:`derive.spatial.spatial`).

    Attributes
    ----------
    parent : int
        Index of the parent body (-1: the base); less than this body's index.
    R0 : tuple of tuple of float, shape (3, 3)
        Constant rotation from ``B_i`` at ``q_i = 0`` to the parent frame.
    p : tuple of float, shape (3,)
        Origin of ``B_i`` in the parent frame (m).
    mass : sympy.Expr
        Mass (kg): a number, or a programme symbol when the body carries parameters (payload,
        symbolic inertials).
    first_moment : tuple of sympy.Expr, shape (3,)
        ``m c`` in ``B_i`` (kg m).
    inertia : tuple of tuple of sympy.Expr, shape (3, 3)
        Rotational inertia about the origin of ``B_i``, in ``B_i`` (kg m^2), symmetric.
    """

    parent: int
    R0: Tuple[Tuple[float, float, float], ...]
    p: Tuple[float, float, float]
    mass: sp.Expr
    first_moment: Tuple[sp.Expr, sp.Expr, sp.Expr]
    inertia: Tuple[Tuple[sp.Expr, sp.Expr, sp.Expr], ...]


@dataclass(frozen=True)
class FlexibleJointModel:
    """Symbolic flexible-joint model.

    Attributes
    ----------
    name : str
        Registry name, e.g. ``"link1"`` or ``"planar3"``.
    n : int
        Number of links (and motors).
    params : tuple of Param
        Parameter table, in argument order.
    q, dq, qm, dqm : tuple of sympy.Symbol
        State symbols, each of length ``n``.
    D : sympy.Matrix, shape (n, n)
        Link inertia matrix D(q), symmetric positive definite.
    h : sympy.Matrix, shape (n, 1)
        Coriolis/centrifugal plus gravity, ``C(q, dq) dq + G(q)``.
    potential : sympy.Expr
        Gravitational potential energy of the links (used by the energy test).
    K, Jm, Bm : tuple of sympy.Expr
        Diagonals of the stiffness, motor inertia and motor damping matrices.
    description : str
        One paragraph for the report and manifest.
    program : Program
        Named intermediate symbols used by D, h and the potential (empty for
        small models). Derivations append their own derivative symbols.
    source : dict or None
        Where a model built from a URDF comes from (``urdf`` path relative to
        the repository root, its ``sha256``, ``base``, ``tip``, ``joints`` in q
        order, ``limits``: the URDF's ``<limit>`` per joint); recorded in the
        manifest. None for the built-in formulas.
    coupling : sympy.Matrix, shape (n, n), or None
        Complete model only (docs/complete-model.md): the rotor spin coupling
        ``S(q)`` of the inertia matrix ``[[D, S], [S^T, J_m]]``; ``h`` then
        also holds the rotors' gyroscopic moments (it depends on ``dq_m``).
        None for the reduced model.
    motor_bias : sympy.Matrix, shape (n, 1), or None
        Complete model only: the velocity terms ``(dS/dt)^T dq`` of the motor equations.
    reduced_model : str or None
        Complete model only: the name of the reduced model with the same state layout.
    rotors : derive.core.rotors.Rotors or None
        Complete model only: the rotor data (gear-ratio defaults, masses, transverse inertias).
    inverse_dynamics : (tuple of sympy.Symbol, sympy.Matrix) or None
        ``(ddq, tau)``: the joint-acceleration symbols (length n) and
        ``tau(q, dq, ddq) = D ddq + h`` (n, 1) as one straight-line programme (RNEA with the
        acceleration as an input) in ``program``. None: the emitter forms ``D ddq + h``.
    bodies : tuple of RigidBody or None
        Reduced spatial models: the chain's (or tree's) bodies in q order, for the emitter's
        Taylor recursion of the RNEA (:mod:`derive.emit.rnea_jets`). None for the planar closed
        forms and the complete models.
    springs : tuple of derive.core.spring.CubicSpring or None
        Nonlinear joint springs ``tau_J = psi(q_m - q)`` (:mod:`derive.core.spring`), one per joint;
        ``K`` then holds each ``psi'(0)``. None: the linear springs ``K (q_m - q)``.
    frictions : tuple of derive.core.friction.MotorFriction or None
        Nonlinear-spring models only: Coulomb and Stribeck motor friction ``F(dq_m)`` per joint,
        beside the viscous ``B_m`` (:mod:`derive.core.friction`). None: viscous damping only.
    robot_facts : dict or None
        The manifest entries ``limits`` and ``task`` a model file states (over its URDF's limits;
        :mod:`derive.model_file.robot_facts`). None: the model states neither.
    urdf_file : str or None
        URDF-built models: the URDF file read (absolute path, build time only: chain.json re-reads it;
        never written). None: a built-in formula, or the URDF is found from ``source["urdf"]``.
    """

    name: str
    n: int
    params: Tuple[Param, ...]
    q: Tuple[sp.Symbol, ...]
    dq: Tuple[sp.Symbol, ...]
    qm: Tuple[sp.Symbol, ...]
    dqm: Tuple[sp.Symbol, ...]
    D: sp.Matrix
    h: sp.Matrix
    potential: sp.Expr
    K: Tuple[sp.Expr, ...]
    Jm: Tuple[sp.Expr, ...]
    Bm: Tuple[sp.Expr, ...]
    description: str
    program: Program = field(default_factory=Program)
    source: Optional[Dict[str, object]] = None
    coupling: Optional[sp.Matrix] = None
    motor_bias: Optional[sp.Matrix] = None
    reduced_model: Optional[str] = None
    rotors: Optional[object] = None  # complete model: its derive.core.rotors.Rotors (for chain.json)
    inverse_dynamics: Optional[Tuple[Tuple[sp.Symbol, ...], sp.Matrix]] = None
    bodies: Optional[Tuple[RigidBody, ...]] = None
    springs: Optional[Tuple[object, ...]] = None  # nonlinear springs: derive.core.spring.CubicSpring per joint
    frictions: Optional[Tuple[object, ...]] = None  # motor friction: derive.core.friction.MotorFriction per joint
    robot_facts: Optional[Dict[str, object]] = None
    urdf_file: Optional[str] = None

    @property
    def state(self) -> Tuple[sp.Symbol, ...]:
        """All 4n state symbols in the order ``[q, dq, q_m, dq_m]``."""
        return self.q + self.dq + self.qm + self.dqm

    @property
    def param_symbols(self) -> Tuple[sp.Symbol, ...]:
        """Parameter symbols in argument order."""
        return tuple(sp.Symbol(p.name, real=True) for p in self.params)

    @property
    def param_names(self) -> Tuple[str, ...]:
        return tuple(p.name for p in self.params)


def state_symbols(n: int) -> Tuple[Tuple[sp.Symbol, ...], ...]:
    """The state symbols ``(q1..qn), (dq1..dqn), (qm1..qmn), (dqm1..dqmn)`` (real).

    Parameters
    ----------
    n : int
        Number of joints.

    Returns
    -------
    tuple of 4 tuples of sympy.Symbol, each of length n
    """
    def block(prefix: str) -> Tuple[sp.Symbol, ...]:
        return tuple(sp.Symbol(f"{prefix}{i + 1}", real=True) for i in range(n))

    return block("q"), block("dq"), block("qm"), block("dqm")


def planar_param_names(n: int) -> List[str]:
    """``m1..mn, l1..ln, r1..rn, I1..In, K1..Kn, Jm1..Jmn, Bm1..Bmn, g0`` (the ``planar<n>`` order)."""
    return [f"{g}{i}" for g in PLANAR_GROUPS for i in range(1, n + 1)] + ["g0"]


def elastic_param_names(n: int) -> List[str]:
    """``K1..Kn, Jm1..Jmn, Bm1..Bmn, g0`` (the leading parameters of a spatial chain)."""
    return [f"{g}{i}" for g in ELASTIC_GROUPS for i in range(1, n + 1)] + ["g0"]


def param_group(name: str) -> str:
    """The group of a parameter name: ``"Jm3" -> "Jm"``, ``"g0" -> "g0"``."""
    return "g0" if name == "g0" else name.rstrip("0123456789")


def coriolis_gravity(D: sp.Matrix, V: sp.Expr, q, dq) -> sp.Matrix:
    """``C(q, dq) dq + G(q)`` from the inertia matrix and the potential.

    Uses ``C dq = D' dq - 1/2 d/dq (dq^T D dq)`` (Lagrange's equations), which
    avoids forming the Christoffel symbols one by one.

    Parameters
    ----------
    D : sympy.Matrix, shape (n, n)
    V : sympy.Expr
        Potential energy.
    q, dq : sequence of sympy.Symbol, length n

    Returns
    -------
    sympy.Matrix, shape (n, 1)
    """
    n = len(q)
    dqv = sp.Matrix(dq)
    dD = [D.diff(qk) for qk in q]  # dD/dq_k, n matrices (n, n)
    Ddot = sp.zeros(n, n)
    for k in range(n):
        Ddot += dD[k] * dq[k]
    h = Ddot * dqv
    for i in range(n):
        h[i] -= sp.Rational(1, 2) * (dqv.T * dD[i] * dqv)[0, 0]
        h[i] += sp.diff(V, q[i])
    return h
