"""Three-vector algebra and named intermediates for the SymPy chain builders.

:mod:`derive.spatial.spatial` (CRBA, RNEA) and :mod:`derive.spatial.spatial_jacobian` write their straight-line
programmes with these: vectors are lists of three SymPy expressions, matrices lists of three rows,
and :class:`Namer` gives an intermediate a name in the model's :class:`derive.core.program.Program`
unless it is a single term. Pure math: no I/O.
"""

from __future__ import annotations

from typing import Dict, List, Tuple

import sympy as sp

from ..core.program import Program

__all__ = ["Vector", "Matrix3", "exact_number", "cross3", "dot3", "matvec3", "matTvec3", "fill_symmetric",
           "Namer", "joint_trig"]

Vector = List[sp.Expr]
Matrix3 = List[List[sp.Expr]]


def exact_number(v: float) -> sp.Expr:
    """Exact integer for integral values (0, +-1 above all), else the double as a Float."""
    v = float(v)
    if v == int(v) and abs(v) < 2 ** 31:
        return sp.Integer(int(v))
    return sp.Float(v)


def cross3(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def dot3(a, b):
    return sp.Add(*[x * y for x, y in zip(a, b)])


def matvec3(M, v):
    return [sp.Add(*[M[r][k] * v[k] for k in range(3)]) for r in range(3)]


def matTvec3(M, v):
    return [sp.Add(*[M[k][r] * v[k] for k in range(3)]) for r in range(3)]


def fill_symmetric(M: Matrix3) -> Matrix3:
    """Fill the lower triangle of ``M`` (given on and above the diagonal) from the upper one."""
    for r in range(3):
        for k in range(r):
            M[r][k] = M[k][r]
    return M


class Namer:
    """``namer(label, e)`` names ``e`` in ``prog`` unless it is a single term.

    A symbol times constants costs nothing to repeat, so it stays inline.
    """

    def __init__(self, prog: Program, prefix: str = ""):
        self.prog = prog
        self.prefix = prefix  # a second pass over the same labels (the inverse dynamics) names them apart

    def __call__(self, label: str, e) -> sp.Expr:
        e = sp.sympify(e)
        if e.is_Atom or (e.is_Mul and sum(1 for a in e.args if not a.is_Number) <= 1):
            return e
        return self.prog.define(self.prefix + label, e)

    def vec(self, label: str, v) -> Vector:
        """Name the three components ``<label>x``, ``<label>y``, ``<label>z``."""
        return [self(f"{label}{'xyz'[k]}", v[k]) for k in range(3)]


def joint_trig(prog: Program, q) -> List[Tuple[sp.Expr, sp.Expr]]:
    """``(c_i, s_i) = (cos q_i, sin q_i)`` with the derivative rules ``dc = -s dq``, ``ds = c dq``."""
    cs: List[Tuple[sp.Expr, sp.Expr]] = []
    for i in range(len(q)):
        box: Dict[str, sp.Expr] = {}
        box["c"] = prog.define(f"c{i + 1}", sp.cos(q[i]), rule=lambda dd, i=i, b=box: -b["s"] * dd(q[i]))
        box["s"] = prog.define(f"s{i + 1}", sp.sin(q[i]), rule=lambda dd, i=i, b=box: b["c"] * dd(q[i]))
        cs.append((box["c"], box["s"]))
    return cs
