"""Arithmetic on scalars that are ``float`` or ``casadi.SX``, where exact float zeros and ones cost nothing.

The URDF's rotations and offsets are mostly exact 0 and +-1 (snapped, :mod:`derive.spatial.chain`)
and many inertials are numbers: kept as Python floats in lists of three, they fold away before
any SX node is made, so the emitted programme holds only the products that are there.
"""

from __future__ import annotations

from typing import List, Union

import casadi as ca

__all__ = ["Scalar", "Vec", "ZERO3", "is_zero", "mul", "neg", "add", "sub", "vadd", "scale", "cross",
           "matvec", "matTvec", "matmul3", "skew"]

Scalar = Union[float, ca.SX]
Vec = List[Scalar]

ZERO3: Vec = [0.0, 0.0, 0.0]


def is_zero(x) -> bool:
    """True for an exact float zero (an SX is never treated as zero)."""
    return isinstance(x, float) and x == 0.0


def mul(a: Scalar, b: Scalar) -> Scalar:
    if is_zero(a) or is_zero(b):
        return 0.0
    for u, v in ((a, b), (b, a)):
        if isinstance(u, float) and u == 1.0:
            return v
        if isinstance(u, float) and u == -1.0:
            return neg(v)
    return a * b


def neg(a: Scalar) -> Scalar:
    return 0.0 if is_zero(a) else -a


def add(*terms: Scalar) -> Scalar:
    total: Scalar = 0.0
    for t in terms:
        if not is_zero(t):
            total = t if is_zero(total) else total + t
    return total


def sub(a: Scalar, b: Scalar) -> Scalar:
    return a if is_zero(b) else add(a, neg(b))


def vadd(*vs: Vec) -> Vec:
    return [add(*c) for c in zip(*vs)]


def scale(k: Scalar, v: Vec) -> Vec:
    return [mul(k, x) for x in v]


def cross(u: Vec, v: Vec) -> Vec:
    return [sub(mul(u[1], v[2]), mul(u[2], v[1])),
            sub(mul(u[2], v[0]), mul(u[0], v[2])),
            sub(mul(u[0], v[1]), mul(u[1], v[0]))]


def matvec(M, v: Vec) -> Vec:
    """``M v`` for a 3x3 ``M`` (rows)."""
    return [add(*[mul(M[r][k], v[k]) for k in range(3)]) for r in range(3)]


def matTvec(M, v: Vec) -> Vec:
    """``M^T v`` for a 3x3 ``M`` (rows)."""
    return [add(*[mul(M[k][r], v[k]) for k in range(3)]) for r in range(3)]


def matmul3(A, B) -> List[Vec]:
    """``A B`` for 3x3 matrices (rows)."""
    return [[add(*[mul(A[r][k], B[k][c]) for k in range(3)]) for c in range(3)] for r in range(3)]


def skew(x: Vec) -> List[Vec]:
    """``[x]x``, the matrix of ``x cross .``."""
    return [[0.0, neg(x[2]), x[1]], [x[2], 0.0, neg(x[0])], [neg(x[1]), x[0], 0.0]]
