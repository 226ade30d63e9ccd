"""SymPy expressions -> CasADi SX, the state symbols, and the skew congruence W M W in SX (the LDL^T is in ldl.py).

The converter walks the SymPy DAG once (memo on nodes), so shared
sub-expressions become shared SX nodes. Only the node types our models
produce are accepted; anything else is an error, never a silent guess.
"""

from __future__ import annotations

from typing import Callable, Dict, List, Mapping

import casadi as ca
import sympy as sp


#: The comparisons of a Piecewise's conditions (SymPy may flip ``<`` into ``>``).
_COMPARE = {"<": lambda a, b: a < b, "<=": lambda a, b: a <= b, ">": lambda a, b: a > b, ">=": lambda a, b: a >= b}


class SympyToSX:
    """Convert SymPy expressions to SX given a binding of every free symbol.

    Parameters
    ----------
    bindings : mapping sympy.Symbol -> casadi.SX (scalar)
        Arguments (state and parameter symbols).
    definitions : mapping sympy.Symbol -> sympy.Expr, optional
        Intermediate symbols of a :class:`derive.core.program.Program`, converted
        on first use.
    implicit : mapping sympy.Symbol -> callable () -> casadi.SX, optional
        Symbols bound to numeric linear algebra (e.g. ``y3 = D^-1 r3``),
        computed on first use.

    Every free symbol must be resolvable by one of the three; anything else
    raises ``ValueError`` naming it (docs/design.md, "Emission").
    """

    def __init__(self, bindings: Mapping[sp.Symbol, ca.SX],
                 definitions: Mapping[sp.Symbol, sp.Expr] = None,
                 implicit: Mapping[sp.Symbol, Callable[[], ca.SX]] = None):
        self._memo: Dict[sp.Basic, ca.SX] = dict(bindings)
        self._definitions = dict(definitions or {})
        self._implicit = dict(implicit or {})

    def bind(self, sym: sp.Symbol, value: ca.SX) -> None:
        self._memo[sym] = value

    def __call__(self, e) -> ca.SX:
        if isinstance(e, sp.MatrixBase):
            out = ca.SX(e.rows, e.cols)
            for i in range(e.rows):
                for j in range(e.cols):
                    out[i, j] = self._convert(e[i, j])
            return out
        return self._convert(sp.sympify(e))

    def _convert(self, e: sp.Basic) -> ca.SX:
        hit = self._memo.get(e)
        if hit is not None:
            return hit
        if e.is_Symbol:
            if e in self._definitions:
                out = self._convert(self._definitions[e])
            elif e in self._implicit:
                out = self._implicit[e]()
            else:
                raise ValueError(f"free symbol {e} is not bound to any argument")
            self._memo[e] = out
            return out
        if e.is_Integer:
            out = ca.SX(float(int(e)))
        elif e.is_Rational:
            out = ca.SX(float(e.p) / float(e.q))
        elif e.is_Float:
            out = ca.SX(float(e))
        elif e.is_Add:
            args = [self._convert(a) for a in e.args]
            out = args[0]
            for a in args[1:]:
                out = out + a
        elif e.is_Mul:
            out = self._mul(e)
        elif e.is_Pow:
            out = self._pow(e.args[0], e.args[1])
        elif isinstance(e, sp.sin):
            out = ca.sin(self._convert(e.args[0]))
        elif isinstance(e, sp.cos):
            out = ca.cos(self._convert(e.args[0]))
        elif isinstance(e, sp.tanh):  # motor friction (derive.core.friction)
            out = ca.tanh(self._convert(e.args[0]))
        elif isinstance(e, sp.exp):
            out = ca.exp(self._convert(e.args[0]))
        elif isinstance(e, sp.Piecewise):  # the three-segment spring's blends (derive.core.spring_laws)
            out = self._piecewise(e.args)
        elif isinstance(e, sp.core.relational.Relational) and e.rel_op in _COMPARE:
            out = _COMPARE[e.rel_op](self._convert(e.lhs), self._convert(e.rhs))
        else:
            raise ValueError(f"cannot emit SymPy node of type {type(e).__name__}: {e}")
        self._memo[e] = out
        return out

    def _piecewise(self, pieces) -> ca.SX:
        """``Piecewise((e1, c1), ..., (en, True))`` as nested ``if_else`` (the last condition must be True)."""
        expr, cond = pieces[-1]
        if cond is not sp.true:
            raise ValueError(f"cannot emit a Piecewise without a final (expr, True) piece: {pieces}")
        out = self._convert(expr)
        for expr, cond in reversed(pieces[:-1]):
            out = ca.if_else(self._convert(cond), self._convert(expr), out)
        return out

    def _mul(self, e: sp.Mul) -> ca.SX:
        # Group denominators: a*b/(c*d) costs one division instead of two.
        sign = 1.0
        num: List[ca.SX] = []
        den: List[ca.SX] = []
        for a in e.args:
            if a.is_Number and a == -1:
                sign = -sign
            elif a.is_Pow and a.args[1].is_Integer and a.args[1] < 0:
                den.append(self._pow(a.args[0], -a.args[1]))
            elif a.is_Rational and not a.is_Integer and a.p in (1, -1):
                den.append(ca.SX(float(a.q)))
                sign = sign * a.p
            else:
                num.append(self._convert(a))
        out = num[0] if num else ca.SX(1.0)
        for a in num[1:]:
            out = out * a
        if den:
            d = den[0]
            for a in den[1:]:
                d = d * a
            out = out / d
        return -out if sign < 0 else out

    def _pow(self, base: sp.Basic, expo: sp.Basic) -> ca.SX:
        b = self._convert(base)
        if expo.is_Integer:
            k = int(expo)
            if k < 0:
                return 1.0 / self._pow(base, -expo)
            if k == 0:
                return ca.SX(1.0)
            out = b
            for _ in range(k - 1):
                out = out * b
            return out
        if expo == sp.Rational(1, 2):
            return ca.sqrt(b)
        raise ValueError(f"cannot emit power with exponent {expo}")


def state_symbols(m):
    """``(x, p, bindings)``: SX symbols of model ``m``'s state ``x`` (4n) and parameters ``p``, and the SymPy
    state and parameter symbols bound to their entries (the bindings of :class:`SympyToSX`)."""
    x = ca.SX.sym("x", 4 * m.n)
    p = ca.SX.sym("p", len(m.params))
    bindings = {s: x[i] for i, s in enumerate(m.state)}
    bindings.update({s: p[j] for j, s in enumerate(m.param_symbols)})
    return x, p, bindings


_SKEW_FNS: Dict[int, ca.Function] = {}


def skew_congruence(W: ca.SX, M: ca.SX) -> ca.SX:
    """``W M W`` for a symmetric ``W`` and a skew-symmetric ``M`` (SX, (n, n)), itself skew.

    Only the strict upper triangle is formed (``M W`` once, then one row of ``W`` per entry), and
    ``M``'s diagonal is taken as zero: about 1.5 n^3 products instead of 2 n^3.
    """
    n = W.shape[0]
    if n not in _SKEW_FNS:
        w, m = ca.SX.sym("W", n, n), ca.SX.sym("M", n, n)
        Y = [[sum((m[i, k] * w[k, j] for k in range(n) if k != i), ca.SX(0)) for j in range(n)] for i in range(n)]
        Z = ca.SX(n, n)
        for i in range(n):
            for j in range(i + 1, n):
                Z[i, j] = sum((w[i, k] * Y[k][j] for k in range(n)), ca.SX(0))
                Z[j, i] = -Z[i, j]
        _SKEW_FNS[n] = ca.Function(f"skew_congruence_{n}", [w, m], [Z])
    return _SKEW_FNS[n](W, M)
