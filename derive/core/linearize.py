"""Feedback linearization of a flexible-joint model, with D(q)^-1 kept implicit.

For ``x = [q; dq; q_m; dq_m]`` and the model of :mod:`derive.core.model_base`::

    f(x) = [dq; y3; dq_m; J_m^-1 (K (q - q_m) - B_m dq_m)],   g = [0; 0; 0; J_m^-1]
    T    = [y1; y2; y3; y4] = [q; dq; L_f y2; L_f y3]

where ``y3 = D^-1 r3`` with ``r3 = -(h + K (q - q_m))`` is the link
acceleration. Inverting D symbolically explodes from n = 3 on (docs/derivation.md,
"Why not invert D"), so we never do it. Instead we differentiate the *identity*
``E0 = D y3 - r3 = 0`` along f, treating y3 and its time derivatives as
implicit symbols ``Y3, Y4, A``:

    E1 = d/dt E0 = D Y4 + R1(x, Y3)           ->  y4 = D^-1 (-R1)
    E2 = d/dt E1 = D A  + R2(x, Y3, Y4)       ->  a  = L_f y4 = D^-1 (-R2)

and ``b = L_g y4 = D^-1 N`` with ``N = -(dR1/d dq_m) J_m^-1`` (= K J_m^-1).
Hence ``beta = b^-1 = N^-1 D`` and ``alpha = -beta a = N^-1 R2``: alpha and
beta need no linear solve at all; y3 and y4 need one SPD solve each, done
numerically in the generated code.

This SymPy form of R1, R2 and alpha is formed only on request (``symbolic=True``;
by default for one-joint models, whose report prints it): the emitted ``T`` and
``alpha`` take R1 and R2 as time derivatives of the inverse dynamics by CasADi AD
(:mod:`derive.emit.dynamics`), and the tests compare the two routes.

The brackets ``ad_f^k g`` serve only the controllability check: the emitted
``ad`` Function is their closed form for the reduced model
(:mod:`derive.emit.brackets`), which needs only ``D``, ``D'`` and ``dh/ddq``.
:func:`brackets_implicit` keeps the
symbolic form (entries of ``W = D^-1`` as implicit symbols, differentiated by
``d W = -W (d D) W``) where it is cheap: one-joint models, whose report prints
it beside the paper's matrix.

Pure math: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Optional, Tuple

import sympy as sp

from .lie import DirectionalDerivative
from .model_base import FlexibleJointModel


@dataclass
class Linearization:
    """Result of :func:`linearize`.

    Attributes
    ----------
    model : FlexibleJointModel
    Y3, Y4 : tuple of sympy.Symbol, length n
        Implicit symbols bound by ``D Y3 = rhs3`` and ``D Y4 = rhs4``.
    W : sympy.Matrix, shape (n, n)
        Implicit symbols for the entries of ``D^-1`` (symmetric: ``W[i, j]``
        and ``W[j, i]`` are the same symbol).
    rhs3 : sympy.Matrix, shape (n, 1)
        ``r3 = -(h + K (q - q_m))``, depends on (x, p).
    rhs4 : sympy.Matrix, shape (n, 1), or None
        ``-R1``, depends on (x, p, Y3); only with ``linearize(..., symbolic=True)``.
    outputs : dict str -> sympy.Matrix
        ``f`` (4n, 1), ``g`` (4n, n), ``T`` (4n, 1), ``beta`` (n, n), ``energy`` (1, 1),
        ``inertia`` (n, n); the implicit ``alpha`` (n, 1) and the symbolic brackets
        ``ad`` (4n, 4n) only when requested (see :func:`linearize`).
        They may contain the implicit symbols above.
    """

    model: FlexibleJointModel
    Y3: Tuple[sp.Symbol, ...]
    Y4: Tuple[sp.Symbol, ...]
    W: sp.Matrix
    rhs3: sp.Matrix
    rhs4: Optional[sp.Matrix]
    outputs: Dict[str, sp.Matrix] = field(default_factory=dict)


def _implicit(prefix: str, n: int) -> Tuple[sp.Symbol, ...]:
    return tuple(sp.Symbol(f"{prefix}_{i + 1}", real=True) for i in range(n))


def _diag(v) -> sp.Matrix:
    return sp.diag(*v)


def inverse_symbols(n: int) -> sp.Matrix:
    """Symmetric matrix of symbols ``Dinv_i_j`` (i <= j) standing for D^-1."""
    return sp.Matrix(n, n, lambda i, j: sp.Symbol(f"Dinv_{min(i, j) + 1}_{max(i, j) + 1}", real=True))


def brackets_implicit(m: FlexibleJointModel, W: sp.Matrix, d_time: DirectionalDerivative,
                      Y3, k: int = 3) -> sp.Matrix:
    """``[g, ad_f g, ..., ad_f^k g]`` with D^-1 kept as the symbols ``W``.

    Uses ``ad_f v = D_v f - D_f v`` (directional derivatives; the paper's
    sign) with ``f = [dq; Y3; dq_m; ddq_m]``, where the link acceleration
    ``Y3 = W r3`` has derivative ``D_v Y3 = W (D_v r3 - (D_v D) Y3)`` and
    ``D_v W = -W (D_v D) W``.

    Parameters
    ----------
    d_time : DirectionalDerivative
        Derivative along f (shared with :func:`linearize`).

    Returns
    -------
    sympy.Matrix, shape (4n, (k + 1) n)
    """
    n = m.n
    x = m.state
    q, dq, qm, dqm = (sp.Matrix(b) for b in (m.q, m.dq, m.qm, m.dqm))
    Kd, Bd = _diag(m.K), _diag(m.Bm)
    Jinv = _diag([1 / j for j in m.Jm])
    r3 = -(m.h + Kd * (q - qm))
    f = sp.Matrix.vstack(dq, sp.Matrix(Y3), dqm, Jinv * (Kd * (q - qm) - Bd * dqm))
    g = sp.Matrix.vstack(sp.zeros(3 * n, n), Jinv)

    def add_inverse_rules(d: DirectionalDerivative, with_y3: bool) -> DirectionalDerivative:
        cache = {}

        def dD():
            if "D" not in cache:
                cache["D"] = d(m.D)
            return cache["D"]

        def dW():  # -W (d D) W, formed once per direction on first use
            if "W" not in cache:
                cache["W"] = sp.zeros(n, n) if dD().is_zero_matrix else -(W * (dD() * W))
            return cache["W"]

        for i in range(n):
            for j in range(i, n):
                d.add_lazy_seed(W[i, j], lambda i=i, j=j: dW()[i, j])
        if with_y3:
            def dY3():
                if "Y3" not in cache:
                    cache["Y3"] = W * (d(r3) - dD() * sp.Matrix(Y3))
                return cache["Y3"]
            for i in range(n):
                d.add_lazy_seed(Y3[i], lambda i=i: dY3()[i])
        return d

    add_inverse_rules(d_time, with_y3=False)  # along f, Y3 -> Y4 is already seeded
    blocks = [g]
    for level in range(k):
        v = blocks[-1]
        cols = []
        for c in range(n):
            vc = v[:, c]
            d_v = DirectionalDerivative({s: vc[i] for i, s in enumerate(x)},
                                        program=m.program, tag=f"b{level}c{c + 1}")
            add_inverse_rules(d_v, with_y3=True)
            cols.append(d_v(f) - d_time(vc))
        blocks.append(sp.Matrix.hstack(*cols))
    return sp.Matrix.hstack(*blocks)


def _implicit_alpha(m: FlexibleJointModel, d_time: DirectionalDerivative, r3: sp.Matrix, Y3, Y4,
                    Jinv: sp.Matrix) -> Tuple[sp.Matrix, sp.Matrix, list]:
    """``(R1, R2, diag(N)^-1)`` of the module docstring, in SymPy; checks that ``N`` is diagonal."""
    n = m.n
    # E0 = D Y3 - r3 = 0.  E1 = d/dt E0 = D Y4 + R1 with R1 = D' Y3 - r3' (r3 has no Y3).
    R1 = d_time(m.D) * sp.Matrix(Y3) - d_time(r3)
    # E2 = d/dt E1 = D A + R2 with R2 = D' Y4 + R1' (R1 has no Y4, so no A term hides in R1').
    R2 = d_time(m.D) * sp.Matrix(Y4) + d_time(R1)
    # b = L_g y4 = D^-1 N with N = -(dR1/d dq_m) J_m^-1 (y3 does not depend on dq_m).
    dR1 = []
    for j in range(n):
        d_u = DirectionalDerivative({m.dqm[j]: sp.Integer(1)}, program=m.program, tag=f"u{j + 1}")
        dR1.append(d_u(R1))
    N = (-sp.Matrix.hstack(*dR1) * Jinv).applyfunc(sp.simplify)
    if not N.is_diagonal() or any(N[i, i].has(*[s for s, _ in m.program.definitions]) for i in range(n)):
        raise ValueError(f"{m.name}: expected L_g y4 = D^-1 K J_m^-1 with K diagonal, got N = {N}")
    return R1, R2, [1 / N[i, i] for i in range(n)]


def complete_plant(m: FlexibleJointModel) -> Linearization:
    """The plant pieces of a complete model (docs/complete-model.md); no T, alpha, beta.

    ``outputs``: ``inertia`` = ``M = [[D, S], [S^T, J_m]]`` (2n, 2n), ``coupling`` = ``S`` (n, n),
    ``rhs`` (2n, 1) = ``[-(h + K (q - q_m)); K (q - q_m) - B_m dq_m - c_m]`` (so that
    ``M [ddq; ddq_m] = rhs + [0; u]``) and ``energy`` (1, 1); f and g are formed
    numerically from them at emission (one LDL^T of M).
    """
    q, dq, qm, dqm = (sp.Matrix(b) for b in (m.q, m.dq, m.qm, m.dqm))
    Kd, Jd, Bd = _diag(m.K), _diag(m.Jm), _diag(m.Bm)
    S = m.coupling
    M = sp.Matrix.vstack(sp.Matrix.hstack(m.D, S), sp.Matrix.hstack(S.T, Jd))
    spring = q - qm
    rhs = sp.Matrix.vstack(-(m.h + Kd * spring), Kd * spring - Bd * dqm - m.motor_bias)
    energy = ((dq.T * m.D * dq)[0, 0] / 2 + (dq.T * S * dqm)[0, 0] + (dqm.T * Jd * dqm)[0, 0] / 2
              + (spring.T * Kd * spring)[0, 0] / 2 + m.potential)
    return Linearization(model=m, Y3=(), Y4=(), W=sp.zeros(0, 0), rhs3=rhs[:m.n, :], rhs4=rhs[m.n:, :],
                         outputs={"inertia": M, "coupling": S, "rhs": rhs, "energy": sp.Matrix([[energy]])})


def linearize(m: FlexibleJointModel, symbolic_brackets: Optional[bool] = None,
              symbolic: Optional[bool] = None) -> Linearization:
    """Derive f, g, T, beta and, if asked, the implicit symbolic alpha and brackets.

    A complete model (``m.coupling`` set) has no static feedback linearization:
    it gets :func:`complete_plant` instead.

    Parameters
    ----------
    m : FlexibleJointModel
    symbolic_brackets : bool, optional
        Also form ``outputs["ad"]`` in SymPy (:func:`brackets_implicit`). Default:
        only for one-joint models (cheap; their report prints it). The emitted
        ``ad`` Function never uses it (CasADi AD from f and g).
    symbolic : bool, optional
        Also form ``R1``, ``R2`` and ``alpha = N^-1 R2`` in SymPy (the implicit form of the
        module docstring; ``rhs4 = -R1`` binds ``Y4``). Default: only for one-joint models,
        whose report prints them. The emitted ``T`` and ``alpha`` never use them: they are
        CasADi AD of the inverse dynamics (:mod:`derive.emit.dynamics`); ``symbolic=True``
        is the independent route the tests compare them with.

    Returns
    -------
    Linearization
        Without ``symbolic``: ``rhs4`` is None and ``outputs`` has no ``alpha``.
    """
    if m.coupling is not None:
        return complete_plant(m)
    n = m.n
    q, dq, qm, dqm = (sp.Matrix(b) for b in (m.q, m.dq, m.qm, m.dqm))
    Kd, Jd, Bd = _diag(m.K), _diag(m.Jm), _diag(m.Bm)
    Jinv = _diag([1 / j for j in m.Jm])
    Y3, Y4 = _implicit("y3", n), _implicit("y4", n)
    acc_m = Jinv * (Kd * (q - qm) - Bd * dqm)  # motor acceleration, explicit
    if symbolic is None:
        symbolic = n == 1
    if symbolic_brackets is None:
        symbolic_brackets = n == 1

    r3 = -(m.h + Kd * (q - qm))
    extra: Dict[str, sp.Matrix] = {}
    rhs4 = None
    if symbolic or symbolic_brackets:
        seeds = {}
        for i in range(n):
            seeds.update({m.q[i]: m.dq[i], m.dq[i]: Y3[i], m.qm[i]: m.dqm[i], m.dqm[i]: acc_m[i],
                          Y3[i]: Y4[i]})
        d_time = DirectionalDerivative(seeds, program=m.program, tag="t")  # d/dt along f
    if symbolic:
        R1, R2, ninv = _implicit_alpha(m, d_time, r3, Y3, Y4, Jinv)
        rhs4 = -R1
    else:  # N = K J_m^-1 by the structure of the model (checked above when symbolic, and by the tests)
        ninv = [m.Jm[i] / m.K[i] for i in range(n)]
    # Named, so beta = Ninv D costs one product per entry (not a division each).
    Ninv = _diag([m.program.define(f"Ninv{i + 1}", ninv[i]) for i in range(n)])
    beta = Ninv * m.D
    if symbolic:
        extra["alpha"] = Ninv * R2

    W = inverse_symbols(n)
    if symbolic_brackets:
        extra["ad"] = brackets_implicit(m, W, d_time, Y3, 3)

    f = sp.Matrix.vstack(dq, sp.Matrix(Y3), dqm, acc_m)
    g = sp.Matrix.vstack(sp.zeros(3 * n, n), Jinv)
    T = sp.Matrix.vstack(q, dq, sp.Matrix(Y3), sp.Matrix(Y4))

    spring = q - qm
    energy = (
        (dq.T * m.D * dq)[0, 0] / 2 + (dqm.T * Jd * dqm)[0, 0] / 2
        + (spring.T * Kd * spring)[0, 0] / 2 + m.potential
    )
    return Linearization(
        model=m, Y3=Y3, Y4=Y4, W=W, rhs3=r3, rhs4=rhs4,
        outputs={
            "f": f, "g": g, "T": T, "beta": beta,
            "energy": sp.Matrix([[energy]]), "inertia": m.D, **extra,
        },
    )
