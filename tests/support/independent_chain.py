"""Independent references for the planar flexible-joint chains (tests only).

Nothing here imports ``derive`` or reuses the generated code: the chain is
rebuilt from its physical description alone,

* relative joint angles; ``q = 0`` hangs straight down (every link along -y);
* gravity ``g0`` along -y;
* link ``i`` has mass ``m_i``, length ``l_i``, centre of mass at ``r_i`` from
  its joint along the link and inertia ``I_i`` about that centre (z axis);
* joint ``i + 1`` sits at the tip of link ``i``;
* flexible joints: ``D ddq + h + K (q - q_m) = 0``,
  ``J_m ddq_m + B_m dq_m - K (q - q_m) = u``.

Two references are built from it:

:func:`pinocchio_chain`
    The rigid chain in Pinocchio's model-building API (``crba``, ``rnea``,
    ``aba``), a rigid-body library with its own algorithms.
:func:`casadi_reference`
    CasADi SX dynamics from link kinematics: centre-of-mass positions and
    link angular rates give the kinetic and potential energy, ``D`` and ``h``
    follow by CasADi automatic differentiation (Lagrange's equations), ``f``
    uses an explicit linear solve with ``D``, and ``T``, ``alpha``, ``beta``
    and the bracket matrix are Lie derivatives by CasADi AD (``jtimes``),
    with the paper's sign ``ad_f v = (df/dx) v - (dv/dx) f``.

Parameters are passed by name (``m1..mn, l1..ln, r1..rn, I1..In, K1..Kn,
Jm1..Jmn, Bm1..Bmn, g0``), so no parameter ordering is shared with the code
under test either.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Dict, Mapping, Tuple

import casadi as ca
import numpy as np
import pinocchio as pin

#: Per-link parameter groups of a planar chain, in the order of :func:`param_names`.
GROUPS = ("m", "l", "r", "I", "K", "Jm", "Bm")


def param_names(n: int) -> Tuple[str, ...]:
    """Parameter names of an ``n``-link planar chain, grouped as in :data:`GROUPS`, then ``g0``.

    Parameters
    ----------
    n : int
        Number of links.

    Returns
    -------
    tuple of str
    """
    return tuple(f"{g}{i}" for g in GROUPS for i in range(1, n + 1)) + ("g0",)


def random_chain_params(n: int, rng: np.random.Generator, damping: bool = True) -> Dict[str, float]:
    """Random physical parameters of an ``n``-link chain, over wide ranges.

    Masses 0.2..5 kg, lengths 0.2..2 m, centre of mass anywhere on the link,
    inertias 0.005..1 kg m^2, stiffnesses 50..500 N m/rad, motor inertias
    0.1..5 kg m^2, motor damping 0..1 N m s/rad (0 if not ``damping``),
    gravity 5..15 m/s^2.

    Parameters
    ----------
    n : int
        Number of links.
    rng : numpy.random.Generator
    damping : bool, optional
        Draw motor damping (default) or set it to zero.

    Returns
    -------
    dict str -> float
    """
    p: Dict[str, float] = {}
    for i in range(1, n + 1):
        p[f"m{i}"] = rng.uniform(0.2, 5.0)
        p[f"l{i}"] = rng.uniform(0.2, 2.0)
        p[f"r{i}"] = p[f"l{i}"] * rng.uniform(0.05, 1.0)
        p[f"I{i}"] = rng.uniform(0.005, 1.0)
        p[f"K{i}"] = rng.uniform(50.0, 500.0)
        p[f"Jm{i}"] = rng.uniform(0.1, 5.0)
        p[f"Bm{i}"] = rng.uniform(0.0, 1.0) if damping else 0.0
    p["g0"] = rng.uniform(5.0, 15.0)
    return p


def random_chain_state(n: int, rng: np.random.Generator) -> np.ndarray:
    """A state ``[q; dq; q_m; dq_m]`` anywhere on the circle, rates up to 3 rad/s.

    Parameters
    ----------
    n : int
    rng : numpy.random.Generator

    Returns
    -------
    numpy.ndarray, shape (4 n,)
    """
    q = rng.uniform(-np.pi, np.pi, n)
    dq = rng.uniform(-3.0, 3.0, n)
    qm = q + rng.uniform(-0.3, 0.3, n)
    dqm = dq + rng.uniform(-1.0, 1.0, n)
    return np.concatenate([q, dq, qm, dqm])


def _split(p: Mapping[str, float], n: int) -> Dict[str, np.ndarray]:
    out = {g: np.array([float(p[f"{g}{i}"]) for i in range(1, n + 1)]) for g in GROUPS}
    out["g0"] = float(p["g0"])
    return out


def pinocchio_chain(p: Mapping[str, float], n: int) -> pin.Model:
    """The rigid planar chain as a Pinocchio model (revolute z joints).

    Parameters
    ----------
    p : mapping str -> float
        Chain parameters by name (the motor and spring entries are ignored).
    n : int
        Number of links.

    Returns
    -------
    pinocchio.Model
        ``nq = nv = n``; its configuration is the vector of relative angles.
    """
    v = _split(p, n)
    model = pin.Model()
    parent = 0
    placement = pin.SE3.Identity()  # joint 1 at the origin
    for i in range(n):
        joint = model.addJoint(parent, pin.JointModelRZ(), placement, f"joint{i + 1}")
        # In the link frame the link points along -y (q = 0 hangs straight down).
        com = np.array([0.0, -v["r"][i], 0.0])
        rot = np.diag([v["I"][i], v["I"][i], v["I"][i]])  # only the z entry matters in the plane
        model.appendBodyToJoint(joint, pin.Inertia(v["m"][i], com, rot), pin.SE3.Identity())
        placement = pin.SE3(np.eye(3), np.array([0.0, -v["l"][i], 0.0]))  # tip of link i
        parent = joint
    model.gravity = pin.Motion(np.array([0.0, -v["g0"], 0.0]), np.zeros(3))
    return model


class PinocchioReference:
    """Rigid-chain quantities by Pinocchio, plus the flexible-joint motor side.

    Parameters
    ----------
    p : mapping str -> float
        Chain parameters by name.
    n : int
        Number of links.
    """

    def __init__(self, p: Mapping[str, float], n: int):
        self.n = n
        self.v = _split(p, n)
        self.model = pinocchio_chain(p, n)
        self.data = self.model.createData()

    def inertia(self, q: np.ndarray) -> np.ndarray:
        """``D(q)`` by the composite rigid body algorithm (symmetrized)."""
        M = pin.crba(self.model, self.data, np.asarray(q, float)).copy()
        return np.triu(M) + np.triu(M, 1).T

    def bias(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """``h(q, dq) = C(q, dq) dq + G(q)`` by recursive Newton-Euler with zero acceleration."""
        return pin.rnea(self.model, self.data, np.asarray(q, float), np.asarray(dq, float),
                        np.zeros(self.n)).copy()

    def link_accel(self, q: np.ndarray, dq: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Forward dynamics by the articulated body algorithm."""
        return pin.aba(self.model, self.data, np.asarray(q, float), np.asarray(dq, float),
                       np.asarray(tau, float)).copy()

    def f(self, x: np.ndarray) -> np.ndarray:
        """Flexible-joint drift ``f(x)``: link side by ``aba``, motor side written out."""
        n, v = self.n, self.v
        q, dq, qm, dqm = (np.asarray(x[k * n:(k + 1) * n], float) for k in range(4))
        spring = v["K"] * (q - qm)
        ddq = self.link_accel(q, dq, -spring)
        ddqm = (spring - v["Bm"] * dqm) / v["Jm"]
        return np.concatenate([dq, ddq, dqm, ddqm])

    def energy(self, x: np.ndarray) -> float:
        """Links (kinetic + gravity) by Pinocchio, plus motor kinetic and spring energy."""
        n, v = self.n, self.v
        q, dq, qm, dqm = (np.asarray(x[k * n:(k + 1) * n], float) for k in range(4))
        kin = pin.computeKineticEnergy(self.model, self.data, q, dq)
        pot = pin.computePotentialEnergy(self.model, self.data, q)
        return float(kin + pot + 0.5 * np.sum(v["Jm"] * dqm**2) + 0.5 * np.sum(v["K"] * (q - qm)**2))


def _lagrangian_dynamics(n: int):
    """SX symbols and ``D``, ``h`` of the chain from its kinematics (Lagrange by CasADi AD)."""
    x = ca.SX.sym("x", 4 * n)
    p = ca.SX.sym("p", len(param_names(n)))
    names = param_names(n)
    par = {name: p[k] for k, name in enumerate(names)}
    q, dq = x[:n], x[n:2 * n]
    kinetic, potential = 0, 0
    joint = ca.SX.zeros(2)  # position of joint i
    theta = 0
    omega = 0
    for i in range(1, n + 1):
        theta = theta + q[i - 1]  # absolute angle of link i
        omega = omega + dq[i - 1]
        along = ca.vertcat(ca.sin(theta), -ca.cos(theta))  # unit vector joint -> tip
        com = joint + par[f"r{i}"] * along
        vcom = ca.jtimes(com, q, dq)  # d com/dt = (d com/dq) dq
        kinetic += 0.5 * par[f"m{i}"] * ca.dot(vcom, vcom) + 0.5 * par[f"I{i}"] * omega**2
        potential += par[f"m{i}"] * par["g0"] * com[1]
        joint = joint + par[f"l{i}"] * along
    # Lagrange: d/dt (dT/d dq) - dT/dq + dV/dq = D ddq + h.
    p_dq = ca.gradient(kinetic, dq)
    D = ca.jacobian(p_dq, dq)
    h = ca.jtimes(p_dq, q, dq) - ca.gradient(kinetic, q) + ca.gradient(potential, q)
    return x, p, par, D, h, kinetic + potential


def _spd_solve(A: ca.SX, b: ca.SX) -> ca.SX:
    """``A^-1 b`` for a symmetric positive definite ``A`` by an explicit Cholesky factorization.

    Written out (rather than ``casadi.solve``, whose SX QR loses ~100x more
    accuracy on the stiffer 7-link chains) so the reference stays as accurate
    as a numerical SPD solve.
    """
    n = A.shape[0]
    L = [[None] * n for _ in range(n)]
    for j in range(n):
        L[j][j] = ca.sqrt(A[j, j] - sum((L[j][k] ** 2 for k in range(j)), 0))
        for i in range(j + 1, n):
            L[i][j] = (A[i, j] - sum((L[i][k] * L[j][k] for k in range(j)), 0)) / L[j][j]
    z = [None] * n  # L z = b
    for i in range(n):
        z[i] = (b[i] - sum((L[i][k] * z[k] for k in range(i)), 0)) / L[i][i]
    y = [None] * n  # L^T y = z
    for i in reversed(range(n)):
        y[i] = (z[i] - sum((L[k][i] * y[k] for k in range(i + 1, n)), 0)) / L[i][i]
    return ca.vertcat(*y)


def _bracket(f: ca.SX, v: ca.SX, x: ca.SX) -> ca.SX:
    """``ad_f v = (df/dx) v - (dv/dx) f`` (the paper's sign), column by column."""
    cols = [ca.jtimes(f, x, v[:, k]) - ca.jtimes(v[:, k], x, f) for k in range(v.shape[1])]
    return ca.horzcat(*cols)


@lru_cache(maxsize=None)
def casadi_reference(n: int) -> Dict[str, ca.Function]:
    """CasADi Functions ``(x, p) -> value`` of the independent SX chain.

    Parameters
    ----------
    n : int
        Number of links.

    Returns
    -------
    dict str -> casadi.Function
        ``inertia`` (n, n), ``h`` (n,), ``energy`` (links + motors + springs), ``f`` (4n,),
        ``g`` (4n, n), ``T`` (4n,), ``alpha`` (n,), ``beta`` (n, n), ``ad`` (4n, 4n).
        ``p`` is ordered as :func:`param_names`.
    """
    x, p, par, D, h, link_energy = _lagrangian_dynamics(n)
    q, dq, qm, dqm = (x[k * n:(k + 1) * n] for k in range(4))
    K = ca.vertcat(*[par[f"K{i}"] for i in range(1, n + 1)])
    Jm = ca.vertcat(*[par[f"Jm{i}"] for i in range(1, n + 1)])
    Bm = ca.vertcat(*[par[f"Bm{i}"] for i in range(1, n + 1)])
    spring = K * (q - qm)
    ddq = _spd_solve(D, -(h + spring))  # explicit solve with D
    ddqm = (spring - Bm * dqm) / Jm
    f = ca.vertcat(dq, ddq, dqm, ddqm)
    g = ca.vertcat(ca.SX.zeros(3 * n, n), ca.diag(1 / Jm))
    energy = link_energy + 0.5 * ca.dot(Jm * dqm, dqm) + 0.5 * ca.dot(K * (q - qm), q - qm)
    # Outputs y1 = q and their Lie derivatives along f.
    y2 = ca.jtimes(q, x, f)
    y3 = ca.jtimes(y2, x, f)
    y4 = ca.jtimes(y3, x, f)
    a = ca.jtimes(y4, x, f)
    decoupling = ca.mtimes(ca.jacobian(y4, x), g)  # L_g y4
    beta = ca.inv(decoupling)
    alpha = -ca.mtimes(beta, a)
    ads = [g]
    for _ in range(3):
        ads.append(_bracket(f, ads[-1], x))
    ad = ca.horzcat(*ads)
    out = {"inertia": D, "h": h, "energy": energy, "f": f, "g": g,
           "T": ca.vertcat(q, y2, y3, y4), "alpha": alpha, "beta": beta, "ad": ad}
    return {k: ca.Function(k, [x, p], [v], ["x", "p"], [k]) for k, v in out.items()}


def evaluate(fun: ca.Function, x: np.ndarray, p: Mapping[str, float], n: int) -> np.ndarray:
    """Evaluate a :func:`casadi_reference` Function with parameters given by name.

    Parameters
    ----------
    fun : casadi.Function
    x : array_like, shape (4 n,)
    p : mapping str -> float
    n : int

    Returns
    -------
    numpy.ndarray
        Dense 2-D result (a vector is a column).
    """
    pv = np.array([float(p[k]) for k in param_names(n)])
    return np.array(fun(np.asarray(x, float), pv), dtype=float)
