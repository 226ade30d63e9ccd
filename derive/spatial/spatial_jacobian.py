"""The Jacobian (Lagrangian) form of a spatial chain's model, kept for comparison and cross-checks.

:func:`derive.spatial.spatial.make_spatial` (CRBA + RNEA) is the emitted form; this one builds the same
``D`` and ``h`` from world-frame Jacobians (docs/spatial.md compares their operation counts).
Pure math: no I/O.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Tuple

import numpy as np
import sympy as sp

from .chain import ChainDescription, chain_numerics, dot, outer
from ..core.lie import DirectionalDerivative
from ..core.model_base import FlexibleJointModel, Param
from ..core.program import Program
from .spatial import make_spatial
from .spatial_params import PAYLOAD
from .sym3 import Namer, cross3, dot3, exact_number, fill_symmetric, joint_trig, matvec3

__all__ = ["make_spatial_jacobian"]


def make_spatial_jacobian(desc: ChainDescription, name: str, params: Tuple[Param, ...],
                          description: str) -> FlexibleJointModel:
    """The same model in the Jacobian (Lagrangian) form, kept for comparison and cross-checks.

    World-frame kinematics (rotations ``W_k``, origins ``o_k``, axes ``z_k``,
    centres of mass ``c_k``) as named symbols;
    ``D = sum_k m_k Jv_k^T Jv_k + Jw_k^T (W_k Ic_k W_k^T) Jw_k`` with
    ``Jv_k[:, j] = z_j x (c_k - o_j)``, ``Jw_k[:, j] = z_j`` (j <= k); and
    ``h = D' dq - 1/2 d/dq (dq^T D dq) + dV/dq`` by directional derivatives
    of D. :func:`make_spatial` (CRBA + RNEA) is the emitted form: see
    docs/spatial.md for the operation counts of both.
    """
    if any(p.name in PAYLOAD for p in params):
        raise ValueError(f"{name}: the Jacobian form takes no payload parameters")
    base = make_spatial(desc, name, params, description)  # for the parameters and state symbols
    num = chain_numerics(desc)
    if any(pa != i - 1 for i, pa in enumerate(num.parents)):
        raise ValueError(f"{name}: the Jacobian form is built for serial chains; the joints form a tree")
    n = base.n
    prog = Program()
    q, dq = base.q, base.dq
    g0 = sp.Symbol("g0", real=True)

    d = Namer(prog)
    cs = joint_trig(prog, q)
    W = [[sp.Integer(int(r == k)) for k in range(3)] for r in range(3)]
    o = [sp.Integer(0)] * 3
    zs, os_, cms, Iws = [], [], [], []
    for i, b in enumerate(num.bodies):
        c, s = cs[i]
        R0 = [[exact_number(b.R0[r, k]) for k in range(3)] for r in range(3)]
        Ri = [[R0[r][0] * c + R0[r][1] * s, R0[r][1] * c - R0[r][0] * s, R0[r][2]] for r in range(3)]
        o = [d(f"o{i + 1}{'xyz'[r]}", o[r] + sp.Add(*[W[r][k] * exact_number(b.p[k]) for k in range(3)])) for r in range(3)]
        W = [[d(f"W{i + 1}_{r + 1}{k + 1}", sp.Add(*[W[r][a] * Ri[a][k] for a in range(3)])) for k in range(3)]
             for r in range(3)]
        com = b.first_moment / b.mass
        cms.append([d(f"cm{i + 1}{'xyz'[r]}", o[r] + sp.Add(*[W[r][k] * exact_number(com[k]) for k in range(3)]))
                    for r in range(3)])
        Ic = b.inertia_origin - b.mass * (dot(com, com) * np.eye(3) - outer(com, com))
        WI = [[sp.Add(*[W[r][a] * exact_number(Ic[a, k]) for a in range(3)]) for k in range(3)] for r in range(3)]
        Iws.append(fill_symmetric([[d(f"Iw{i + 1}_{r + 1}{k + 1}", sp.Add(*[WI[r][a] * W[k][a] for a in range(3)]))
                                if k >= r else None for k in range(3)] for r in range(3)]))
        zs.append([W[r][2] for r in range(3)])
        os_.append(o)
    D = sp.zeros(n, n)
    for k in range(n):
        m = exact_number(num.bodies[k].mass)
        Jv = [dvec for dvec in ([d(f"Jv{k + 1}_{j + 1}{'xyz'[r]}", e) for r, e in enumerate(
            cross3(zs[j], [cms[k][a] - os_[j][a] for a in range(3)]))] for j in range(k + 1))]
        for a in range(k + 1):
            Iz = matvec3(Iws[k], zs[a])
            for b_ in range(a + 1):
                D[a, b_] += m * dot3(Jv[a], Jv[b_]) + dot3(zs[b_], Iz)
    for a in range(n):
        for b_ in range(a + 1):
            D[a, b_] = D[b_, a] = prog.define(f"Dj{a + 1}_{b_ + 1}", D[a, b_])
    V = g0 * d("Vj", sp.Add(*[exact_number(num.bodies[k].mass) * cms[k][2] for k in range(n)]))
    dt = DirectionalDerivative({q[i]: dq[i] for i in range(n)}, program=prog, tag="jt")
    Ddot = dt(D)
    dqv = sp.Matrix(dq)
    h = Ddot * dqv
    for i in range(n):
        di = DirectionalDerivative({q[i]: sp.Integer(1)}, program=prog, tag=f"jq{i + 1}")
        h[i] = prog.define(f"hj{i + 1}", h[i] - (dqv.T * di(D) * dqv)[0, 0] / 2 + di(V))
    return replace(base, D=D, h=h, potential=V, program=prog, inverse_dynamics=None)
