"""Time derivatives of the inverse dynamics by a Taylor recursion of the RNEA, in momenta (SX).

The kernel (:mod:`derive.emit.dynamics`) needs, along the joint trajectory whose derivatives
at the current instant are ``(q, dq, a, a_rate, 0)``, the first and second time derivatives of
``tau(q, dq, a) = D(q) a + h(q, dq)``: ``r1 = tau^(1)`` with ``a_rate = 0`` and
``w = tau^(2)`` with ``a_rate = y4`` (docs/derivation.md, "Time derivatives by a Taylor
recursion"). Forward-mode AD of the straight-line RNEA gives them too (the tests' reference,
:func:`derive.emit.dynamics.time_derivatives`), but it does not know three facts that this
recursion uses (it measured about 25 % more operations):

* the body-frame components of the angular velocity have the angular acceleration as their
  time derivative, so one jet ``w^(0..)`` per body carries both;
* a rotation about the joint's z axis has a derivative that is a cross product with ``e_z``:
  for ``r = Rz(q_i)^T u``, ``r' = Rz^T u' + dq_i J(r)`` with ``J(v) = v x e_z = (v_y, -v_x, 0)``
  (two multiplications), instead of differentiating the rotation's entries;
* Newton-Euler's products of velocities are needed only where a torque is read. Each body
  contributes its momenta, linear in its velocities, and the subtree's momenta are summed
  towards the root; the products ``w x L`` and ``v x P`` are formed once per joint and only
  their z component, instead of ``w x (w x h)``, ``w x I w`` per body in full (7 % fewer
  operations on the kernel of a 21-joint chain, 3 % on the Panda's).

Jets are lists of the component derivatives ``x^(0), x^(1), ...`` of body-frame vectors, with
``q_i^(1..4) = (dq, a, a_rate, a_jerk)``. Body ``i`` with parent ``p``, rotation
``R_i = R0_i Rz(q_i)`` to the parent frame, origin ``p_i`` in it::

    w_i^(k) = [R_i^T w_p]^(k) + q_i^(k+1) e_z         (angular velocity)
    v_i^(k) = [R_i^T (v_p + w_p x p_i)]^(k)            (velocity of the origin)
    P_i^(k) = m v_i^(k) + w_i^(k) x h                  (momentum)
    L_i^(k) = I w_i^(k) + h x v_i^(k)                  (angular momentum about the origin)

with ``[Rz^T rho]^(k)`` from ``[Rz^T rho]' = Rz^T rho' + q' J(Rz^T rho)`` applied k times
(:func:`_rotated`; ``-J`` for ``Rz v`` towards the parent). The base is at rest and accelerated
upwards by gravity: ``v^(1) = g0 e_z``, every other base jet zero. Backward, a child's
momenta join its parent's, ``P_p += [R_i P_i]``, ``L_p += [R_i L_i] + p_i x [R_i P_i]``,
and the torque of joint ``i`` is the z component of the moment the subtree needs about its
moving origin, ``d/dt L + v x P`` in rotating components::

    tau_i^(k) = e_z . ( L_i^(k+1) + sum_j B_kj (w_i^(j) x L_i^(k-j) + v_i^(j) x P_i^(k-j)) )

(subtree sums; binomial weights ``B = (1), (1, 1), (1, 2, 1)``). ``m``, ``h = m c`` and ``I``
(about the origin) are constant in time.

Arithmetic is on scalars (``float`` or ``casadi.SX``) kept in lists of three, so that the
exact zeros and ones of the URDF's rotations and offsets cost nothing.
"""

from __future__ import annotations

from math import comb
from typing import List, Sequence, Tuple

import casadi as ca

from .sparse_scalar import ZERO3, Scalar, Vec, add, cross, is_zero, matTvec, matvec, mul, neg, scale, sub, vadd

__all__ = ["BodyNumbers", "JointRotation", "rnea_jets"]

#: ``(R0, p, mass, first_moment, inertia, parent)`` of one body, numbers as floats, parameters as SX.
BodyNumbers = Tuple[Sequence[Sequence[float]], Sequence[float], Scalar, Sequence[Scalar],
                    Sequence[Sequence[Scalar]], int]

_BINOMIAL = ((1.0,), (1.0, 1.0), (1.0, 2.0, 1.0))
#: Highest derivative of the inverse dynamics: ``tau^(k)`` needs the trajectory up to ``q^(k+2)``.
MAX_ORDER = 2


def _J(v: Vec) -> Vec:
    """``v x e_z``."""
    return [v[1], neg(v[0]), 0.0]


def _ez(x: Scalar) -> Vec:
    return [0.0, 0.0, x]


class JointRotation:
    """``R = R0 Rz(q_i)`` of one joint and the jets of vectors rotated by it along the trajectory."""

    def __init__(self, R0, q_i, rates: Sequence[Scalar] = ()):
        self.R0, self.c, self.s = R0, ca.cos(q_i), ca.sin(q_i)
        self.rates = list(rates)  # q_i^(1), q_i^(2), ... (float zeros where the trajectory has none)

    def to_body(self, u: Vec) -> Vec:
        """``R^T u``: a parent-frame vector in body coordinates."""
        u = matTvec(self.R0, u)
        c, s = self.c, self.s
        return [add(mul(c, u[0]), mul(s, u[1])), sub(mul(c, u[1]), mul(s, u[0])), u[2]]

    def to_parent(self, v: Vec) -> Vec:
        """``R v``: a body vector in parent coordinates."""
        c, s = self.c, self.s
        return matvec(self.R0, [sub(mul(c, v[0]), mul(s, v[1])), add(mul(s, v[0]), mul(c, v[1])), v[2]])

    def jets_to_body(self, u: List[Vec]) -> List[Vec]:
        """Jets of ``R^T u(t)`` from the jets of ``u`` (parent coordinates), same length."""
        return _rotated([self.to_body(x) for x in u], self.rates, 1.0)

    def jets_to_parent(self, v: List[Vec]) -> List[Vec]:
        """Jets of ``R v(t)`` from the jets of ``v`` (body coordinates), same length."""
        return [self.to_parent(x) for x in _rotated(v, self.rates, -1.0)]


def _rotated(rho: List[Vec], rates: Sequence[Scalar], sign: float) -> List[Vec]:
    """Jets of ``x = Rz(q)^(-sign) rho`` in the rotated coordinates, from the jets ``rho`` (same length).

    ``x' = Rz^-sign rho' + sign q' J(x)``; so with ``X(k, j)`` the k-th derivative of
    ``Rz^-sign rho^(j)``: ``X(0, j) = rho_j`` (the rotation is applied to ``rho`` by the caller)
    and ``X(k, j) = X(k-1, j+1) + sign sum_m C(k-1, m) q^(m+1) J(X(k-1-m, j))``.
    """
    memo = {}

    def X(k: int, j: int) -> Vec:
        if (k, j) not in memo:
            if k == 0:
                memo[k, j] = rho[j]
            else:
                terms = [X(k - 1, j + 1)]
                for m in range(k):
                    weight = mul(sign * comb(k - 1, m), rates[m]) if m < len(rates) else 0.0
                    if not is_zero(weight):
                        terms.append(scale(weight, _J(X(k - 1 - m, j))))
                memo[k, j] = vadd(*terms)
        return memo[k, j]

    return [X(k, 0) for k in range(len(rho))]


def _z_cross(u: Vec, v: Vec) -> Scalar:
    """``e_z . (u x v)``."""
    return sub(mul(u[0], v[1]), mul(u[1], v[0]))


def _joint_torque(k: int, w: List[Vec], v: List[Vec], P: List[Vec], L: List[Vec]) -> Scalar:
    """``tau^(k)`` of a joint from its subtree's momenta (see the module docstring)."""
    products = [mul(_BINOMIAL[k][j], add(_z_cross(w[j], L[k - j]), _z_cross(v[j], P[k - j])))
                for j in range(k + 1)]
    return add(L[k + 1][2], *products)


def rnea_jets(bodies: Sequence[BodyNumbers], q, rates: Sequence, g0: Scalar, order: int) -> List[ca.SX]:
    """``[tau^(0), ..., tau^(order)]`` of the inverse dynamics along a joint trajectory (see the module docstring).

    Parameters
    ----------
    bodies : sequence of BodyNumbers, length n
        In q order, parents before children.
    q : casadi.SX, shape (n, 1), or a sequence of n scalars
        Joint positions.
    rates : sequence of (casadi.SX (n, 1), sequence of n scalars, or None)
        The trajectory's time derivatives ``q^(1), q^(2), ...`` at the instant, e.g.
        ``(dq, a, a_rate, a_jerk)``; missing ones and None are zero. ``tau^(k)`` reads up to
        ``q^(k+2)``.
    g0 : float or casadi.SX
        Gravitational acceleration along -z of the base.
    order : int
        Highest derivative, 0..2.

    Returns
    -------
    list of casadi.SX, each (n, 1)
        ``tau^(0) = D a + h``, ``tau^(1)``, ``tau^(2)`` (as many as ``order + 1``).
    """
    if order not in range(MAX_ORDER + 1):
        raise ValueError(f"order = {order!r}; expected 0, 1 or 2")
    n, M = len(bodies), order + 2  # momenta up to order + 1
    rates = list(rates)[:M]
    rates += [None] * (M - len(rates))
    joint_rates = [[0.0 if r is None else r[i] for r in rates] for i in range(n)]  # q_i^(1..M), missing ones 0
    rot, w, v, P, L = ([None] * n for _ in range(5))
    for i, (R0, p, m, h, I, parent) in enumerate(bodies):
        Ri = rot[i] = JointRotation(R0, q[i], joint_rates[i])
        if parent < 0:
            w_p, v_p = [ZERO3] * M, [ZERO3, [0.0, 0.0, g0]] + [ZERO3] * (M - 2)
        else:
            w_p, v_p = w[parent], v[parent]
        w[i] = [vadd(x, _ez(Ri.rates[k])) for k, x in enumerate(Ri.jets_to_body(w_p))]
        v[i] = Ri.jets_to_body([vadd(v_p[k], cross(w_p[k], list(p))) for k in range(M)])
        P[i] = [vadd(scale(m, v[i][k]), cross(w[i][k], list(h))) for k in range(M)]
        L[i] = [vadd(matvec(I, w[i][k]), cross(list(h), v[i][k])) for k in range(M)]
    tau = [[None] * n for _ in range(order + 1)]
    for i in reversed(range(n)):  # children come after their parents: each subtree is complete here
        for k in range(order + 1):
            tau[k][i] = _joint_torque(k, w[i], v[i], P[i], L[i])
        parent = bodies[i][5]
        if parent >= 0:
            RP, RL = rot[i].jets_to_parent(P[i]), rot[i].jets_to_parent(L[i])
            p = list(bodies[i][1])
            P[parent] = [vadd(P[parent][k], RP[k]) for k in range(M)]
            L[parent] = [vadd(L[parent][k], RL[k], cross(p, RP[k])) for k in range(M)]
    return [ca.vertcat(*[ca.SX(t) if isinstance(t, float) else t for t in col]) for col in tau]
