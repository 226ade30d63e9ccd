"""The honest peer of the generated alpha/beta: CasADi SX + algorithmic differentiation.

Built from the SAME dynamics (the derive models' D(q), h(q, dq), K, J_m, B_m,
converted to SX with :class:`derive.emit.sx.SympyToSX`), with the link
acceleration ``y3 = D^-1 r3`` from the same kind of unpivoted LDL^T solve the
generated code uses, and every Lie derivative by CasADi AD
(Jacobian-vector products along ``f`` and ``g``)::

    y4 = jtimes(y3, x, f)        a = L_f y4 = jtimes(y4, x, f)
    b  = L_g y4 = jtimes(y4, x, g)
    generic:    [beta, -alpha] = b^-1 [I, a]  (one symbolic solve)
    structured: beta = J_m K^-1 D(q), alpha = -beta a   (b known in closed form)

The structured variant is what a CasADi user who read the paper would write;
both are measured and the faster one is the reported peer. Each is given as two Functions
(``alpha``, ``beta``) and as one (``core``: ``T = [q; dq; y3; y4]``, ``alpha``, ``beta`` jointly CSE'd),
the form of the generated laws' core.
Build-time tool (needs SymPy): used by ``python -m bench`` and the tests only.
"""
from __future__ import annotations

from typing import Dict

import casadi as ca


def peer_expressions(model_name: str):
    """SX ``(x, p, exprs)`` with ``exprs`` = dict of alpha/beta variants and y3, y4."""
    from derive.registry import build
    from derive.emit.ldl import ldl_factor, ldl_solve
    from derive.emit.sx import SympyToSX

    m = build(model_name)
    n = m.n
    x = ca.SX.sym("x", 4 * n)
    p = ca.SX.sym("p", len(m.params))
    bind = {s: x[i] for i, s in enumerate(m.state)}
    bind.update({s: p[j] for j, s in enumerate(m.param_symbols)})
    program = getattr(m, "program", None)  # named intermediates of D, h (if the model has them)
    conv = SympyToSX(bind, dict(program.definitions)) if program is not None else SympyToSX(bind)
    D = conv(m.D)
    h = conv(m.h)
    K = ca.vertcat(*[conv(k) for k in m.K])
    Jm = ca.vertcat(*[conv(j) for j in m.Jm])
    Bm = ca.vertcat(*[conv(b) for b in m.Bm])
    q, dq, qm, dqm = (x[i * n:(i + 1) * n] for i in range(4))
    r3 = -(h + K * (q - qm))
    y3 = ldl_solve(ldl_factor(D), r3)
    f = ca.vertcat(dq, y3, dqm, (K * (q - qm) - Bm * dqm) / Jm)
    g = ca.vertcat(ca.SX(3 * n, n), ca.diag(1.0 / Jm))
    y4 = ca.jtimes(y3, x, f)
    a = ca.jtimes(y4, x, f)
    b = ca.jtimes(y4, x, g)
    sol = ca.solve(b, ca.horzcat(ca.SX.eye(n), a))
    exprs = {
        "y3": y3, "y4": y4,
        "generic_alpha": -sol[:, n], "generic_beta": sol[:, :n],
    }
    beta_s = ca.mtimes(ca.diag(Jm / K), D)
    exprs["structured_alpha"] = -ca.mtimes(beta_s, a)
    exprs["structured_beta"] = beta_s
    exprs["T"] = ca.vertcat(q, dq, y3, y4)
    return x, p, exprs


def peer_functions(model_name: str, variant: str = "structured") -> Dict[str, ca.Function]:
    """SX Functions ``peer_<variant>_alpha/_beta(x, p)`` and ``peer_<variant>_core(x, p) -> (y_hat, alpha, beta)``
    (CSE'd like the generated ones)."""
    x, p, e = peer_expressions(model_name)
    alpha, beta = ca.vec(e[f"{variant}_alpha"]), e[f"{variant}_beta"]
    out = {q: ca.Function(f"peer_{variant}_{q}", [x, p], [ca.cse(val)], ["x", "p"], [q])
           for q, val in (("alpha", alpha), ("beta", beta))}
    out["core"] = ca.Function(f"peer_{variant}_core", [x, p], ca.cse([e["T"], alpha, beta]),
                              ["x", "p"], ["y_hat", "alpha", "beta"])
    return out
