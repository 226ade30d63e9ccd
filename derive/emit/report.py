"""``generated/<model>/REPORT.md``: what was derived, how big it is, and a numeric check.

The controllability condition of feedback linearization (rank of
``[g, ad_f g, ad_f^2 g, ad_f^3 g]`` = 4n, involutivity of
``span{g, ad_f g, ad_f^2 g}``) is checked numerically on seeded sample
states with the emitted CasADi functions themselves: brackets of the
distribution's columns by one forward-mode AD pass per column (no Jacobian of
the bracket matrix is formed, so the check stays cheap for long chains). Numbers are printed with few
significant digits so that the file stays byte-identical across runs.
"""

from __future__ import annotations

from typing import Dict, List

import casadi as ca
import numpy as np
import sympy as sp

from ..core.linearize import Linearization

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


def _sample_state(rng, n: int, deflection=None) -> np.ndarray:
    """A random state; ``deflection`` (n,), if given: ``q_m = q + phi``, ``|phi|`` up to it (a spring law's range)."""
    if deflection is None:
        return np.concatenate([rng.uniform(-1.5, 1.5, n), rng.uniform(-1, 1, n),
                               rng.uniform(-1.5, 1.5, n), rng.uniform(-1, 1, n)])
    q, dq = rng.uniform(-1.5, 1.5, n), rng.uniform(-1, 1, n)
    return np.concatenate([q, dq, q + rng.uniform(-1, 1, n) * np.asarray(deflection), rng.uniform(-1, 1, n)])


def bracket_functions(x: ca.SX, A: ca.SX, n: int):
    """Numeric evaluators of the bracket matrix and of its distribution's directional derivatives.

    Parameters
    ----------
    x : casadi.SX, shape (4n, 1)
    A : casadi.SX, shape (4n, 4n)
        ``[g, ad_f g, ad_f^2 g, ad_f^3 g]`` as an SX expression of ``x``.
    n : int

    Returns
    -------
    (casadi.Function, casadi.Function)
        ``x -> A`` and ``(x, v) -> (d Delta / dx) v`` (4n, 3n): column ``b`` is the derivative of the
        distribution's column ``b`` along ``v``, one forward pass (no Jacobian is formed).
    """
    v = ca.SX.sym("v", 4 * n)
    return (ca.Function("brackets", [x], [A]),
            ca.Function("d_dist", [x, v], [ca.jtimes(A[:, :3 * n], x, v)]))


def pairwise_brackets(d_dist: ca.Function, xs: np.ndarray, cols: np.ndarray) -> List[np.ndarray]:
    """``[X_a, X_b] = (dX_b/dx) X_a - (dX_a/dx) X_b`` for every pair ``a < b`` of ``cols`` (4n, 3n)."""
    m = cols.shape[1]
    along = [np.array(d_dist(xs, cols[:, a])) for a in range(m)]  # along[a][:, b] = (dX_b/dx) X_a
    return [along[a][:, b] - along[b][:, a] for a in range(m) for b in range(a + 1, m)]


def controllability_check(functions: Dict[str, ca.Function], n: int, defaults: np.ndarray,
                          samples: int = 5, seed: int = 0, deflection=None) -> List[Dict[str, object]]:
    """Rank and involutivity residuals at seeded random states.

    The brackets of pairs of distribution columns are taken numerically, by one
    forward-mode pass of the emitted ``ad`` per column (:func:`bracket_functions`).

    ``deflection`` (n,), optional: sample ``q_m - q`` within it (nonlinear springs' declared ranges).

    Returns
    -------
    list of dict
        Per sample: ``rank``, ``sigma_ratio`` (smallest / largest singular
        value of the bracket matrix), ``involutivity`` (largest relative
        residual of ``[v, w]`` outside ``span{g, ad_f g, ad_f^2 g}``).
    """
    x = ca.SX.sym("x", 4 * n)
    brackets, d_dist = bracket_functions(x, functions["ad"](x, defaults), n)
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(samples):
        xs = _sample_state(rng, n, deflection)
        A = np.array(brackets(xs))
        s = np.linalg.svd(A, compute_uv=False)
        dist = A[:, :3 * n]
        Q, _ = np.linalg.qr(dist)
        worst = 0.0
        for br in pairwise_brackets(d_dist, xs, dist):
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


def _parameter_and_function_tables(m, functions, ops) -> List[str]:
    """The ``## Parameters`` and ``## Generated functions`` tables of a model's REPORT.md."""
    lines = ["## Parameters", "", "| name | default | meaning | unit |", "|---|---|---|---|"]
    lines += [f"| `{p.name}` | {p.default:g} | {p.meaning} | {p.unit} |" for p in m.params]
    lines += ["", "## Generated functions", "", "| function | output shape | operations |", "|---|---|---|"]
    for name, fn in functions.items():
        lines.append(f"| `{m.name}_{name}` | {fn.size_out(0)[0]} x {fn.size_out(0)[1]} | {ops[name]} |")
    return lines


def render_report(lin: Linearization, functions: Dict[str, ca.Function], ops: Dict[str, int],
                  header: str) -> str:
    """The Markdown text of ``REPORT.md`` for one model."""
    m = lin.model
    n = m.n
    lines = [f"<!-- {header} -->", f"# {m.name}", "", m.description, "",
             f"State $x = [q; \\dot q; q_m; \\dot q_m]$ ({4 * n} entries), input $u$ ({n} motor torques).",
             ""]
    lines += _parameter_and_function_tables(m, functions, ops)
    lines += ["", f"Named intermediate symbols in the derivation program: {len(m.program.definitions)}.", ""]
    if m.name == "link1":
        lines += _link1_latex(lin)
    defaults = np.array([p.default for p in m.params])
    lines += ["## Feedback-linearizability, checked numerically", "",
              *controllability_lines(functions, n, defaults), ""]
    return "\n".join(lines)


def controllability_lines(functions: Dict[str, ca.Function], n: int, defaults: np.ndarray,
                          deflection=None) -> List[str]:
    """The report's paragraph and table of :func:`controllability_check` (``deflection``: passed on)."""
    rows = controllability_check(functions, n, defaults, deflection=deflection)
    where = "deflections within the declared ranges, default parameters" if deflection is not None \
        else "default parameters"
    lines = [f"At {len(rows)} seeded random states ({where}): rank of "
             f"$[g, ad_f g, ad_f^2 g, ad_f^3 g]$ (must be {4 * n}), smallest/largest singular value, "
             "and the largest relative residual of a bracket $[v, w]$ of two columns of "
             "$\\{g, ad_f g, ad_f^2 g\\}$ outside their span (involutivity; must be ~0).", "",
             "| sample | rank | sigma_min / sigma_max | involutivity residual |", "|---|---|---|---|"]
    return lines + [f"| {i} | {r['rank']} | {r['sigma_ratio']:.1e} | {_fmt(r['involutivity'])} |"
                    for i, r in enumerate(rows)]


#: Relative singular-value threshold of the complete model's bracket ranks.
RANK_THRESHOLD = 1e-8


def complete_brackets(f_fn: ca.Function, g_fn: ca.Function, n: int, params: np.ndarray,
                      samples: int = 3, seed: int = 0) -> List[Dict[str, object]]:
    """The paper's test on emitted ``f``, ``g`` (CasADi AD): rank of ``[g, ad_f g, ad_f^2 g, ad_f^3 g]``
    and involutivity of ``span{g, ad_f g, ad_f^2 g}`` at seeded random states.

    Columns are normalized before the SVD; a bracket ``[X_a, X_b]`` is divided by
    ``|X_a| |X_b|``. Rank = number of singular values above
    :data:`RANK_THRESHOLD` times the largest.

    Returns
    -------
    list of dict
        Per sample: ``rank4`` (of the 4n x 4n bracket matrix), ``rank3`` (of the
        distribution, 3n if regular), ``rank3_closed`` (with every pairwise bracket
        added: 3n iff involutive), ``gap`` = (sigma_3n, sigma_3n+1) / sigma_1 of the closed set.
    """
    x = ca.SX.sym("x", 4 * n)
    F, G = f_fn(x, params), g_fn(x, params)

    def ad(B):  # (dF/dx) B - (dB/dx) F, column by column (forward mode, no Jacobian)
        return ca.horzcat(*[ca.jtimes(F, x, B[:, c]) for c in range(n)]) - ca.jtimes(B, x, F)

    blocks = [G]
    for _ in range(3):
        blocks.append(ad(blocks[-1]))
    brackets, d_dist = bracket_functions(x, ca.horzcat(*blocks), n)
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(samples):
        xs = _sample_state(rng, n)
        A = np.array(brackets(xs))
        cols = A[:, :3 * n]
        norms = np.linalg.norm(cols, axis=0)
        extra = [br / (norms[a] * norms[b]) for br, (a, b) in
                 zip(pairwise_brackets(d_dist, xs, cols),
                     [(a, b) for a in range(3 * n) for b in range(a + 1, 3 * n)])]
        closed = np.column_stack([cols / norms] + extra)

        def rank(Mx):
            s = np.linalg.svd(Mx, compute_uv=False)
            return int(np.sum(s > RANK_THRESHOLD * s[0])), s / s[0]

        r4, _ = rank(A / np.linalg.norm(A, axis=0))
        r3, _ = rank(cols / norms)
        rc, sc = rank(closed)
        rows.append({"rank4": r4, "rank3": r3, "rank3_closed": rc,
                     "gap": (float(sc[3 * n - 1]), float(sc[3 * n]) if len(sc) > 3 * n else 0.0)})
    return rows


def static_fl_verdict(rows: List[Dict[str, object]], n: int) -> bool:
    """True when every sample has full bracket rank 4n and an involutive (rank 3n, closed) distribution."""
    return all(r["rank4"] == 4 * n and r["rank3"] == 3 * n and r["rank3_closed"] == 3 * n for r in rows)


def render_complete_report(lin: Linearization, functions: Dict[str, ca.Function], ops: Dict[str, int],
                           header: str) -> str:
    """The Markdown text of ``REPORT.md`` for a complete model (plant functions and the bracket test)."""
    m = lin.model
    n = m.n
    lines = [f"<!-- {header} -->", f"# {m.name}", "", m.description, "",
             f"Complete elastic model (docs/complete-model.md); reduced model: `{m.reduced_model}`. "
             f"State $x = [q; \\dot q; q_m; \\dot q_m]$ ({4 * n} entries), input $u$ ({n} motor torques).",
             ""]
    lines += _parameter_and_function_tables(m, functions, ops)
    defaults = np.array([p.default for p in m.params])
    rows = complete_brackets(functions["f"], functions["g"], n, defaults)
    verdict = static_fl_verdict(rows, n)
    lines += ["", "## Brackets: does static feedback linearization exist?", "",
              f"At {len(rows)} seeded random states (default parameters), by CasADi AD on the emitted f and g: "
              f"rank of $[g, ad_f g, ad_f^2 g, ad_f^3 g]$ (needs {4 * n}), rank of "
              f"$\\Delta = span\\{{g, ad_f g, ad_f^2 g\\}}$ (needs {3 * n}) and of $\\Delta$ with all pairwise "
              f"brackets added (involutive iff {3 * n}); normalized columns, threshold {RANK_THRESHOLD:.0e} "
              "of the largest singular value; the gap is $\\sigma_{3n}$, $\\sigma_{3n+1}$ of the closed set.", "",
              "| sample | rank [g .. ad^3 g] | rank Delta | rank with brackets | sigma_3n / sigma_1 | "
              "sigma_3n+1 / sigma_1 |", "|---|---|---|---|---|---|"]
    for i, r in enumerate(rows):
        lines.append(f"| {i} | {r['rank4']} | {r['rank3']} | {r['rank3_closed']} | {r['gap'][0]:.1e} | "
                     f"{_fmt(r['gap'][1])} |")
    lines += ["", "Static feedback linearization: " + (
        "**exists** (full rank, involutive)." if verdict else
        f"**does not exist** at these states; the emitted plant functions are for simulation and for "
        f"laws built on `{m.reduced_model}`."), ""]
    return "\n".join(lines)
