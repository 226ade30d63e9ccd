"""Model registry: symbolic dynamics of flexible-joint arms.

Every model is the flexible-joint system of DESIGN.md section 2::

    D(q) ddq + h(q, dq) + K (q - q_m) = 0,        h = C(q, dq) dq + G(q)
    J_m ddq_m + B_m dq_m - K (q - q_m) = u         (K, J_m, B_m diagonal)

with state ``x = [q; dq; q_m; dq_m]`` (four blocks of ``n``). A model supplies
the symbolic pieces (D, h, the diagonals of K, J_m, B_m) and a parameter table.
This module is pure math: no I/O, no printing.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable, Dict, List, Tuple

import sympy as sp


@dataclass(frozen=True)
class Param:
    """One model parameter: symbol name, default value, meaning and SI unit."""

    name: str
    default: float
    meaning: str
    unit: str


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


def _state_symbols(n: int) -> Tuple[Tuple[sp.Symbol, ...], ...]:
    def block(prefix: str) -> Tuple[sp.Symbol, ...]:
        return tuple(sp.Symbol(f"{prefix}{i + 1}", real=True) for i in range(n))

    return block("q"), block("dq"), block("qm"), block("dqm")


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


def make_link1() -> FlexibleJointModel:
    """The paper's single flexible joint, eq (3), plus optional motor damping ``B_m``."""
    params = (
        Param("J_l", 1.0, "link inertia about the joint axis", "kg m^2"),
        Param("J_m", 2.0, "motor (rotor) inertia", "kg m^2"),
        Param("K", 150.0, "joint stiffness (paper: 100..200)", "N m/rad"),
        Param("M", 1.0, "link mass", "kg"),
        Param("g0", 9.8, "gravitational acceleration", "m/s^2"),
        Param("L", 1.0, "distance joint -> link centre of mass", "m"),
        Param("B_m", 0.0, "motor viscous damping", "N m s/rad"),
    )
    (q,), (dq,), (qm,), (dqm,) = (tuple(b) for b in _state_symbols(1))
    J_l, J_m, K, M, g0, L, B_m = (sp.Symbol(p.name, real=True) for p in params)
    V = -M * g0 * L * sp.cos(q)  # q = 0 hangs down
    D = sp.Matrix([[J_l]])
    h = sp.Matrix([M * g0 * L * sp.sin(q)])
    return FlexibleJointModel(
        name="link1", n=1, params=params,
        q=(q,), dq=(dq,), qm=(qm,), dqm=(dqm,),
        D=D, h=h, potential=V, K=(K,), Jm=(J_m,), Bm=(B_m,),
        description=(
            "Single-link flexible joint of the paper (eq 3): "
            "J_l q'' + M g0 L sin(q) + K (q - q_m) = 0, "
            "J_m q_m'' + B_m q_m' - K (q - q_m) = u."
        ),
    )


def make_planar(n: int) -> FlexibleJointModel:
    """Planar serial chain of ``n`` flexible joints with relative angles.

    q = 0 hangs straight down, gravity ``g0`` acts along -y. Link i has mass
    ``m_i``, length ``l_i``, centre of mass at ``r_i`` from its joint and
    inertia ``I_i`` about its centre of mass.

    The inertia matrix is built in closed form (DESIGN.md section 5): with
    absolute angles ``theta = S q`` (``S`` lower-triangular ones),
    ``D = S^T M(theta) S`` where
    ``M_jk = cos(theta_j - theta_k) sum_{i >= max(j,k)} m_i c_ij c_ik + delta_jk I_j``
    and ``c_ij = l_j`` for ``j < i``, ``r_i`` for ``j = i``.
    """
    if not 1 <= n <= 7:
        raise ValueError(f"planar<n>: n must be in 1..7, got {n}")
    idx = range(1, n + 1)
    groups = [
        ("m", 1.0, "mass of link {i}", "kg"),
        ("l", 1.0, "length of link {i}", "m"),
        ("r", 0.5, "joint {i} -> centre of mass of link {i}", "m"),
        ("I", 0.1, "inertia of link {i} about its centre of mass", "kg m^2"),
        ("K", 150.0, "stiffness of joint {i}", "N m/rad"),
        ("Jm", 2.0, "inertia of motor {i}", "kg m^2"),
        ("Bm", 0.0, "viscous damping of motor {i}", "N m s/rad"),
    ]
    params = tuple(
        Param(f"{g}{i}", d, meaning.format(i=i), unit) for g, d, meaning, unit in groups for i in idx
    ) + (Param("g0", 9.8, "gravitational acceleration", "m/s^2"),)
    sym = {p.name: sp.Symbol(p.name, real=True) for p in params}
    m = [sym[f"m{i}"] for i in idx]
    l = [sym[f"l{i}"] for i in idx]
    r = [sym[f"r{i}"] for i in idx]
    inertia = [sym[f"I{i}"] for i in idx]
    g0 = sym["g0"]
    q, dq, qm, dqm = _state_symbols(n)

    def rel(j: int, k: int) -> sp.Expr:  # theta_j - theta_k for j >= k (0-based)
        return sp.Add(*q[k + 1: j + 1])

    def c(i: int, j: int) -> sp.Expr:  # lever of link i's CoM velocity on absolute rate j
        return l[j] if j < i else (r[i] if j == i else sp.Integer(0))

    Mabs = sp.zeros(n, n)
    for j in range(n):
        for k in range(j + 1):
            coeff = sp.Add(*[m[i] * c(i, j) * c(i, k) for i in range(j, n)])
            Mabs[j, k] = coeff * sp.cos(rel(j, k))
            Mabs[k, j] = Mabs[j, k]
        Mabs[j, j] += inertia[j]
    S = sp.Matrix(n, n, lambda i, j: 1 if j <= i else 0)
    D = S.T * Mabs * S

    theta = [sp.Add(*q[: i + 1]) for i in range(n)]
    height = [  # y coordinate of the centre of mass of link i
        -sp.Add(*[l[j] * sp.cos(theta[j]) for j in range(i)]) - r[i] * sp.cos(theta[i])
        for i in range(n)
    ]
    V = sp.Add(*[m[i] * g0 * height[i] for i in range(n)])
    h = coriolis_gravity(D, V, q, dq)
    return FlexibleJointModel(
        name=f"planar{n}", n=n, params=params, q=q, dq=dq, qm=qm, dqm=dqm,
        D=D, h=h, potential=V,
        K=tuple(sym[f"K{i}"] for i in idx),
        Jm=tuple(sym[f"Jm{i}"] for i in idx),
        Bm=tuple(sym[f"Bm{i}"] for i in idx),
        description=(
            f"Planar serial chain of {n} link(s) with flexible joints, relative joint "
            "angles, q = 0 hanging straight down, gravity g0 along -y."
        ),
    )


MODEL_NAMES: Tuple[str, ...] = ("link1",) + tuple(f"planar{n}" for n in range(1, 8))


def build(name: str) -> FlexibleJointModel:
    """Build a registered model by name.

    Raises
    ------
    ValueError
        If ``name`` is not registered; the message lists the available models.
    """
    if name == "link1":
        return make_link1()
    match = re.fullmatch(r"planar([1-7])", name or "")
    if match:
        return make_planar(int(match.group(1)))
    raise ValueError(f"unknown model {name!r}; available models: {', '.join(MODEL_NAMES)}")
