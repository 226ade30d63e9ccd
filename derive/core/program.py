"""Straight-line programs of SymPy expressions: named intermediate symbols.

SymPy flattens nested sums and products, so an expression DAG such as the
suffix sums of a serial chain (``P_i = P_{i+1} + t_i``) turns into O(n)
terms per entry and O(n^2) overall, and every derivative pays for that
again. A :class:`Program` keeps such quantities as *defined symbols*
(``P_3 := P_4 + t_3``) in creation order. Derivatives of defined symbols
are themselves defined symbols (see :class:`derive.core.lie.DirectionalDerivative`),
so differentiation stays linear in the program size, and the emitter binds
the symbols one by one (creation order is a topological order).

Pure math: no I/O.
"""

from __future__ import annotations

from typing import Callable, Dict, List, Tuple

import sympy as sp


class Program:
    """Ordered definitions ``symbol := expression`` (expressions may use earlier symbols).

    Attributes
    ----------
    use_rules : bool
        Use the derivative shortcuts given to :meth:`define` (default True;
        False differentiates every definition, for cross-checks).
    """

    use_rules = True

    def __init__(self) -> None:
        self._defs: Dict[sp.Symbol, sp.Expr] = {}
        self._order: List[sp.Symbol] = []
        self._derivs: Dict[Tuple[sp.Symbol, str], sp.Expr] = {}
        self._rules: Dict[sp.Symbol, Callable] = {}

    def define(self, name: str, expr, rule: Callable = None) -> sp.Expr:
        """Define ``name := expr``; returns the symbol (or ``expr`` itself if it is atomic).

        ``rule``, if given, states the derivative more cheaply than
        differentiating ``expr`` would: ``rule(d)`` receives the directional
        derivative (a callable on expressions) and returns the derivative of
        the symbol along it. Example: for ``cr := c1 c2 + s1 s2`` (that is
        ``cos(theta1 - theta2)``), ``rule = lambda d: -sr * (d(theta1) - d(theta2))``.
        Tests compare every such shortcut against plain differentiation.
        """
        expr = sp.sympify(expr)
        if expr.is_Atom:  # a number or an existing symbol: nothing to name
            return expr
        sym = sp.Symbol(name, real=True)
        if sym in self._defs:
            raise ValueError(f"program symbol {name} defined twice")
        self._defs[sym] = expr
        self._order.append(sym)
        if rule is not None:
            self._rules[sym] = rule
        return sym

    def __contains__(self, sym) -> bool:
        return sym in self._defs

    def definition(self, sym: sp.Symbol) -> sp.Expr:
        return self._defs[sym]

    @property
    def definitions(self) -> List[Tuple[sp.Symbol, sp.Expr]]:
        """All ``(symbol, expression)`` pairs in creation (= dependency) order."""
        return [(s, self._defs[s]) for s in self._order]

    def derivative(self, sym: sp.Symbol, tag: str, compute: Callable[[sp.Expr], sp.Expr]) -> sp.Expr:
        """Derivative of a defined symbol along direction ``tag`` (cached, defined on first use).

        ``compute`` differentiates the definition. A zero or atomic result is
        returned as is; otherwise it is defined as ``<sym>__d<tag>``.
        """
        key = (sym, tag)
        if key not in self._derivs:
            rule = self._rules.get(sym) if self.use_rules else None
            d = rule(compute) if rule is not None else compute(self._defs[sym])
            self._derivs[key] = self.define(f"{sym.name}__d{tag}", d)
        return self._derivs[key]

    def inline(self, expr):
        """Substitute every definition (for small models and tests only: no sharing)."""
        for sym in reversed(self._order):
            if isinstance(expr, sp.MatrixBase):
                expr = expr.xreplace({sym: self._defs[sym]})
            else:
                expr = sp.sympify(expr).xreplace({sym: self._defs[sym]})
        return expr
