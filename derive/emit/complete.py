"""CasADi Functions of a complete model (docs/complete-model.md): plant functions only.

``M(q) [ddq; ddq_m] = rhs(x) + [0; u]`` with ``M = [[D', S], [S^T, J_m]]``
(SPD, 2n x 2n) is solved numerically through one LDL^T factorization of M:
``f = [dq; a_l; dq_m; a_m]`` with ``[a_l; a_m] = M^-1 rhs`` and
``g = [0; (M^-1)_12; 0; (M^-1)_22]``. There is no static feedback
linearization to emit (see the model's REPORT.md, "Brackets").
"""

from __future__ import annotations

from typing import Dict, Tuple

import casadi as ca

from ..core.linearize import Linearization
from .ldl import ldl_factor, ldl_solve, spd_inverse
from .sx import SympyToSX, state_symbols

#: Quantities emitted for a complete model, in file order, with their meaning.
COMPLETE_QUANTITIES: Tuple[Tuple[str, str], ...] = (
    ("f", "drift vector field f(x) of the complete model, (4n,)"),
    ("g", "input vector fields g(x) = [0; (M^-1)_12; 0; (M^-1)_22] (depends on q through the coupling), (4n, n)"),
    ("energy", "total mechanical energy (links, rotors with spin coupling, springs, gravity), scalar"),
    ("inertia", "inertia matrix M(q) = [[D'(q), S(q)], [S(q)^T, J_m]] of [dq; dq_m], (2n, 2n)"),
    ("coupling", "rotor spin coupling S(q), S_ji = (J_m,i / N_i) z_j . z_i for j < i, (n, n)"),
)


def build_complete_functions(lin: Linearization, cse: bool = True) -> Dict[str, ca.Function]:
    """SX Functions ``<model>_<quantity>`` for every entry of :data:`COMPLETE_QUANTITIES`.

    Parameters
    ----------
    lin : Linearization
        From :func:`derive.core.linearize.complete_plant`.
    cse : bool
        CasADi common-subexpression elimination on each output.

    Returns
    -------
    dict str -> casadi.Function
        Signature ``(x (4n), p) -> (value,)``.
    """
    m = lin.model
    n = m.n
    x, p, bindings = state_symbols(m)
    conv = SympyToSX(bindings, dict(m.program.definitions), {})
    M = conv(lin.outputs["inertia"])
    factors = ldl_factor(M)
    acc = ldl_solve(factors, conv(lin.outputs["rhs"]))
    Minv = spd_inverse(factors)
    zero = ca.SX.zeros(n, n)
    values = {
        "f": ca.vertcat(x[n:2 * n], acc[:n], x[3 * n:], acc[n:]),
        "g": ca.vertcat(zero, Minv[:n, n:], zero, Minv[n:, n:]),
        "energy": conv(lin.outputs["energy"]),
        "inertia": M,
        "coupling": conv(lin.outputs["coupling"]),
    }
    out = {}
    for name, _ in COMPLETE_QUANTITIES:
        value = ca.cse(values[name]) if cse else values[name]
        out[name] = ca.Function(f"{m.name}_{name}", [x, p], [value], ["x", "p"], [name])
    return out
