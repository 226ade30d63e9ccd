"""The bracket matrix ``ad = [g, ad_f g, ad_f^2 g, ad_f^3 g]`` of the reduced model, in closed form.

With ``x = [q; dq; q_m; dq_m]``, ``A = J_m^-1``, ``B = B_m``, ``K`` (all diagonal),
``W = D(q)^-1`` and the paper's sign ``ad_f v = (df/dx) v - (dv/dx) f``, the drift
``f = [dq; W r3; dq_m; A (K (q - q_m) - B dq_m)]``, ``r3 = -(h(q, dq) + K (q - q_m))`` and
``g = [0; 0; 0; A]`` give, block row by block row (docs/derivation.md, "Brackets in closed form")::

    g        = [0; 0;                  0;             A          ]
    ad_f g   = [0; 0;                  A;            -A B A      ]
    ad_f^2 g = [0; X;                 -A B A;        -A K A + A B A B A]
    ad_f^3 g = [X; W (D' - dh/ddq) X - X B A;  -A K A + A B A B A;  2 A K A B A - A B A B A B A]

    X = W K A,    D' = sum_i (dD/dq_i) dq_i

Only the two link-velocity rows depend on the state, and only through ``D``, ``D'`` and
``dh/ddq``: the brackets need no derivative of ``W`` or of the link acceleration, which is
what made the generic construction (:func:`derive.emit.functions.ad_by_ad`, kept as the tests'
reference) the largest function of a spatial model.

Two builds of the same blocks:

- :func:`closed_form_brackets` (SX, the ``.casadi`` file): ``D' - dh/ddq = N^T - N`` with
  ``N = d(D(q) dq)/dq`` (``dq`` held; Christoffel's identity for ``h = C dq + G``, see below) by
  forward-mode AD of the gravity-free inverse dynamics, ``W`` by a symmetric inverse of the
  ``LDL^T`` factors and ``W (N^T - N) W`` as a skew congruence (its upper triangle only);
- :func:`bracket_twin` (MX, the C file): column ``j`` of ``X`` and of the third bracket by one
  small SX Function (two LDL^T solves and ``(D' - dh/ddq) v`` as forward derivatives of the
  inverse dynamics) mapped over the ``n`` columns, so the C holds one column's arithmetic in a
  loop, not ``n`` copies of it.

Why ``N^T - N``: with ``h = C dq + G`` and the Christoffel ``C``, ``D' = C + C^T`` and
``dh/ddq = 2 C``, so ``D' - dh/ddq = C^T - C``, and entry by entry
``(C^T - C)_ij = d(D dq)_j/dq_i - d(D dq)_i/dq_j``. ``D(q) dq`` has no velocity products, so its
Jacobian costs about half of ``dh/ddq`` (21 joints: 24.7k against 47.7k operations); the tests
compare the result with the generic construction on every built-in reduced model.
"""

from __future__ import annotations

from typing import Tuple

import casadi as ca

from .dynamics import elastic_diagonals, programme
from .ldl import ldl_factor, packed_factor_fn, packed_solve_fn, symmetric_inverse
from .sx import skew_congruence

__all__ = ["closed_form_brackets", "bracket_twin", "assemble_brackets", "coriolis_difference_along",
           "inertia_times"]


def _constant_rows(a, b, k) -> Tuple[object, object, object]:
    """Diagonals of ``A B A``, ``-A K A + A B A B A`` and ``2 A K A B A - A B A B A B A`` (column vectors)."""
    aba = a * a * b
    row2 = -a * a * k + a * aba * b
    row3 = 2 * a * a * a * k * b - aba * aba * b
    return aba, row2, row3


def assemble_brackets(a, b, k, X, R3):
    """``[g, ad_f g, ad_f^2 g, ad_f^3 g]`` (4n, 4n) from the diagonals and the two state-dependent blocks.

    Parameters
    ----------
    a, b, k : casadi.SX or casadi.MX, shape (n, 1)
        Diagonals of ``J_m^-1``, ``B_m`` and ``K``.
    X : shape (n, n)
        ``W K A`` (``W = D^-1``).
    R3 : shape (n, n)
        ``W (D' - dh/ddq) X - X B A``: the link-velocity row of ``ad_f^3 g``.
    """
    n = a.shape[0]
    zero = type(X).zeros(n, n)
    aba, row2, row3 = _constant_rows(a, b, k)
    g = ca.vertcat(zero, zero, zero, ca.diag(a))
    ad1 = ca.vertcat(zero, zero, ca.diag(a), -ca.diag(aba))
    ad2 = ca.vertcat(zero, X, -ca.diag(aba), ca.diag(row2))
    ad3 = ca.vertcat(X, R3, ca.diag(row2), ca.diag(row3))
    return ca.horzcat(g, ad1, ad2, ad3)


def closed_form_brackets(model, x: ca.SX, p: ca.SX) -> ca.SX:
    """The bracket matrix as one SX expression of ``x`` (4n) and ``p`` (see the module docstring).

    Returns
    -------
    casadi.SX, shape (4n, 4n)
    """
    n = model.n
    q, dq = x[:n], x[n:2 * n]
    D = programme(model)(q, dq, ca.SX.zeros(n), p)[0]
    k, jm, b = elastic_diagonals(model, p)
    a = 1 / jm
    W = symmetric_inverse(ldl_factor(D))
    X = ca.mtimes(W, ca.diag(k * a))
    N = ca.jacobian(inertia_times(model, q, dq, p), q)  # d(D(q) dq)/dq, dq held
    R3 = ca.mtimes(skew_congruence(W, N.T - N), ca.diag(k * a)) - ca.mtimes(X, ca.diag(b * a))
    return assemble_brackets(a, b, k, X, R3)


def inertia_times(model, q, v, p):
    """``D(q) v`` as the inverse dynamics ``tau(q, 0, v)`` with gravity switched off (SX, (n, 1)).

    ``g0 = 0`` in ``p``; a model without a ``g0`` parameter subtracts ``tau(q, 0, 0)`` instead.
    """
    n = model.n
    prog, zero = programme(model), ca.SX.zeros(n)
    names = list(model.param_names)
    if "g0" in names:
        i = names.index("g0")
        return prog(q, zero, v, ca.vertcat(p[:i], ca.SX(0), p[i + 1:]))[2]
    return prog(q, zero, v, p)[2] - prog(q, zero, zero, p)[2]


def coriolis_difference_along(model, q, dq, v, p):
    """``(D'(q, dq) - dh/ddq(q, dq)) v`` by forward derivatives of the inverse dynamics ``tau(q, dq, a)``.

    ``D' v`` is the derivative of ``D(q) v`` (:func:`inertia_times`) along ``q' = dq``; ``dh/ddq v``
    that of ``tau(q, dq, 0) = h`` along ``dq' = v``. (SX, (n, 1).)
    """
    zero = ca.SX.zeros(model.n)
    return ca.jtimes(inertia_times(model, q, v, p), q, dq) - ca.jtimes(programme(model)(q, dq, zero, p)[2], dq, v)


def _column_function(model) -> ca.Function:
    """``(q, dq, N, r, c, ba, p) -> (x_j, r_j)``: column j of ``X`` and of ``R3`` from ``c = (K A)_j e_j``.

    ``N``, ``r``: the packed (negated) LDL^T factors of ``A`` (:func:`derive.emit.ldl.packed_factor_fn`).
    """
    n = model.n
    q, dq, c = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("c", n)
    ba, p = ca.SX.sym("ba"), ca.SX.sym("p", len(model.params))
    N, r = ca.SX.sym("N", n * (n - 1) // 2), ca.SX.sym("r", n)
    solve = packed_solve_fn(n)
    xj = solve(N, r, c)
    rj = solve(N, r, coriolis_difference_along(model, q, dq, xj, p)) - xj * ba
    xj, rj = ca.cse([xj, rj])
    return ca.Function(f"{model.name}_bracket_column", [q, dq, N, r, c, ba, p], [xj, rj],
                       ["q", "dq", "N", "r", "c", "ba", "p"], ["x_j", "r_j"])


def bracket_twin(model, inertia: ca.Function) -> ca.Function:
    """The MX twin of the ``ad`` Function for the C file: same name, signature and value.

    Calls the model's ``inertia`` Function (already in the C file) and an LDL^T factorization,
    then maps :func:`_column_function` over the ``n`` columns (a loop in C).
    """
    n = model.n
    x, p = ca.MX.sym("x", 4 * n), ca.MX.sym("p", len(model.params))
    q, dq = x[:n], x[n:2 * n]
    k, jm, b = elastic_diagonals(model, p)
    a = 1 / jm
    N, r = packed_factor_fn(n)(inertia(x, p))
    columns = _column_function(model).map(n)
    X, R3 = columns(q, dq, N, r, ca.diag(k * a), (b * a).T, p)
    value = assemble_brackets(a, b, k, X, R3)
    return ca.Function(f"{model.name}_ad", [x, p], [value], ["x", "p"], ["ad"])
