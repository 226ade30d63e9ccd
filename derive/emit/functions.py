"""Build the CasADi SX Functions of one model from its :class:`Linearization`.

Every Function has the signature ``(x, p) -> (value,)`` with ``x`` of length
4n (``[q; dq; q_m; dq_m]``) and ``p`` of length ``len(param_names)``.
The implicit symbols of the derivation are bound here to numeric linear
algebra on D(q): ``y3 = D^-1 r3`` and ``y4 = D^-1 rhs4`` through one LDL^T
factorization, and ``Dinv`` through the same factors (brackets only).
"""

from __future__ import annotations

from typing import Dict, Tuple

import casadi as ca

from ..linearize import Linearization
from .sx import SympyToSX, ldl_factor, ldl_solve, spd_inverse

#: Quantities emitted for every model, in file order, with their meaning.
QUANTITIES: Tuple[Tuple[str, str], ...] = (
    ("f", "drift vector field f(x), (4n,)"),
    ("g", "input vector fields g(x) = [0; 0; 0; J_m^-1], (4n, n)"),
    ("ad", "brackets [g, ad_f g, ad_f^2 g, ad_f^3 g] (paper's sign), (4n, 4n)"),
    ("T", "linearizing coordinates [y1; y2; y3; y4] = [q; dq; ddq; dddq], (4n,)"),
    ("alpha", "alpha(x) = -L_g y4^-1 L_f y4, (n,)"),
    ("beta", "beta(x) = L_g y4^-1 = J_m K^-1 D(q), (n, n)"),
    ("energy", "total mechanical energy (links, motors, springs, gravity), scalar"),
    ("inertia", "link inertia matrix D(q), (n, n)"),
)

_NON_OPS = {ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST, ca.OP_PARAMETER}


def operation_count(fn: ca.Function) -> int:
    """Number of arithmetic operations of an SX Function (no inputs, outputs, constants)."""
    return sum(1 for k in range(fn.n_instructions()) if fn.instruction_id(k) not in _NON_OPS)



def build_functions(lin: Linearization, cse: bool = True) -> Dict[str, ca.Function]:
    """SX Functions ``<model>_<quantity>`` for every entry of :data:`QUANTITIES`.

    Parameters
    ----------
    lin : Linearization
    cse : bool
        Run CasADi's common-subexpression elimination on each output (the
        emitted default; ``False`` exists so tests can check CSE == no-CSE).

    Returns
    -------
    dict str -> casadi.Function
        Keyed by quantity name (``"alpha"``), Function named ``"<model>_alpha"``.
    """
    m = lin.model
    n = m.n
    x = ca.SX.sym("x", 4 * n)
    p = ca.SX.sym("p", len(m.params))
    bindings = {s: x[i] for i, s in enumerate(m.state)}
    bindings.update({s: p[j] for j, s in enumerate(m.param_symbols)})
    lazy: Dict[str, object] = {}

    def factors():  # one LDL^T of D(q), shared by every solve
        if "ldl" not in lazy:
            lazy["ldl"] = ldl_factor(conv(m.D))
        return lazy["ldl"]

    def solved(key: str, rhs) -> ca.SX:
        if key not in lazy:
            lazy[key] = ldl_solve(*factors(), conv(rhs))
        return lazy[key]

    def inverse() -> ca.SX:
        if "inv" not in lazy:
            lazy["inv"] = spd_inverse(*factors())
        return lazy["inv"]

    implicit = {}
    for i in range(n):
        implicit[lin.Y3[i]] = lambda i=i: solved("y3", lin.rhs3)[i]
        implicit[lin.Y4[i]] = lambda i=i: solved("y4", lin.rhs4)[i]
        for j in range(i, n):
            implicit[lin.W[i, j]] = lambda i=i, j=j: inverse()[i, j]
    conv = SympyToSX(bindings, dict(m.program.definitions), implicit)

    out = {}
    for name, _ in QUANTITIES:
        expr = lin.outputs[name]
        value = conv(expr)
        if expr.shape[1] == 1 and name != "energy":
            value = ca.vec(value)
        if cse:
            value = ca.cse(value)
        out[name] = ca.Function(f"{m.name}_{name}", [x, p], [value], ["x", "p"], [name])
    return out
