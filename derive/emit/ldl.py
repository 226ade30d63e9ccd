"""Unpivoted ``LDL^T`` of a symmetric positive definite SX matrix: factor, solves, inverse.

The factors are kept *negated*: ``N = -L`` (strict lower triangle of the unit factor) and
``r = -1/d`` (minus the reciprocal pivots), :class:`LDLFactors`. The reason is CasADi's on-the-fly
simplification ``x * (1/d) -> x / d``: with ``1/d`` formed once and multiplied, every product by it
became a division again (35 divisions in the Panda's kernel instead of 7; a division costs several
products and sits on the factor's critical path). ``x * (-1/d)`` is not rewritten, and the signs
cancel in pairs everywhere but one negation per solve::

    d_j  = A_jj - sum_k N_jk (N_jk d_k)
    N_ij = (A_ij - sum_k N_ik (N_jk d_k)) r_j                    (= -L_ij)
    solve A x = b:   z_i = b_i + sum_k N_ik z_k,   x_i = sum_k N_ki x_k - z_i r_i
    inverse:         U = L^-1 (U_ij = N_ij + sum_k N_ik U_kj),   A^-1 = -U^T diag(r) U

Scalar SX arithmetic from Python costs tens of microseconds per operation (the wrapper's overload
resolution); the factorization and the solves are O(n^3) and O(n^2) of them per use. So each is
built once per size as an SX Function of symbols and *called* on the actual expressions: the call
evaluates the same operations in the same order in C++ (with the same on-the-fly simplifications
of exact zeros and ones), i.e. the same graph, much faster.
"""

from __future__ import annotations

from typing import Dict, List, NamedTuple

import casadi as ca

__all__ = ["LDLFactors", "ldl_factor", "ldl_solve", "spd_inverse", "symmetric_inverse",
           "packed_factor_fn", "packed_solve_fn"]


class LDLFactors(NamedTuple):
    """``A = L diag(d) L^T``, negated (see the module docstring).

    Attributes
    ----------
    neg_L : list of list of casadi.SX
        ``neg_L[i][j] = -L[i][j]`` for ``j < i`` (None elsewhere).
    neg_inv_d : list of casadi.SX, length n
        ``-1 / d[i]``, all < 0 for SPD input.
    """

    neg_L: List[List[ca.SX]]
    neg_inv_d: List[ca.SX]


_FACTOR_FNS: Dict[int, ca.Function] = {}
_SOLVE_FNS: Dict[int, ca.Function] = {}
_INVERSE_FNS: Dict[int, ca.Function] = {}


def _lower(n: int):
    return [(i, k) for i in range(n) for k in range(i)]


def _unpack(lv, n: int) -> List[List[ca.SX]]:
    N = [[None] * n for _ in range(n)]
    for k, (i, j) in enumerate(_lower(n)):
        N[i][j] = lv[k]
    return N


def _pack(N, n: int) -> ca.SX:
    return ca.vertcat(ca.SX(0, 1), *[N[i][k] for i, k in _lower(n)])


def _factor_py(A: ca.SX):
    """``(N, r)`` of ``A`` (module docstring), in Python SX (traced once per size into its Function)."""
    n = A.shape[0]
    N = [[None] * n for _ in range(n)]
    d: List[ca.SX] = []
    r: List[ca.SX] = []  # one division per pivot; the rest are products
    Nd = [[None] * n for _ in range(n)]  # N[j][k] * d[k], formed once
    for j in range(n):
        dj = A[j, j]
        for k in range(j):
            Nd[j][k] = N[j][k] * d[k]
            dj = dj - N[j][k] * Nd[j][k]
        d.append(dj)
        r.append(-1.0 / dj)
        for i in range(j + 1, n):
            lij = A[i, j]
            for k in range(j):
                lij = lij - N[i][k] * Nd[j][k]
            N[i][j] = lij * r[j]
    return N, r


def _solve_py(N, r, b: ca.SX) -> ca.SX:
    """``A^-1 b`` from the negated factors, in Python SX (traced once per size into its Function)."""
    n = len(r)
    z = [None] * n
    for i in range(n):
        zi = b[i]
        for k in range(i):
            zi = zi + N[i][k] * z[k]
        z[i] = zi
    x = [None] * n
    for i in reversed(range(n)):
        minus_y = z[i] * r[i]  # -z_i / d_i
        if i == n - 1:
            x[i] = -minus_y
            continue
        xi = N[i + 1][i] * x[i + 1]
        for k in range(i + 2, n):
            xi = xi + N[k][i] * x[k]
        x[i] = xi - minus_y
    return ca.vertcat(*x)


def _inverse_py(lv: ca.SX, rv: ca.SX, n: int) -> ca.SX:
    """``A^-1 = -U^T diag(r) U`` with ``U = L^-1`` from the packed negated factors, the upper triangle formed once."""
    N = _unpack(lv, n)
    U = [[None] * n for _ in range(n)]  # U = L^-1, unit lower triangular
    for j in range(n):
        for i in range(j + 1, n):
            u = N[i][j]
            for k in range(j + 1, i):
                u = u + N[i][k] * U[k][j]
            U[i][j] = u

    def u(k, j):  # U[k][j] for k >= j
        return 1 if k == j else U[k][j]

    W = ca.SX(n, n)
    for j in range(n):
        V = [rv[k] * u(k, j) for k in range(j, n)]  # diag(r) U, column j
        for i in range(j + 1):  # (U^T diag(r) U)_ij = -(A^-1)_ij
            W[i, j] = W[j, i] = -sum((u(k, i) * V[k - j] for k in range(j, n)), ca.SX(0))
    return W


def packed_factor_fn(n: int) -> ca.Function:
    """``ldl_factor_<n>(A) -> (N, r)``: :func:`ldl_factor` as a Function of packed outputs.

    ``N`` (n (n - 1) / 2,) holds ``-L``'s strict lower triangle row by row, ``r`` (n,) minus the
    reciprocal pivots: the layout :func:`packed_solve_fn` takes.
    """
    if n not in _FACTOR_FNS:
        A = ca.SX.sym("A", n, n)
        N, r = _factor_py(A)
        _FACTOR_FNS[n] = ca.Function(f"ldl_factor_{n}", [A], [_pack(N, n), ca.vertcat(*r)])
    return _FACTOR_FNS[n]


def packed_solve_fn(n: int) -> ca.Function:
    """``ldl_solve_<n>(N, r, b) -> x`` with ``A x = b`` (the packed factors of :func:`packed_factor_fn`)."""
    if n not in _SOLVE_FNS:
        lv, rv, b = ca.SX.sym("N", n * (n - 1) // 2), ca.SX.sym("r", n), ca.SX.sym("b", n)
        _SOLVE_FNS[n] = ca.Function(f"ldl_solve_{n}", [lv, rv, b], [_solve_py(_unpack(lv, n), [rv[i] for i in range(n)], b)])
    return _SOLVE_FNS[n]


def ldl_factor(A: ca.SX) -> LDLFactors:
    """Unpivoted ``LDL^T`` of a symmetric positive definite SX matrix (no pivoting is needed for SPD).

    Parameters
    ----------
    A : casadi.SX, shape (n, n), symmetric positive definite

    Returns
    -------
    LDLFactors
        The factors, negated (see the module docstring).
    """
    n = A.shape[0]
    lv, rv = packed_factor_fn(n)(A)
    return LDLFactors(_unpack(lv, n), [rv[i] for i in range(n)])


def ldl_solve(factors: LDLFactors, b: ca.SX) -> ca.SX:
    """``A^-1 b`` given :func:`ldl_factor` of A.

    Parameters
    ----------
    factors : LDLFactors
    b : casadi.SX, shape (n, 1)

    Returns
    -------
    casadi.SX, shape (n, 1)
    """
    n = len(factors.neg_inv_d)
    return packed_solve_fn(n)(_pack(factors.neg_L, n), ca.vertcat(*factors.neg_inv_d), b)


def spd_inverse(factors: LDLFactors) -> ca.SX:
    """``A^-1`` from :func:`ldl_factor` of A, column by column (SX, (n, n))."""
    n = len(factors.neg_inv_d)
    return ca.horzcat(*[ldl_solve(factors, ca.SX(ca.DM.eye(n)[:, j])) for j in range(n)])


def symmetric_inverse(factors: LDLFactors) -> ca.SX:
    """``A^-1`` from :func:`ldl_factor` of A (SX, (n, n)): about n^3/3 products, half of :func:`spd_inverse`."""
    n = len(factors.neg_inv_d)
    if n not in _INVERSE_FNS:
        lv, rv = ca.SX.sym("N", n * (n - 1) // 2), ca.SX.sym("r", n)
        _INVERSE_FNS[n] = ca.Function(f"ldl_inverse_{n}", [lv, rv], [_inverse_py(lv, rv, n)])
    return _INVERSE_FNS[n](_pack(factors.neg_L, n), ca.vertcat(*factors.neg_inv_d))
