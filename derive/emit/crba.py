"""The joint-space inertia ``D(q)`` by the composite-rigid-body algorithm, on regrouped bodies (SX).

With the regrouped inertials of :func:`derive.emit.regroup.regroup` (no mass anywhere), a
subtree's composite inertials about the origin of its root body are a first moment ``h`` and an
inertia ``I`` only, and carrying a child's composite ``(h, I)`` (rotated by ``R = R0 Rz(q)`` to the
parent's axes, at ``p``) to the parent's origin is::

    h_parent += R h
    I_parent += R I R^T - [R h]x [p]x - [p]x [R h]x

(:mod:`derive.emit.regroup`, with no mass). Column ``i`` of ``D`` is the moment about each
ancestor's axis of the momentum of subtree ``i`` turning at unit rate about its own axis:
``P = e_z x h_i``, ``L = I_i e_z`` at ``O_i``, carried towards the root as ``P <- R P``,
``L <- R L + p x R P``; ``D_ji = e_z . L`` at body ``j``. The rotation about z of a symmetric
matrix uses ``cos^2``, ``sin^2`` and ``cos sin`` once per joint. The regrouping leaves the kinetic
energy, hence ``D``, unchanged; on the Panda this is 508 operations against 558 for the model's
own CRBA on the stated inertials.
"""

from __future__ import annotations

from typing import List, Sequence

import casadi as ca

from .rnea_jets import BodyNumbers, JointRotation
from .sparse_scalar import Vec, add, cross, matmul3, mul, skew, sub, vadd

__all__ = ["joint_inertia"]


class _Rotation(JointRotation):
    """``R = R0 Rz(q)`` of one joint (:class:`derive.emit.rnea_jets.JointRotation`), and symmetric matrices by it."""

    _squares = None

    def symmetric(self, A) -> List[Vec]:
        """``R A R^T`` for a symmetric ``A``."""
        c, s = self.c, self.s
        if self._squares is None:
            self._squares = (c * c, s * s, c * s)
        cc, ss, cs = self._squares
        b00 = add(mul(cc, A[0][0]), mul(-2.0, mul(cs, A[0][1])), mul(ss, A[1][1]))
        b11 = sub(add(A[0][0], A[1][1]), b00)  # the trace of the x-y block is invariant
        b01 = add(mul(cs, sub(A[0][0], A[1][1])), mul(sub(cc, ss), A[0][1]))
        b02, b12 = sub(mul(c, A[0][2]), mul(s, A[1][2])), add(mul(s, A[0][2]), mul(c, A[1][2]))
        B = [[b00, b01, b02], [b01, b11, b12], [b02, b12, A[2][2]]]
        R0T = [[self.R0[k][r] for k in range(3)] for r in range(3)]
        return matmul3(matmul3(self.R0, B), R0T)


def joint_inertia(bodies: Sequence[BodyNumbers], q) -> ca.SX:
    """``D(q)`` of regrouped bodies (see the module docstring).

    Parameters
    ----------
    bodies : sequence of BodyNumbers, length n
        Regrouped (:func:`derive.emit.regroup.regroup`): every mass is 0.
    q : casadi.SX, shape (n, 1), or a sequence of n scalars

    Returns
    -------
    casadi.SX, shape (n, n)
    """
    if any(not (isinstance(b[2], float) and b[2] == 0.0) for b in bodies):
        raise ValueError("joint_inertia takes regrouped bodies (every mass 0): see derive.emit.regroup")
    n = len(bodies)
    rot = [_Rotation(b[0], q[i]) for i, b in enumerate(bodies)]
    h = [list(b[3]) for b in bodies]
    inertia = [[list(row) for row in b[4]] for b in bodies]
    for i in reversed(range(n)):  # children come after their parents: each composite is complete here
        parent, p = bodies[i][5], list(bodies[i][1])
        if parent < 0:
            continue
        Rh, RI = rot[i].to_parent(h[i]), rot[i].symmetric(inertia[i])
        HP, PH = matmul3(skew(Rh), skew(p)), matmul3(skew(p), skew(Rh))
        h[parent] = vadd(h[parent], Rh)
        inertia[parent] = [[sub(sub(add(inertia[parent][r][c], RI[r][c]), HP[r][c]), PH[r][c]) for c in range(3)]
                           for r in range(3)]
    D = [[0.0] * n for _ in range(n)]  # zero between branches of a tree
    for i in range(n):
        P, L = cross([0.0, 0.0, 1.0], h[i]), [inertia[i][r][2] for r in range(3)]
        D[i][i], j = L[2], i
        while bodies[j][5] >= 0:
            RP = rot[j].to_parent(P)
            L, P = vadd(rot[j].to_parent(L), cross(list(bodies[j][1]), RP)), RP
            j = bodies[j][5]
            D[j][i] = D[i][j] = L[2]
    return ca.vertcat(*[ca.horzcat(*[ca.SX(x) if isinstance(x, float) else x for x in row]) for row in D])
