"""Build the CasADi SX Functions of one model from its :class:`Linearization`.

Every Function has the signature ``(x, p) -> (value,)`` with ``x`` of length
4n (``[q; dq; q_m; dq_m]``) and ``p`` of length ``len(param_names)``.
The implicit symbols of the derivation are bound here to numeric linear
algebra on D(q): ``y3 = D^-1 r3`` through one LDL^T factorization. ``T`` and
``alpha`` call the model's elastic kernel (:mod:`derive.emit.dynamics`: ``y3``, ``y4``,
``alpha`` and ``beta`` from the time derivatives of the inverse dynamics); the SymPy route
(``y4 = D^-1 rhs4``, the implicit ``alpha``) is ``route="symbolic"``, for cross-checks.

The brackets ``ad = [g, ad_f g, ad_f^2 g, ad_f^3 g]`` are their closed form for the reduced
model (:mod:`derive.emit.brackets`, docs/derivation.md, "Brackets in closed form").
:func:`ad_by_ad`, CasADi forward-mode AD of ``ad_f v`` over the SX of ``f``, is the generic
construction the tests compare it with.
"""

from __future__ import annotations

from typing import Dict, Tuple

import casadi as ca

from ..core.linearize import Linearization
from .brackets import closed_form_brackets
from .dynamics import build_kernel, elastic_kernel, state_bodies, sx_function
from .ldl import ldl_factor, ldl_solve
from .sx import SympyToSX, state_symbols

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



def ad_by_ad(x: ca.SX, D: ca.SX, r3: ca.SX, acc_m: ca.SX, g: ca.SX, factors, k: int = 3) -> ca.SX:
    """``[g, ad_f g, ..., ad_f^k g]`` (paper's sign) by CasADi forward-mode AD.

    ``ad_f v = (df/dx) v - (dv/dx) f`` with ``f = [dq; y3; dq_m; acc_m]`` and
    ``y3 = D^-1 r3``; ``(df/dx) v`` takes the link-acceleration row implicitly,
    ``D_v y3 = D^-1 (D_v r3 - (D_v D) y3)``, with the LDL^T ``factors`` of D.

    Parameters
    ----------
    x : casadi.SX, shape (4n, 1)
        State symbols ``[q; dq; q_m; dq_m]``.
    D : casadi.SX, shape (n, n)
    r3 : casadi.SX, shape (n, 1)
        ``-(h + K (q - q_m))``.
    acc_m : casadi.SX, shape (n, 1)
        Motor acceleration ``J_m^-1 (K (q - q_m) - B_m dq_m)``.
    g : casadi.SX, shape (4n, n)
    factors : tuple
        :func:`derive.emit.ldl.ldl_factor` of ``D``.
    k : int
        Number of brackets after ``g``.

    Returns
    -------
    casadi.SX, shape (4n, (k + 1) n)
    """
    n = D.shape[0]
    y3 = ldl_solve(factors, r3)
    f = ca.vertcat(x[n:2 * n], y3, x[3 * n:], acc_m)

    def df_along(v: ca.SX) -> ca.SX:  # (df/dx) v, one column
        dy3 = ldl_solve(factors, ca.jtimes(r3, x, v) - ca.mtimes(ca.jtimes(D, x, v), y3))
        return ca.vertcat(v[n:2 * n], dy3, v[3 * n:], ca.jtimes(acc_m, x, v))

    blocks = [g]
    for _ in range(k):
        V = blocks[-1]
        JfV = ca.horzcat(*[df_along(V[:, c]) for c in range(n)])
        blocks.append(JfV - ca.jtimes(V, x, f))
    return ca.horzcat(*blocks)


def build_model_functions(lin: Linearization, cse: bool = True,
                          route: str = "ad") -> Tuple[Dict[str, ca.Function], ca.Function]:
    """:func:`build_functions` and the elastic kernel its ``T`` and ``alpha`` call (:mod:`derive.emit.dynamics`).

    ``route="symbolic"`` converts the implicit SymPy ``T`` and ``alpha`` instead (needs
    ``linearize(..., symbolic=True)``): the independent route the tests compare with.
    """
    m = lin.model
    n = m.n
    x, p, bindings = state_symbols(m)
    lazy: Dict[str, object] = {}

    def factors():  # one LDL^T of D(q), shared by every solve
        if "ldl" not in lazy:
            lazy["ldl"] = ldl_factor(conv(m.D))
        return lazy["ldl"]

    def solved(key: str, rhs) -> ca.SX:
        if key not in lazy:
            if rhs is None:
                raise ValueError(f"{m.name}: y4 is bound only by linearize(..., symbolic=True)")
            lazy[key] = ldl_solve(factors(), conv(rhs))
        return lazy[key]

    implicit = {}
    for i in range(n):
        implicit[lin.Y3[i]] = lambda i=i: solved("y3", lin.rhs3)[i]
        implicit[lin.Y4[i]] = lambda i=i: solved("y4", lin.rhs4)[i]
    conv = SympyToSX(bindings, dict(m.program.definitions), implicit)

    kernel = None if route == "symbolic" else elastic_kernel(m, build_kernel(m))
    by_ad = {} if kernel is None else state_bodies(m, kernel)
    out = {}
    for name, _ in QUANTITIES:
        if name in by_ad:
            # one kernel call (itself CSE'd) and a few products: a CSE pass would find nothing more
            out[name] = sx_function(f"{m.name}_{name}", by_ad[name], [4 * n, len(m.params)], ["x", "p"],
                                    [name], cse=False)
            continue
        value = closed_form_brackets(m, x, p) if name == "ad" else conv(lin.outputs[name])
        if value.shape[1] == 1 and name != "energy":
            value = ca.vec(value)
        if cse:
            value = ca.cse(value)
        out[name] = ca.Function(f"{m.name}_{name}", [x, p], [value], ["x", "p"], [name])
    return out, kernel


def build_functions(lin: Linearization, cse: bool = True, route: str = "ad") -> Dict[str, ca.Function]:
    """SX Functions ``<model>_<quantity>`` for every entry of :data:`QUANTITIES`.

    Parameters
    ----------
    lin : Linearization
    cse : bool
        Run CasADi's common-subexpression elimination on each output (the
        emitted default; ``False`` exists so tests can check CSE == no-CSE).
    route : str
        ``"ad"`` (emitted): ``T`` and ``alpha`` by CasADi AD of the inverse dynamics
        (:mod:`derive.emit.dynamics`); ``"symbolic"``: from the implicit SymPy form of
        ``linearize(..., symbolic=True)`` (for cross-checks).

    Returns
    -------
    dict str -> casadi.Function
        Keyed by quantity name (``"alpha"``), Function named ``"<model>_alpha"``.
    """
    return build_model_functions(lin, cse, route)[0]
