"""Regrouped inertials: each body's part that moves with its parent, carried onto the parent.

For a body turning about the z axis of its frame, three parts of its inertials (about its origin
``O``, in its frame) move rigidly with its *parent*, whatever the joint does:

* its mass ``m`` seen as a point mass at ``O`` (``O`` lies on the joint axis);
* the first moment along the axis, ``h_z e_z``;
* the inertia ``lam (E - e_z e_z^T)`` with ``lam = I_yy``: its kinetic energy is
  ``lam/2 |w_perp|^2``, and the components of the angular velocity across the axis are the
  parent's (``w = Rz^T R0^T w_parent + dq e_z``).

Their kinetic and potential energies are functions of the parent's motion alone, so adding them
to the parent's inertials (rotated by ``R0``, moved from ``O`` to the parent's origin) and
removing them from the body changes neither the Lagrangian nor any joint torque, nor any time
derivative of one. A root body's part moves with the fixed base and is dropped. Done from the
leaves towards the root, every body keeps only ``h_x, h_y`` and ``I`` with ``I_yy = 0`` and no
mass: the regrouping of the base inertial parameters (Khalil and Kleinfinger, 1987; Gautier and
Khalil, 1990) for revolute joints in general position.

The regrouped bodies are not physical (no mass, an inertia that is not positive definite); they
serve the recursion of the joint torques (:func:`derive.emit.rnea_jets.rnea_jets`), where the
zeros drop the momentum ``m v`` and half of the first-moment products of every body.

Moving ``(m, h', I')`` (about a point at ``p``, parent coordinates) to the parent's origin::

    h_parent += h' + m p
    I_parent += I' - [h']x [p]x - [p]x [h']x - m [p]x^2
"""

from __future__ import annotations

from typing import List, Sequence

from .rnea_jets import BodyNumbers
from .sparse_scalar import Scalar, add, matmul3, mul, neg, scale, skew, sub, vadd

__all__ = ["regroup"]


def _moved_part(R0, p, m: Scalar, hz: Scalar, lam: Scalar):
    """``(m, h, I)`` about the parent's origin, parent coordinates, of the part of a body that moves with its parent."""
    axis = [float(R0[r][2]) for r in range(3)]  # the joint axis in parent coordinates
    h_axis = scale(hz, axis)
    P, H = skew(list(p)), skew(h_axis)
    HP, PH, PP = matmul3(H, P), matmul3(P, H), matmul3(P, P)
    across = [[(1.0 if r == c else 0.0) - axis[r] * axis[c] for c in range(3)] for r in range(3)]
    inertia = [[sub(add(mul(lam, across[r][c]), neg(HP[r][c]), neg(PH[r][c])), mul(m, PP[r][c]))
                for c in range(3)] for r in range(3)]
    return m, vadd(h_axis, scale(m, list(p))), inertia


def regroup(bodies: Sequence[BodyNumbers]) -> List[BodyNumbers]:
    """The bodies with each one's parent-rigid part carried onto its parent (see the module docstring).

    Parameters
    ----------
    bodies : sequence of BodyNumbers, length n
        ``(R0, p, mass, first_moment, inertia, parent)`` in q order, parents before children;
        numbers as floats, parameters as SX.

    Returns
    -------
    list of BodyNumbers, length n
        Same kinematics; every mass 0, every ``first_moment[2]`` 0 and every ``inertia[1][1]`` 0.
        Every joint torque of :func:`derive.emit.rnea_jets.rnea_jets` (and its derivatives) is
        unchanged, up to rounding.
    """
    mass = [b[2] for b in bodies]
    first = [list(b[3]) for b in bodies]
    inertia = [[list(row) for row in b[4]] for b in bodies]
    for i in reversed(range(len(bodies))):  # children come after their parents: each body is complete here
        R0, p, _, _, _, parent = bodies[i]
        lam = inertia[i][1][1]
        if parent >= 0:
            m, h, I = _moved_part(R0, p, mass[i], first[i][2], lam)
            mass[parent] = add(mass[parent], m)
            first[parent] = vadd(first[parent], h)
            inertia[parent] = [vadd(inertia[parent][r], I[r]) for r in range(3)]
        mass[i], first[i][2] = 0.0, 0.0
        inertia[i][0][0], inertia[i][1][1] = sub(inertia[i][0][0], lam), 0.0
    return [(b[0], b[1], mass[i], first[i], inertia[i], b[5]) for i, b in enumerate(bodies)]
