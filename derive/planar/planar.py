"""Built-in formula models: the paper's single link (``link1``) and planar chains (``planar<n>``).

Both are :class:`derive.core.model_base.FlexibleJointModel` instances built from
closed forms (docs/derivation.md, "Equations of motion"); the planar chain's
intermediates are named symbols of a :class:`derive.core.program.Program` so that
D, h and their time derivatives stay O(n^2). Pure math: no I/O, no printing.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable, Dict, List, Optional, Tuple

import sympy as sp

from ..core.model_base import FlexibleJointModel, Param, state_symbols
from ..core.program import Program
from ..core.rotors import Rotors, gear_params, planar_carried

__all__ = ["make_link1", "make_planar", "planar_params", "make_link1_complete"]

#: Per-link parameter groups of ``planar<n>``: prefix, default, meaning, unit (then ``g0``).
PLANAR_TABLE: Tuple[Tuple[str, float, str, str], ...] = (
    ("m", 1.0, "mass of link {i}", "kg"),
    ("l", 1.0, "length of link {i}", "m"),
    ("r", 0.5, "joint {i} -> centre of mass of link {i}", "m"),
    ("I", 0.1, "inertia of link {i} about its centre of mass", "kg m^2"),
    ("K", 150.0, "stiffness of joint {i}", "N m/rad"),
    ("Jm", 2.0, "inertia of motor {i}", "kg m^2"),
    ("Bm", 0.0, "viscous damping of motor {i}", "N m s/rad"),
)

Define = Callable[..., sp.Expr]


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
    (q,), (dq,), (qm,), (dqm,) = (tuple(b) for b in state_symbols(1))
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


def planar_params(n: int, defaults: Dict[str, float] = None) -> Tuple[Param, ...]:
    """Parameter table of ``planar<n>`` (groups of :data:`PLANAR_TABLE`, then ``g0``).

    Parameters
    ----------
    n : int
        Number of links.
    defaults : dict str -> float, optional
        Overrides of parameter defaults.

    Raises
    ------
    ValueError
        If ``defaults`` names a parameter the chain does not have.
    """
    idx = range(1, n + 1)
    params = tuple(
        Param(f"{g}{i}", d, meaning.format(i=i), unit) for g, d, meaning, unit in PLANAR_TABLE for i in idx
    ) + (Param("g0", 9.8, "gravitational acceleration", "m/s^2"),)
    overrides = dict(defaults or {})
    unknown = sorted(set(overrides) - {p.name for p in params})
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown} for a {n}-link planar chain; "
                         f"expected names among {[p.name for p in params]}")
    return tuple(Param(p.name, float(overrides.get(p.name, p.default)), p.meaning, p.unit)
                 for p in params)


def _mass_distribution(d: Define, m, l, r, inertia) -> Tuple[list, list]:
    """First moments ``e_j`` and the coefficients ``a_jk`` (parameters only)."""
    n = len(m)
    mass_after = [sp.Integer(0)] * (n + 1)  # mass beyond link j
    for j in reversed(range(n)):
        mass_after[j] = d(f"mtail{j + 1}", m[j] + mass_after[j + 1])
    e = [d(f"e{j + 1}", m[j] * r[j] + l[j] * mass_after[j + 1]) for j in range(n)]
    a = [[None] * n for _ in range(n)]
    for j in range(n):
        a[j][j] = d(f"a{j + 1}_{j + 1}", m[j] * r[j] ** 2 + l[j] ** 2 * mass_after[j + 1] + inertia[j])
        for k in range(j):
            a[j][k] = a[k][j] = d(f"a{j + 1}_{k + 1}", l[k] * e[j])
    return e, a


def _kinematics(d: Define, q, dq):
    """Absolute angles' rates, their trig, and ``cos/sin(theta_j - theta_k)`` with derivative rules."""
    n = len(q)
    theta, omega = [q[0]], [dq[0]]
    for i in range(1, n):
        theta.append(d(f"th{i + 1}", theta[-1] + q[i]))
        omega.append(d(f"w{i + 1}", omega[-1] + dq[i]))
    cth = [d(f"c{i + 1}", sp.cos(theta[i])) for i in range(n)]
    sth = [d(f"s{i + 1}", sp.sin(theta[i])) for i in range(n)]
    cos_rel: List[list] = [[None] * n for _ in range(n)]  # cos(theta_j - theta_k)
    sin_rel: List[list] = [[None] * n for _ in range(n)]  # sin(theta_j - theta_k)
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
    return omega, cth, sth, cos_rel, sin_rel


def _inertia_matrix(d: Define, a, cos_rel) -> sp.Matrix:
    """``D = S^T M S`` by suffix sums: ``R_jb = sum_{k >= b} M_jk``, ``D_ab = sum_{j >= a} R_jb``."""
    n = len(a)

    def M(j: int, k: int) -> sp.Expr:
        return a[j][j] if j == k else a[j][k] * cos_rel[j][k]

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
    return D


def _bias(d: Define, a, e, sin_rel, sth, omega, g0) -> sp.Matrix:
    """``h = S^T (centrifugal + gravity)``, again a suffix sum."""
    n = len(a)
    wsq = [d(f"wsq{k + 1}", omega[k] ** 2) for k in range(n)]
    h = sp.zeros(n, 1)
    tail = sp.Integer(0)
    for j in reversed(range(n)):
        cj = sp.Add(*[a[j][k] * sin_rel[j][k] * wsq[k] for k in range(n) if k != j])
        tail = d(f"h{j + 1}", cj + g0 * e[j] * sth[j] + tail)
        h[j] = tail
    return h


def make_link1_complete(gear_ratio: float = 100.0) -> FlexibleJointModel:
    """``link1`` as a complete model: its only rotor rides on the base, so ``S = 0``.

    The base does not rotate, so the rotor's carried inertia and spin coupling
    vanish and the dynamics are exactly ``link1``'s whatever the gear ratio
    ``N1`` (a parameter appended to ``link1``'s): Spong's reduced model is
    exact for a single joint.
    """
    base = make_link1()
    return replace(base, name="link1_complete", params=base.params + gear_params([gear_ratio]),
                   coupling=sp.zeros(1, 1), motor_bias=sp.zeros(1, 1), reduced_model="link1",
                   description=base.description + " Complete model: the rotor rides on the base (S = 0).")


def make_planar(n: int, name: str = None, defaults: Dict[str, float] = None,
                description: str = None, rotors: Optional[Rotors] = None,
                reduced_model: Optional[str] = None) -> FlexibleJointModel:
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
    rotors : Rotors, optional
        The complete model (docs/complete-model.md): rotor ``i`` at the far end
        of link ``i-1`` (its polar inertia ``J_m,i / N_i^2`` and mass join that
        link), all axes parallel, so ``S_ji = J_m,i / N_i`` (``j < i``) is
        constant and there are no gyroscopic terms. Appends ``N1..Nn``.
    reduced_model : str, optional
        Recorded in a complete model.
    """
    if not 1 <= n <= 7:
        raise ValueError(f"planar<n>: n must be in 1..7, got {n}")
    idx = range(1, n + 1)
    params = planar_params(n, defaults) + (gear_params(rotors.gear_ratio) if rotors is not None else ())
    sym = {p.name: sp.Symbol(p.name, real=True) for p in params}
    m, l, r, inertia = ([sym[f"{g}{i}"] for i in idx] for g in ("m", "l", "r", "I"))
    g0 = sym["g0"]
    q, dq, qm, dqm = state_symbols(n)
    prog = Program()
    d = prog.define
    complete = {}
    if rotors is not None:
        jm, gear = [sym[f"Jm{i}"] for i in idx], [sym[f"N{i}"] for i in idx]
        m, r, inertia = planar_carried(m, l, r, inertia, [d(f"Ia{i + 1}", jm[i] / gear[i] ** 2) for i in range(n)],
                                       rotors, d)
        coef = [d(f"Sc{i + 1}", jm[i] / gear[i]) for i in range(n)]
        complete = {"coupling": sp.Matrix(n, n, lambda j, i: coef[i] if j < i else 0),
                    "motor_bias": sp.zeros(n, 1), "reduced_model": reduced_model, "rotors": rotors}
    e, a = _mass_distribution(d, m, l, r, inertia)
    omega, cth, sth, cos_rel, sin_rel = _kinematics(d, q, dq)
    D = _inertia_matrix(d, a, cos_rel)
    h = _bias(d, a, e, sin_rel, sth, omega, g0)
    V = -g0 * sp.Add(*[e[j] * cth[j] for j in range(n)])
    return FlexibleJointModel(
        **complete, name=name or f"planar{n}", n=n, params=params, q=q, dq=dq, qm=qm, dqm=dqm,
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
