"""``generated/<model>/REPORT.md``: what was derived, how big it is, and a numeric check.

The controllability condition of feedback linearization (rank of
``[g, ad_f g, ad_f^2 g, ad_f^3 g]`` = 4n, involutivity of
``span{g, ad_f g, ad_f^2 g}``) is checked numerically on seeded sample
states with the emitted CasADi functions themselves (brackets of the
distribution's columns by CasADi AD). Numbers are printed with few
significant digits so that the file stays byte-identical across runs.
"""

from __future__ import annotations

from typing import Dict, List

import casadi as ca
import numpy as np
import sympy as sp

from ..linearize import Linearization

#: The paper's printed link1 expressions (section 2), with the erratum each one carries.
PAPER_LINK1 = [
    ("g(x)", r"\begin{bmatrix}0&0&0&1\end{bmatrix}^T",
     "erratum 1: the last entry is $1/J_m$"),
    ("T_3", r"-\frac{MgL}{J_l}\sin x_1 - \frac{K}{J_m}(x_1 - x_3)",
     "erratum 2: the spring factor is $K/J_l$"),
    ("T_4", r"-\frac{MgL}{J_l}\cos(x_1) x_2 - \frac{K}{J_m}(x_2 - x_4)",
     "erratum 2: the spring factor is $K/J_l$"),
    ("u", r"\frac{J_l J_m}{K}(\nu - a(x))", "right: $\\beta = J_l J_m / K$, $\\alpha = -\\beta a$"),
    ("[g, ad_f g, ad_f^2 g, ad_f^3 g]",
     r"\begin{bmatrix}0&0&0&\frac{K}{J_lJ_m}\\0&0&\frac{K}{J_lJ_m}&0\\"
     r"0&\frac{1}{J_m}&0&-\frac{K}{J_m^2}\\\frac{1}{J_m}&0&-\frac{K}{J_m^2}&0\end{bmatrix}",
     "erratum 5: right with $ad_f v = (\\partial f/\\partial x) v - (\\partial v/\\partial x) f$ (at $B_m = 0$)"),
]


def _fmt(v: float) -> str:
    return "< 1e-12" if abs(v) < 1e-12 else f"{v:.1e}"


def controllability_check(functions: Dict[str, ca.Function], n: int, defaults: np.ndarray,
                          samples: int = 5, seed: int = 0) -> List[Dict[str, object]]:
    """Rank and involutivity residuals at seeded random states.

    Returns
    -------
    list of dict
        Per sample: ``rank``, ``sigma_ratio`` (smallest / largest singular
        value of the bracket matrix), ``involutivity`` (largest relative
        residual of ``[v, w]`` outside ``span{g, ad_f g, ad_f^2 g}``).
    """
    x = ca.SX.sym("x", 4 * n)
    ad = functions["ad"](x, defaults)
    # jac[:, c] blocks: d(ad[:, c])/dx, for the bracket [v, w] = (dw/dx) v - (dv/dx) w.
    jac = ca.Function("jac_ad", [x], [ca.jacobian(ca.vec(ad), x), ad])
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(samples):
        xs = np.concatenate([rng.uniform(-1.5, 1.5, n), rng.uniform(-1, 1, n),
                             rng.uniform(-1.5, 1.5, n), rng.uniform(-1, 1, n)])
        J, A = (np.array(v) for v in jac(xs))
        s = np.linalg.svd(A, compute_uv=False)
        dist = A[:, :3 * n]
        Q, _ = np.linalg.qr(dist)
        worst = 0.0
        dcol = [J[c * 4 * n:(c + 1) * 4 * n, :] for c in range(3 * n)]
        for a in range(3 * n):
            for b in range(a + 1, 3 * n):
                br = dcol[b] @ dist[:, a] - dcol[a] @ dist[:, b]
                nb = np.linalg.norm(br)
                if nb > 0:
                    worst = max(worst, np.linalg.norm(br - Q @ (Q.T @ br)) / max(nb, 1.0))
        rows.append({"rank": int(np.linalg.matrix_rank(A)), "sigma_ratio": float(s[-1] / s[0]),
                     "involutivity": worst})
    return rows


def _link1_latex(lin: Linearization) -> List[str]:
    m = lin.model
    Jl = m.D[0, 0]
    subs = {lin.Y3[0]: lin.rhs3[0] / Jl, lin.W[0, 0]: 1 / Jl}
    subs[lin.Y4[0]] = (lin.rhs4[0] / Jl).xreplace(subs)
    nice = lambda e: sp.latex(sp.simplify(sp.sympify(e).xreplace(subs).xreplace(subs)))
    out = lin.outputs
    lines = ["## Derived expressions (link1) next to the paper", "",
             "| quantity | derived by fjm | printed in the paper | note |", "|---|---|---|---|"]
    derived = {
        "g(x)": sp.latex(out["g"].T),
        "T_3": nice(out["T"][2]),
        "T_4": nice(out["T"][3]),
        "u": f"\\alpha + \\beta\\nu,\\ \\beta = {nice(out['beta'][0, 0])}",
        "[g, ad_f g, ad_f^2 g, ad_f^3 g]": sp.latex(out["ad"].applyfunc(
            lambda e: sp.simplify(sp.sympify(e).xreplace(subs)))),
    }
    for name, printed, note in PAPER_LINK1:
        lines.append(f"| ${name}$ | ${derived[name]}$ | ${printed}$ | {note} |")
    lines += ["", "Full derived expressions (with motor damping $B_m$; $y_3$, $y_4$ inlined):", "",
              f"- $f(x) = {sp.latex(sp.simplify(out['f'].xreplace(subs).T))}^T$",
              f"- $T(x) = {sp.latex(sp.simplify(out['T'].xreplace(subs).xreplace(subs).T))}^T$",
              f"- $\\alpha(x) = {nice(out['alpha'][0])}$",
              f"- $\\beta(x) = {nice(out['beta'][0, 0])}$", ""]
    return lines


def render_report(lin: Linearization, functions: Dict[str, ca.Function], ops: Dict[str, int],
                  header: str) -> str:
    """The Markdown text of ``REPORT.md`` for one model."""
    m = lin.model
    n = m.n
    lines = [f"<!-- {header} -->", f"# {m.name}", "", m.description, "",
             f"State $x = [q; \\dot q; q_m; \\dot q_m]$ ({4 * n} entries), input $u$ ({n} motor torques).",
             "", "## Parameters", "", "| name | default | meaning | unit |", "|---|---|---|---|"]
    lines += [f"| `{p.name}` | {p.default:g} | {p.meaning} | {p.unit} |" for p in m.params]
    lines += ["", "## Generated functions", "", "| function | output shape | operations |", "|---|---|---|"]
    for name, fn in functions.items():
        lines.append(f"| `{m.name}_{name}` | {fn.size_out(0)[0]} x {fn.size_out(0)[1]} | {ops[name]} |")
    lines += ["", f"Named intermediate symbols in the derivation program: {len(m.program.definitions)}.", ""]
    if m.name == "link1":
        lines += _link1_latex(lin)
    defaults = np.array([p.default for p in m.params])
    rows = controllability_check(functions, n, defaults)
    lines += ["## Feedback-linearizability, checked numerically", "",
              f"At {len(rows)} seeded random states (default parameters): rank of "
              f"$[g, ad_f g, ad_f^2 g, ad_f^3 g]$ (must be {4 * n}), smallest/largest singular value, "
              "and the largest relative residual of a bracket $[v, w]$ of two columns of "
              "$\\{g, ad_f g, ad_f^2 g\\}$ outside their span (involutivity; must be ~0).", "",
              "| sample | rank | sigma_min / sigma_max | involutivity residual |", "|---|---|---|---|"]
    for i, r in enumerate(rows):
        lines.append(f"| {i} | {r['rank']} | {r['sigma_ratio']:.1e} | {_fmt(r['involutivity'])} |")
    lines.append("")
    return "\n".join(lines)
