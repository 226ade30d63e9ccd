"""Feedback linearization in torque coordinates: the laws of a torque-sensed arm.

A torque-sensed arm measures ``m = [q; dq; tau_J; dtau_J; dq_m]`` (5n) with the
link-side joint torque ``tau_J = K (q_m - q)`` and its rate. The link equation
``D(q) ddq + h(q, dq) = tau_J`` then gives the linearizing coordinates without K::

    E0 = D Y3 - (tau_J - h) = 0                 ->  y3 = D^-1 (tau_J - h)
    E1 = D Y4 + D' Y3 + h' - dtau_J = 0          ->  y4 = D^-1 (dtau_J - R1),  R1 = D' Y3 + h'
    E2 = D A + W - ddtau_J = 0,                  W  = d/dt R1 + D' Y4 = D'' Y3 + 2 D' Y4 + h''

(time derivatives along ``q -> dq``, ``dq -> Y3``, ``Y3 -> Y4``; ``Y3, Y4`` are the
implicit symbols of :mod:`derive.core.linearize`, bound to numeric solves with D in the
generated code, so D is never inverted symbolically). The motor equation
``J_m ddq_m + B_m dq_m + tau_J = u`` gives ``ddtau_J = K (J_m^-1 (u - tau_J - B_m dq_m) - y3)``,
so ``A = nu`` for::

    u = alpha_tau + beta_tau nu,   alpha_tau = tau_J + B_m dq_m + J_m y3 + J_m K^-1 W,
                                   beta_tau  = J_m K^-1 D

exactly when the law's K is the plant's. With a nominal ``K_nom`` instead the error is
the matched input gain ``Gamma = K K_nom^-1`` (docs/torque-sensing.md). Nothing here
forms ``q_m - q``: the measured ``tau_J`` enters as a symbol.

The gravity torque ``G(q) = h(q, 0)`` of the motor PD + gravity law is ``h`` emitted with
``dq`` bound to zero (``derive/emit/torque.py``): the program symbols of ``h`` depend on
``dq``, so a SymPy substitution in ``h`` alone would not reach them.

Pure math: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Tuple

import sympy as sp

from .lie import DirectionalDerivative
from .linearize import Linearization


@dataclass
class TorqueLinearization:
    """Result of :func:`torque_linearize`.

    Attributes
    ----------
    lin : Linearization
        The state derivation whose implicit symbols ``Y3``, ``Y4`` are reused.
    tau, dtau : tuple of sympy.Symbol, length n
        Measured joint torque and its rate.
    measurement : tuple of sympy.Symbol, length 5n
        ``[q; dq; tau_J; dtau_J; dq_m]`` in argument order.
    rhs3, rhs4 : sympy.Matrix, shape (n, 1)
        ``D Y3 = rhs3 = tau_J - h`` and ``D Y4 = rhs4 = dtau_J - R1`` (rhs4 contains Y3).
    outputs : dict str -> sympy.Matrix
        ``T_tau`` (4n, 1), ``alpha_tau`` (n, 1), ``beta_tau`` (n, n) (with Y3, Y4 in them).
    """

    lin: Linearization
    tau: Tuple[sp.Symbol, ...]
    dtau: Tuple[sp.Symbol, ...]
    measurement: Tuple[sp.Symbol, ...]
    rhs3: sp.Matrix
    rhs4: sp.Matrix
    outputs: Dict[str, sp.Matrix]


def inverse_dynamics_derivatives(m, Y3, Y4) -> Tuple[sp.Matrix, sp.Matrix]:
    """``(R1, W) = (D' Y3 + h', D'' Y3 + 2 D' Y4 + h'')`` in SymPy, ``Y3``, ``Y4`` implicit symbols.

    The time derivatives of ``D Y3 + h`` along ``q -> dq``, ``dq -> Y3``, ``Y3 -> Y4`` (no ``Y4'``).
    """
    n = m.n
    seeds = {}
    for i in range(n):
        seeds.update({m.q[i]: m.dq[i], m.dq[i]: Y3[i], Y3[i]: Y4[i]})
    # D and h (and every program symbol they use) depend on (q, dq) only, and this direction
    # agrees with the state derivation's "t" on q, dq and Y3: the program's derivative symbols
    # along "t" are the same functions, so they are shared (the emitter binds no q_m, so a
    # definition that used q_m would fail to emit rather than be silently wrong).
    d_time = DirectionalDerivative(seeds, program=m.program, tag="t")
    dD = d_time(m.D)
    R1 = dD * sp.Matrix(Y3) + d_time(m.h)
    return R1, d_time(R1) + dD * sp.Matrix(Y4)


def torque_linearize(lin: Linearization) -> TorqueLinearization:
    """Derive ``T_tau``, ``alpha_tau`` and ``beta_tau`` in torque coordinates.

    Parameters
    ----------
    lin : Linearization
        From :func:`derive.core.linearize.linearize` of the same model (its program and
        implicit symbols are shared).

    Returns
    -------
    TorqueLinearization
    """
    m = lin.model
    n = m.n
    tau = tuple(sp.Symbol(f"tauJ{i + 1}", real=True) for i in range(n))
    dtau = tuple(sp.Symbol(f"dtauJ{i + 1}", real=True) for i in range(n))
    Y3, Y4 = sp.Matrix(lin.Y3), sp.Matrix(lin.Y4)
    R1, W = inverse_dynamics_derivatives(m, lin.Y3, lin.Y4)
    ratio = sp.diag(*[m.Jm[i] / m.K[i] for i in range(n)])  # J_m K^-1, diagonal
    tau_v, dqm = sp.Matrix(tau), sp.Matrix(m.dqm)
    alpha = tau_v + sp.diag(*m.Bm) * dqm + sp.diag(*m.Jm) * Y3 + ratio * W
    beta = ratio * m.D
    return TorqueLinearization(
        lin=lin, tau=tau, dtau=dtau, measurement=tuple(m.q) + tuple(m.dq) + tau + dtau + tuple(m.dqm),
        rhs3=tau_v - m.h, rhs4=sp.Matrix(dtau) - R1,
        outputs={"T_tau": sp.Matrix.vstack(sp.Matrix(m.q), sp.Matrix(m.dq), Y3, Y4),
                 "alpha_tau": alpha, "beta_tau": beta})
