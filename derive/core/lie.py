"""Lie derivatives and Lie brackets, with the paper's sign convention.

Convention (the paper's, docs/design.md "Lie brackets")::

    ad_f v = [f, v] = (df/dx) v - (dv/dx) f

Isidori and Khalil define the bracket with the opposite sign,
``[f, v] = (dv/dx) f - (df/dx) v``. The two differ only by a factor -1 on
the odd iterates ad_f^1 g and ad_f^3 g; ranks and involutivity, hence the
feedback-linearizability test, are unaffected. We follow the paper so that
its printed bracket matrix (erratum 5) is reproduced entry by entry.

Two implementations live here:

* :func:`lie_bracket` / :func:`ad_iterates` work on explicit SymPy matrices
  with full Jacobians. They are the simple reference, fine for small models.
* :class:`DirectionalDerivative` is a memoised forward-mode directional
  derivative over the expression tree. It is what scales: it never forms a
  Jacobian, visits every shared sub-expression once, and supports *implicit*
  symbols (such as the entries of D(q)^-1, or the link acceleration) whose
  derivative is given by a rule instead of an explicit formula.

Pure functions of symbols: no I/O.
"""

from __future__ import annotations

from typing import Callable, Dict, Mapping, Optional, Sequence

import sympy as sp


def lie_derivative(h: sp.Matrix, f: sp.Matrix, x: Sequence[sp.Symbol]) -> sp.Matrix:
    """Lie derivative ``L_f h = (dh/dx) f``.

    Parameters
    ----------
    h : sympy.Matrix, shape (m, 1) or (m, k)
        Scalar or vector function (each column differentiated separately).
    f : sympy.Matrix, shape (N, 1)
        Vector field.
    x : sequence of sympy.Symbol, length N
        Coordinates.

    Returns
    -------
    sympy.Matrix, same shape as ``h``
    """
    return h.jacobian(x) * f if h.shape[1] == 1 else sp.Matrix.hstack(
        *[h[:, j].jacobian(x) * f for j in range(h.shape[1])]
    )


def lie_bracket(f: sp.Matrix, v: sp.Matrix, x: Sequence[sp.Symbol]) -> sp.Matrix:
    """Lie bracket with the paper's sign: ``ad_f v = (df/dx) v - (dv/dx) f``.

    Parameters
    ----------
    f : sympy.Matrix, shape (N, 1)
    v : sympy.Matrix, shape (N, 1) or (N, k)
        One vector field per column.
    x : sequence of sympy.Symbol, length N

    Returns
    -------
    sympy.Matrix, shape of ``v``
    """
    Jf = f.jacobian(x)
    cols = [Jf * v[:, j] - v[:, j].jacobian(x) * f for j in range(v.shape[1])]
    return sp.Matrix.hstack(*cols).applyfunc(sp.expand)


def ad_iterates(f: sp.Matrix, g: sp.Matrix, x: Sequence[sp.Symbol], k: int) -> sp.Matrix:
    """``[g, ad_f g, ..., ad_f^k g]`` stacked column-block-wise.

    Returns
    -------
    sympy.Matrix, shape (N, (k + 1) * g.shape[1])
    """
    blocks = [g]
    for _ in range(k):
        blocks.append(lie_bracket(f, blocks[-1], x))
    return sp.Matrix.hstack(*blocks)


class DirectionalDerivative:
    """Memoised forward-mode derivative of expressions along one direction.

    ``d(e) = sum_s (de/ds) * seed[s]`` over the symbols ``s`` of ``e``; a
    symbol missing from ``seeds`` has derivative zero. Each distinct
    sub-expression is differentiated once per instance (memo on the node), so
    the cost is linear in the size of the expression DAG, unlike summing
    ``sympy.diff`` over every coordinate.

    Parameters
    ----------
    seeds : mapping sympy.Symbol -> sympy.Expr
        Derivative of each symbol along the direction (e.g. ``q -> dq``).
    lazy_seeds : mapping sympy.Symbol -> callable, optional
        Seeds computed on first use (for implicit symbols whose rule is
        expensive, such as the entries of D^-1).
    program : derive.core.program.Program, optional
        Defined intermediate symbols. Their derivative is the derivative of
        their definition, itself defined in the program as a new symbol
        named after ``tag``, so repeated use costs nothing.
    tag : str
        Name of this direction (unique per direction within a program).
    """

    def __init__(self, seeds: Mapping[sp.Symbol, sp.Expr],
                 lazy_seeds: Optional[Mapping[sp.Symbol, Callable[[], sp.Expr]]] = None,
                 program=None, tag: str = ""):
        self._seeds: Dict[sp.Symbol, sp.Expr] = dict(seeds)
        self._lazy = dict(lazy_seeds or {})
        self._memo: Dict[sp.Basic, sp.Expr] = {}
        self._program = program
        self._tag = tag

    def add_lazy_seed(self, s: sp.Symbol, rule: Callable[[], sp.Expr]) -> None:
        """Register a seed computed on first use (may call this instance)."""
        self._lazy[s] = rule

    def _seed(self, s: sp.Symbol) -> sp.Expr:
        if s not in self._seeds:
            if s in self._lazy:
                self._seeds[s] = self._lazy.pop(s)()
            elif self._program is not None and s in self._program:
                self._seeds[s] = self._program.derivative(s, self._tag, self._d)
        return self._seeds.get(s, sp.Integer(0))

    def __call__(self, e):
        """Derivative of an expression or (elementwise) of a matrix."""
        if isinstance(e, sp.MatrixBase):
            return e.applyfunc(self._d)
        return self._d(sp.sympify(e))

    def _d(self, e: sp.Basic) -> sp.Expr:
        hit = self._memo.get(e)
        if hit is not None:
            return hit
        if e.is_Symbol:
            out = self._seed(e)
        elif e.is_Number:
            out = sp.Integer(0)
        elif e.is_Add:
            out = sp.Add(*[self._d(a) for a in e.args])
        elif e.is_Mul:
            terms = []
            for i, a in enumerate(e.args):
                da = self._d(a)
                if da != 0:
                    terms.append(sp.Mul(*(e.args[:i] + (da,) + e.args[i + 1:])))
            out = sp.Add(*terms)
        elif e.is_Pow:
            base, expo = e.args
            if expo.is_Number:
                db = self._d(base)
                out = expo * base ** (expo - 1) * db if db != 0 else sp.Integer(0)
            else:  # not produced by our models; exact fallback
                out = self._fallback(e)
        elif isinstance(e, sp.sin):
            out = sp.cos(e.args[0]) * self._d(e.args[0])
        elif isinstance(e, sp.cos):
            out = -sp.sin(e.args[0]) * self._d(e.args[0])
        else:
            out = self._fallback(e)
        self._memo[e] = out
        return out

    def _fallback(self, e: sp.Basic) -> sp.Expr:
        syms = sorted(e.free_symbols, key=sp.default_sort_key)
        return sp.Add(*[sp.diff(e, s) * self._seed(s) for s in syms])
