"""Time derivatives of the inverse dynamics by a Taylor recursion of the RNEA (SX).

The kernel (:mod:`derive.emit.dynamics`) needs, along the joint trajectory whose derivatives
at the current instant are ``(q, dq, a, a_rate, 0)``, the first and second time derivatives of
``tau(q, dq, a) = D(q) a + h(q, dq)``: ``r1 = tau^(1)`` with ``a_rate = 0`` and
``w = tau^(2)`` with ``a_rate = y4`` (docs/derivation.md, "Time derivatives by a Taylor
recursion"). Forward-mode AD of the straight-line RNEA gives them too (the tests' reference,
:func:`derive.emit.dynamics.time_derivatives`), but it does not know two facts that this
recursion uses, and it measured about 25 % more operations:

* the body-frame components of the angular velocity have the angular acceleration as their
  time derivative (``w_i^(k+1) = dw_i^(k)``), so only ``dw`` is propagated;
* a rotation about the joint's z axis has a derivative that is a cross product with ``e_z``:
  for ``r = R_i^T u``, ``r^(1) = R_i^T u^(1) + dq_i J(r)`` with ``J(v) = v x e_z = (v_y, -v_x, 0)``
  (two multiplications), instead of differentiating the rotation's entries.

Recursion, body ``i`` with parent ``p`` (rotation ``R_i = R0_i Rz(q_i)`` to the parent frame,
origin ``p_i`` in it; vectors in body coordinates, ``(k)`` the k-th derivative of the
components, binomial weights ``B = (1), (1, 1), (1, 2, 1)``)::

    rho_k = R_i^T u^(k),   [R_i^T u]^(0) = rho_0,   [R_i^T u]^(1) = rho_1 + dq J(rho_0),
                           [R_i^T u]^(2) = rho_2 + dq J(rho_1 + [R_i^T u]^(1)) + a J(rho_0)
    wr = R_i^T w_p,        w_i = wr + dq e_z,        w_i^(k+1) = dw_i^(k)
    dw_i^(0) = [R_i^T dw_p]^(0) + dq J(wr) + a e_z
    dw_i^(1) = [R_i^T dw_p]^(1) + dq J(dw_i^(0)) + a J(wr) + a_rate e_z
    dw_i^(2) = [R_i^T dw_p]^(2) + dq J(dw_i^(1)) + 2 a J(dw_i^(0)) + a_rate J(wr)
    c^(k)    = a_p^(k) + dw_p^(k) x p_i + sum_j B_kj w_p^(j) x (w_p^(k-j) x p_i),  acc_i^(k) = [R_i^T c]^(k)
    f^(k)    = m acc^(k) + dw^(k) x h + sum_j B_kj w^(j) x (w^(k-j) x h)
    n^(k)    = I dw^(k) + h x acc^(k) + sum_j B_kj w^(j) x (I w^(k-j))

with the base at rest and accelerated upwards by gravity (``acc^(0) = g0 e_z``, every other
base jet zero). The backward pass carries each body's force and moment to its parent,
``[R_i v]^(k) = R_i t_k`` with ``t_0 = v^(0)``, ``t_1 = v^(1) - dq J(v^(0))``,
``t_2 = v^(2) - J(2 dq v^(1) + a v^(0)) - dq^2 (v_x^(0), v_y^(0), 0)``, and
``tau_i^(k)`` is the z component of body ``i``'s composite moment. The inertials ``m``,
``h = m c``, ``I`` (about the origin) are constant in time.

Arithmetic is on scalars (``float`` or ``casadi.SX``) kept in lists of three, so that the
exact zeros and ones of the URDF's rotations and offsets cost nothing.
"""

from __future__ import annotations

from typing import List, Sequence, Tuple, Union

import casadi as ca

__all__ = ["BodyNumbers", "rnea_jets"]

Scalar = Union[float, ca.SX]
Vec = List[Scalar]
#: ``(R0, p, mass, first_moment, inertia, parent)`` of one body, numbers as floats, parameters as SX.
BodyNumbers = Tuple[Sequence[Sequence[float]], Sequence[float], Scalar, Sequence[Scalar],
                    Sequence[Sequence[Scalar]], int]

_ZERO: Vec = [0.0, 0.0, 0.0]
_BINOMIAL = ((1.0,), (1.0, 1.0), (1.0, 2.0, 1.0))


def _is_zero(x) -> bool:
    return isinstance(x, float) and x == 0.0


def _mul(a: Scalar, b: Scalar) -> Scalar:
    if _is_zero(a) or _is_zero(b):
        return 0.0
    for u, v in ((a, b), (b, a)):
        if isinstance(u, float) and u == 1.0:
            return v
        if isinstance(u, float) and u == -1.0:
            return _neg(v)
    return a * b


def _neg(a: Scalar) -> Scalar:
    return 0.0 if _is_zero(a) else -a


def _add(*terms: Scalar) -> Scalar:
    total: Scalar = 0.0
    for t in terms:
        if not _is_zero(t):
            total = t if _is_zero(total) else total + t
    return total


def _sub(a: Scalar, b: Scalar) -> Scalar:
    return a if _is_zero(b) else _add(a, _neg(b))


def _vadd(*vs: Vec) -> Vec:
    return [_add(*c) for c in zip(*vs)]


def _scale(k: Scalar, v: Vec) -> Vec:
    return [_mul(k, x) for x in v]


def _cross(u: Vec, v: Vec) -> Vec:
    return [_sub(_mul(u[1], v[2]), _mul(u[2], v[1])),
            _sub(_mul(u[2], v[0]), _mul(u[0], v[2])),
            _sub(_mul(u[0], v[1]), _mul(u[1], v[0]))]


def _matvec(M, v: Vec) -> Vec:
    return [_add(*[_mul(M[r][k], v[k]) for k in range(3)]) for r in range(3)]


def _matTvec(M, v: Vec) -> Vec:
    return [_add(*[_mul(M[k][r], v[k]) for k in range(3)]) for r in range(3)]


def _J(v: Vec) -> Vec:
    """``v x e_z``."""
    return [v[1], _neg(v[0]), 0.0]


def _ez(x: Scalar) -> Vec:
    return [0.0, 0.0, x]


class _JointRotation:
    """``R = R0 Rz(q_i)`` of one joint and the derivative rules of rotated vectors along the trajectory."""

    def __init__(self, R0, q_i, dq_i: Scalar, a_i: Scalar):
        self.R0, self.c, self.s = R0, ca.cos(q_i), ca.sin(q_i)
        self.dq, self.a = dq_i, a_i

    def to_body(self, u: Vec) -> Vec:
        """``R^T u``: a parent-frame vector in body coordinates."""
        u = _matTvec(self.R0, u)
        c, s = self.c, self.s
        return [_add(_mul(c, u[0]), _mul(s, u[1])), _sub(_mul(c, u[1]), _mul(s, u[0])), u[2]]

    def to_parent(self, v: Vec) -> Vec:
        """``R v``: a body vector in parent coordinates."""
        c, s = self.c, self.s
        return _matvec(self.R0, [_sub(_mul(c, v[0]), _mul(s, v[1])), _add(_mul(s, v[0]), _mul(c, v[1])), v[2]])

    def jets_to_body(self, u: List[Vec]) -> List[Vec]:
        """Jets of ``R^T u(t)`` from the jets of ``u`` (parent coordinates), same order."""
        rho = [self.to_body(x) for x in u]
        out = [rho[0]]
        if len(u) > 1:
            out.append(_vadd(rho[1], _scale(self.dq, _J(rho[0]))))
        if len(u) > 2:
            out.append(_vadd(rho[2], _scale(self.dq, _J(_vadd(rho[1], out[1]))), _scale(self.a, _J(rho[0]))))
        return out

    def jets_to_parent(self, v: List[Vec]) -> List[Vec]:
        """Jets of ``R v(t)`` from the jets of ``v`` (body coordinates), same order."""
        t = [v[0]]
        if len(v) > 1:
            t.append(_vadd(v[1], _scale(_neg(self.dq), _J(v[0]))))
        if len(v) > 2:
            u = [_add(_mul(_mul(2.0, self.dq), v[1][c]), _mul(self.a, v[0][c])) for c in range(2)]
            dq2 = _mul(self.dq, self.dq)
            t.append([_sub(_sub(v[2][0], u[1]), _mul(dq2, v[0][0])),
                      _sub(_add(v[2][1], u[0]), _mul(dq2, v[0][1])), v[2][2]])
        return [self.to_parent(x) for x in t]


def _leibniz(k: int, left: List[Vec], right: List[Vec]) -> Vec:
    """``sum_j B_kj left^(j) x right^(k-j)``: the k-th derivative of ``left x right``."""
    return _vadd(*[_scale(_BINOMIAL[k][j], _cross(left[j], right[k - j])) for j in range(k + 1)])


def rnea_jets(bodies: Sequence[BodyNumbers], q, dq, a, a_rate, g0: Scalar, order: int) -> List[ca.SX]:
    """``[tau^(0), ..., tau^(order)]`` of the inverse dynamics along the joint trajectory (see the module docstring).

    Parameters
    ----------
    bodies : sequence of BodyNumbers, length n
        In q order, parents before children.
    q, dq, a : casadi.SX, shape (n, 1), or sequences of n scalars
        Joint positions, rates and accelerations (``a`` of float zeros: ``tau = h``).
    a_rate : casadi.SX, shape (n, 1), sequence of n scalars, or None
        Time derivative of ``a`` (None: zero). ``a``'s second derivative is zero.
    g0 : float or casadi.SX
        Gravitational acceleration along -z of the base.
    order : int
        Highest derivative, 0..2.

    Returns
    -------
    list of casadi.SX, each (n, 1)
        ``tau^(0) = D a + h``, ``tau^(1)``, ``tau^(2)`` (as many as ``order + 1``).
    """
    if order not in (0, 1, 2):
        raise ValueError(f"order = {order!r}; expected 0, 1 or 2")
    n, K = len(bodies), order + 1
    rates = [0.0] * n if a_rate is None else a_rate
    rot, w, dw, acc, force, moment = ([None] * n for _ in range(6))
    for i, (R0, p, m, h, I, parent) in enumerate(bodies):
        Ri = rot[i] = _JointRotation(R0, q[i], dq[i], a[i])
        if parent < 0:
            w_p, dw_p, acc_p = _ZERO, [_ZERO] * K, [[0.0, 0.0, g0]] + [_ZERO] * (K - 1)
        else:
            w_p, dw_p, acc_p = w[parent], dw[parent], acc[parent]
        wr = Ri.to_body(w_p)
        dwr = Ri.jets_to_body(dw_p)
        dw_i = [_vadd(dwr[0], _scale(Ri.dq, _J(wr)), _ez(Ri.a))]
        if K > 1:
            dw_i.append(_vadd(dwr[1], _scale(Ri.dq, _J(dw_i[0])), _scale(Ri.a, _J(wr)), _ez(rates[i])))
        if K > 2:
            dw_i.append(_vadd(dwr[2], _scale(Ri.dq, _J(dw_i[1])), _scale(_mul(2.0, Ri.a), _J(dw_i[0])),
                              _scale(rates[i], _J(wr))))
        w_pj = [w_p] + dw_p[:K - 1]  # the parent's w^(0..K-1)
        w_x_p = [_cross(x, list(p)) for x in w_pj]
        c = [_vadd(acc_p[k], _cross(dw_p[k], list(p)), _leibniz(k, w_pj, w_x_p)) for k in range(K)]
        acc_i = Ri.jets_to_body(c)
        w_i = [_vadd(wr, _ez(Ri.dq))] + dw_i[:K - 1]
        w_x_h = [_cross(x, list(h)) for x in w_i] + [_cross(dw_i[K - 1], list(h))]  # w^(k+1) x h = dw^(k) x h
        I_w = [_matvec(I, x) for x in w_i] + [_matvec(I, dw_i[K - 1])]
        force[i] = [_vadd(_scale(m, acc_i[k]), w_x_h[k + 1], _leibniz(k, w_i, w_x_h)) for k in range(K)]
        moment[i] = [_vadd(I_w[k + 1], _cross(list(h), acc_i[k]), _leibniz(k, w_i, I_w)) for k in range(K)]
        w[i], dw[i], acc[i] = w_i[0], dw_i, acc_i
    tau = [[None] * n for _ in range(K)]
    for i in reversed(range(n)):  # children come after their parents: each is complete when carried
        for k in range(K):
            tau[k][i] = moment[i][k][2]
        parent = bodies[i][5]
        if parent >= 0:
            F = rot[i].jets_to_parent(force[i])
            N = rot[i].jets_to_parent(moment[i])
            p = list(bodies[i][1])
            force[parent] = [_vadd(force[parent][k], F[k]) for k in range(K)]
            moment[parent] = [_vadd(moment[parent][k], N[k], _cross(p, F[k])) for k in range(K)]
    return [ca.vertcat(*[ca.SX(t) if isinstance(t, float) else t for t in col]) for col in tau]
