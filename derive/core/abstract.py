"""Abstract scalar functions with their derivatives, for deriving through a law substituted later.

A nonlinear spring ``psi(phi)`` or a motor friction ``F(v)`` enters the derivation as a chain of SymPy
function classes ``(h, h', h'', ...)`` whose derivative is the next one, so that SymPy's chain rule
carries them through every Lie derivative and bracket; the law replaces them at the end. Keeping
them abstract keeps the paper's determinants small. Pure math: no I/O.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Dict, Tuple

import sympy as sp

__all__ = ["derivative_chain", "law_derivative", "substitute_chain"]

_CHAINS: Dict[Tuple[str, int], Tuple[type, ...]] = {}


def derivative_chain(stem: str, joint: int, orders: int, what: str) -> Tuple[type, ...]:
    """``(h, h', ..., h^(orders-1))`` of joint ``joint`` as SymPy function classes (cached per stem, joint).

    Parameters
    ----------
    stem : str
        Name stem: the classes are ``<stem><joint>``, ``<stem><joint>_d1``, ... (they name the
        functions in the report).
    joint : int
        Joint number, 1-based.
    orders : int
        How many classes; asking for the derivative of the last one is an error.
    what : str
        What the function is, for that error (``"spring"``, ``"friction"``).
    """
    key = (stem, joint)
    if key not in _CHAINS:
        def make(k: int) -> type:
            def fdiff(self, argindex=1):
                if k + 1 >= orders:
                    raise ValueError(f"{what} derivative of order {k + 1} requested; only {orders - 1} are defined")
                return _CHAINS[key][k + 1](self.args[0])
            name = f"{stem}{joint}" if k == 0 else f"{stem}{joint}_d{k}"
            return type(name, (sp.Function,), {"nargs": 1, "fdiff": fdiff, "order": k, "joint": joint})
        _CHAINS[key] = tuple(make(k) for k in range(orders))
    return _CHAINS[key]


@lru_cache(maxsize=None)
def _derivative_template(law, k: int) -> Tuple[sp.Dummy, sp.Expr]:
    """``(a, law^(k)(a))`` once per law and order (a piecewise law's derivatives take a while to form)."""
    a = sp.Dummy("a", real=True)
    return a, sp.diff(law(a), a, k)


def law_derivative(law, k: int, x: sp.Expr) -> sp.Expr:
    """``law^(k)(x)``: the k-th derivative of the scalar law ``law(a)`` (a hashable callable, e.g. a
    frozen dataclass's bound method), at ``x``."""
    if not k:
        return law(x)
    a, expr = _derivative_template(law, k)
    return expr.subs(a, x)


def substitute_chain(e, chain: Tuple[type, ...], derivative):
    """``e`` with every ``chain[k](x)`` replaced by ``derivative(k, x)`` (the law for the abstract function)."""
    for k, cls in enumerate(chain):
        e = e.replace(cls, lambda x, k=k: derivative(k, x))
    return e
