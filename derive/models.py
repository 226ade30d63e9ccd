"""Model registry: symbolic dynamics of flexible-joint arms.

Every model is the flexible-joint system of docs/design.md ("The model")::

    D(q) ddq + h(q, dq) + K (q - q_m) = 0,        h = C(q, dq) dq + G(q)
    J_m ddq_m + B_m dq_m - K (q - q_m) = u         (K, J_m, B_m diagonal)

with state ``x = [q; dq; q_m; dq_m]`` (four blocks of ``n``). A model supplies
the symbolic pieces (D, h, the diagonals of K, J_m, B_m) and a parameter table.
This module is pure math: no I/O, no printing.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Optional, Tuple

import sympy as sp

from .program import Program


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
    program : Program
        Named intermediate symbols used by D, h and the potential (empty for
        small models). Derivations append their own derivative symbols.
    source : dict or None
        Where a model built from a URDF comes from (``urdf`` path relative to
        the repository root, its ``sha256``, ``base``, ``tip``, ``joints`` in q
        order); recorded in the manifest. None for the built-in formulas.
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


def make_planar(n: int, name: str = None, defaults: Dict[str, float] = None,
                description: str = None) -> FlexibleJointModel:
    """Planar serial chain of ``n`` flexible joints with relative angles.

    q = 0 hangs straight down, gravity ``g0`` acts along -y. Link i has mass
    ``m_i``, length ``l_i``, centre of mass at ``r_i`` from its joint and
    inertia ``I_i`` about its centre of mass.

    Closed form in absolute angles ``theta = S q`` (``S`` lower-triangular
    ones), ``omega = S dq`` (docs/derivation.md, "Equations of motion")::

        M_jk  = a_jk cos(theta_j - theta_k),  a_jk = l_k e_j (j > k),
        a_jj  = m_j r_j^2 + l_j^2 sum_{i>j} m_i + I_j,  e_j = m_j r_j + l_j sum_{i>j} m_i
        c_j   = sum_k a_jk sin(theta_j - theta_k) omega_k^2       (centrifugal)
        G_j   = g0 e_j sin(theta_j)                                (gravity)
        D = S^T M S,   h = S^T (c + G)

    The products with S are suffix sums, kept as named symbols of the
    model's :class:`Program` so that D and h cost O(n^2) operations and
    their time derivatives stay just as compact.

    Parameters
    ----------
    n : int
        Number of links, 1..7.
    name : str, optional
        Model name (default ``planar<n>``); used for user model files.
    defaults : dict str -> float, optional
        Overrides of parameter defaults (names as in the parameter table).
    description : str, optional
        Replaces the generated description.
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
    overrides = dict(defaults or {})
    unknown = sorted(set(overrides) - {p.name for p in params})
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown} for a {n}-link planar chain; "
                         f"expected names among {[p.name for p in params]}")
    params = tuple(Param(p.name, float(overrides.get(p.name, p.default)), p.meaning, p.unit)
                   for p in params)
    sym = {p.name: sp.Symbol(p.name, real=True) for p in params}
    m = [sym[f"m{i}"] for i in idx]
    l = [sym[f"l{i}"] for i in idx]
    r = [sym[f"r{i}"] for i in idx]
    inertia = [sym[f"I{i}"] for i in idx]
    g0 = sym["g0"]
    q, dq, qm, dqm = _state_symbols(n)
    prog = Program()
    d = prog.define

    # Mass distribution (parameters only): mass beyond link j, first moment e_j, a_jk.
    mass_after = [sp.Integer(0)] * (n + 1)
    for j in reversed(range(n)):
        mass_after[j] = d(f"mtail{j + 1}", m[j] + mass_after[j + 1])
    e = [d(f"e{j + 1}", m[j] * r[j] + l[j] * mass_after[j + 1]) for j in range(n)]
    a = [[None] * n for _ in range(n)]
    for j in range(n):
        a[j][j] = d(f"a{j + 1}_{j + 1}", m[j] * r[j] ** 2 + l[j] ** 2 * mass_after[j + 1] + inertia[j])
        for k in range(j):
            a[j][k] = a[k][j] = d(f"a{j + 1}_{k + 1}", l[k] * e[j])

    # Kinematics: absolute angles, their trig, absolute rates.
    theta, omega = [q[0]], [dq[0]]
    for i in range(1, n):
        theta.append(d(f"th{i + 1}", theta[-1] + q[i]))
        omega.append(d(f"w{i + 1}", omega[-1] + dq[i]))
    cth = [d(f"c{i + 1}", sp.cos(theta[i])) for i in range(n)]
    sth = [d(f"s{i + 1}", sp.sin(theta[i])) for i in range(n)]
    cos_rel = [[None] * n for _ in range(n)]  # cos(theta_j - theta_k)
    sin_rel = [[None] * n for _ in range(n)]  # sin(theta_j - theta_k)
    # Their derivatives are stated directly, d cos(a) = -sin(a) da and d sin(a) = cos(a) da with
    # da = d theta_j - d theta_k: 1-2 products instead of the 4 of the product formula.
    for j in range(n):
        for k in range(j):
            rate = lambda dd, j=j, k=k: dd(theta[j]) - dd(theta[k])
            cos_rel[j][k] = cos_rel[k][j] = d(f"cr{j + 1}_{k + 1}", cth[j] * cth[k] + sth[j] * sth[k],
                                              rule=lambda dd, j=j, k=k: -sin_rel[j][k] * rate(dd, j, k))
            sin_rel[j][k] = d(f"sr{j + 1}_{k + 1}", sth[j] * cth[k] - cth[j] * sth[k],
                              rule=lambda dd, j=j, k=k: cos_rel[j][k] * rate(dd, j, k))
            sin_rel[k][j] = -sin_rel[j][k]

    def M(j: int, k: int) -> sp.Expr:
        return a[j][j] if j == k else a[j][k] * cos_rel[j][k]

    # D = S^T M S by suffix sums: R_jb = sum_{k >= b} M_jk, D_ab = sum_{j >= a} R_jb.
    R = [[None] * (n + 1) for _ in range(n)]
    for j in range(n):
        R[j][n] = sp.Integer(0)
        for b in reversed(range(n)):
            R[j][b] = d(f"Rs{j + 1}_{b + 1}", M(j, b) + R[j][b + 1])
    D = sp.zeros(n, n)
    for b in range(n):
        below = sp.Integer(0)
        for a_ in reversed(range(b, n)):
            below = d(f"D{a_ + 1}_{b + 1}", R[a_][b] + below)
            D[a_, b] = D[b, a_] = below

    # h = S^T (centrifugal + gravity), again a suffix sum.
    wsq = [d(f"wsq{k + 1}", omega[k] ** 2) for k in range(n)]
    h = sp.zeros(n, 1)
    tail = sp.Integer(0)
    for j in reversed(range(n)):
        cj = sp.Add(*[a[j][k] * sin_rel[j][k] * wsq[k] for k in range(n) if k != j])
        tail = d(f"h{j + 1}", cj + g0 * e[j] * sth[j] + tail)
        h[j] = tail
    V = -g0 * sp.Add(*[e[j] * cth[j] for j in range(n)])
    return FlexibleJointModel(
        name=name or f"planar{n}", n=n, params=params, q=q, dq=dq, qm=qm, dqm=dqm,
        D=D, h=h, potential=V,
        K=tuple(sym[f"K{i}"] for i in idx),
        Jm=tuple(sym[f"Jm{i}"] for i in idx),
        Bm=tuple(sym[f"Bm{i}"] for i in idx),
        description=description or (
            f"Planar serial chain of {n} link(s) with flexible joints, relative joint "
            "angles, q = 0 hanging straight down, gravity g0 along -y."
        ),
        program=prog,
    )


#: Built-in spatial arms: each is the URDF model file ``derive/robots/<name>/<name>.toml``.
SPATIAL_NAMES: Tuple[str, ...] = ("elbow3", "panda")
ROBOTS = Path(__file__).resolve().parent / "robots"

MODEL_NAMES: Tuple[str, ...] = ("link1",) + tuple(f"planar{n}" for n in range(1, 8)) + SPATIAL_NAMES


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
    if name in SPATIAL_NAMES:
        from .model_file import load_model_file  # imports this module: import here, not at the top
        return load_model_file(ROBOTS / name / f"{name}.toml", builtin=True).build()
    raise ValueError(f"unknown model {name!r}; available models: {', '.join(MODEL_NAMES)}")
