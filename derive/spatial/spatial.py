"""Spatial serial chains of revolute joints: D(q), h(q, dq) and the potential as a Program.

The chain comes as a :class:`derive.spatial.chain.ChainDescription` (URDF conventions,
from :mod:`derive.spatial.urdf` or :func:`derive.spatial.chain.planar_description`); its
build-time numbers (body frames along the joint axes, 10 inertia numbers per
body) are those of :func:`derive.spatial.chain.chain_numerics`.

Symbolic part (:func:`make_spatial`): a straight-line :class:`Program` with
named intermediates --

* ``c_i = cos q_i``, ``s_i = sin q_i`` with the derivative rules
  ``dc = -s dq``, ``ds = c dq``; the rotations ``R_i = R0_i Rz(q_i)`` are linear
  in them;
* ``h = C dq + G`` by recursive Newton-Euler with ``ddq = 0`` and the base
  accelerated upwards by ``g0`` (gravity): a forward pass (body rates,
  accelerations and the forces they need) and a backward pass (forces
  carried to the base, ``h_i`` = the joint-axis moment);
* the inverse dynamics ``tau(q, dq, ddq) = D ddq + h`` by the same RNEA with the
  joint accelerations as symbols (``inverse_dynamics``; reduced model only), and the bodies'
  numbers and inertials (``bodies``) for the emitter's Taylor recursion of it, which gives
  ``y4`` and ``alpha`` their time derivatives (:mod:`derive.emit.rnea_jets`);
* ``D`` by the composite-rigid-body algorithm (composite inertias in body
  frames, one force propagation per entry below the diagonal);
* the potential from the world height of every body's centre of mass.

The result is a :class:`derive.core.model_base.FlexibleJointModel`, so linearization
and emission are exactly those of the planar chains. Pure math: no I/O.
:func:`derive.spatial.spatial_jacobian.make_spatial_jacobian` is the Jacobian (Lagrangian) form of the
same model, kept for cross-checks.
"""

from __future__ import annotations

from typing import Dict, List, Optional, Sequence, Tuple

import sympy as sp

from .chain import ChainDescription, ChainNumerics, chain_numerics, mm, rpy_matrix, snap
from ..core.model_base import FlexibleJointModel, Param, RigidBody, elastic_param_names, state_symbols
from ..core.program import Program
from .sym3 import Matrix3, Namer, Vector, cross3, dot3, exact_number, fill_symmetric, joint_trig, matTvec3, matvec3
from ..core.rotors import Rotors, carry_rotors, coupling_matrix, motor_bias, spin_moments
from .spatial_params import INERTIAL_FIELDS, PAYLOAD

__all__ = ["make_spatial"]

def _check_params(num: ChainNumerics, name: str, params: Tuple[Param, ...],
                  symbolic: Sequence[str]) -> bool:
    """Check the parameter order (see :mod:`derive.spatial.spatial_params`); True if there is a payload."""
    expected = elastic_param_names(len(num.bodies))
    inertial_names = [f"{f}_{link}" for link in symbolic for f, _, _ in INERTIAL_FIELDS]
    names = [p.name for p in params]
    payload = names[len(expected):len(expected) + len(PAYLOAD)] == list(PAYLOAD)
    if names != expected + (list(PAYLOAD) if payload else []) + inertial_names:
        raise ValueError(f"{name}: parameters must be {expected} (optionally followed by {list(PAYLOAD)}) "
                         f"and then {inertial_names}, got {names}")
    return payload


def _check_structure(num: ChainNumerics, desc: ChainDescription, name: str, params: Tuple[Param, ...],
                     symbolic: Sequence[str], rotors: Optional[Rotors]) -> Tuple[List[str], bool]:
    """``(gear parameter names, has a payload)``; refuses rotors or a payload on a tree, and a wrong parameter order."""
    n = len(num.bodies)
    if rotors is not None and _is_tree(num):
        raise ValueError(f"{name}: the complete model (rotors) is built for serial chains; the joints form a tree")
    gears = [f"N{i}" for i in range(1, n + 1)] if rotors is not None else []
    if [p.name for p in params[len(params) - len(gears):]] != gears:
        raise ValueError(f"{name}: a complete model's parameters must end with {gears}")
    payload = _check_params(num, name, params[:len(params) - len(gears)], symbolic)
    if payload and _is_tree(num):
        raise ValueError(f"{name}: a payload rides on the tip of a serial chain; the joints form a tree "
                         f"(tips {list(desc.tips)}): leave out the payload parameters")
    return gears, payload


def _is_tree(num: ChainNumerics) -> bool:
    """True unless every body's parent is the previous body (a serial path)."""
    return any(pa != i - 1 for i, pa in enumerate(num.parents))


def _rotations(d: Namer, num: ChainNumerics, cs) -> Tuple[List[Matrix3], List[Vector]]:
    """``R_i = R0_i Rz(q_i)`` (linear in ``c_i``, ``s_i``) and the joint origins ``p_i``."""
    R: List[Matrix3] = []
    P: List[Vector] = []
    for i, b in enumerate(num.bodies):
        c, s = cs[i]
        R0 = [[exact_number(b.R0[r, k]) for k in range(3)] for r in range(3)]
        Ri = [[d(f"R{i + 1}_{r + 1}1", R0[r][0] * c + R0[r][1] * s),
               d(f"R{i + 1}_{r + 1}2", R0[r][1] * c - R0[r][0] * s),
               R0[r][2]] for r in range(3)]
        R.append(Ri)
        P.append([exact_number(v) for v in b.p])
    return R, P


def _body_inertias(d: Namer, num: ChainNumerics, sym: Dict[str, sp.Symbol], payload: bool):
    """Mass, first moment and inertia about the origin of every body: numbers, plus the symbolic parts."""
    mass = [exact_number(b.mass) for b in num.bodies]
    hmom = [[exact_number(v) for v in b.first_moment] for b in num.bodies]
    Io = [[[exact_number(b.inertia_origin[r, k]) for k in range(3)] for r in range(3)] for b in num.bodies]
    for link, k, Rl, pl, inertial in num.symbolic:  # inertials as parameters join their body
        ms = sym[f"m_{link}"]
        cl = [sym[f"c{a}_{link}"] for a in "xyz"]
        c = [d(f"cB_{link}_{'xyz'[r]}", sp.Add(*[exact_number(Rl[r, j]) * cl[j] for j in range(3)]) + exact_number(pl[r]))
             for r in range(3)]
        Rc = snap(mm(Rl, rpy_matrix(inertial.rpy)))
        i6 = [sym[f"i{a}_{link}"] for a in ("xx", "xy", "xz", "yy", "yz", "zz")]
        Ic = [[i6[0], i6[1], i6[2]], [i6[1], i6[3], i6[4]], [i6[2], i6[4], i6[5]]]
        RIc = [[sp.Add(*[exact_number(Rc[r, a]) * Ic[a][b] * exact_number(Rc[j, b]) for a in range(3) for b in range(3)])
                for j in range(3)] for r in range(3)]
        b = k - 1
        mass[b] = d(f"mb_{link}", mass[b] + ms)
        hmom[b] = [d(f"hb_{link}_{'xyz'[r]}", hmom[b][r] + ms * c[r]) for r in range(3)]
        cc = c[0] ** 2 + c[1] ** 2 + c[2] ** 2
        Io[b] = fill_symmetric([[d(f"Iob_{link}_{r + 1}{j + 1}",
                               Io[b][r][j] + RIc[r][j] + ms * ((cc if r == j else 0) - c[r] * c[j]))
                             if j >= r else None for j in range(3)] for r in range(3)])
    if payload:  # a point mass m_load at c_load (tip link frame) joins the last body
        mp = sym["m_load"]
        c = [sp.Add(*[exact_number(num.tip_R[r, k]) * sym[f"{'xyz'[k]}_load"] for k in range(3)]) + exact_number(num.tip_p[r])
             for r in range(3)]
        c = [d(f"cload{'xyz'[r]}", c[r]) for r in range(3)]
        last = len(num.bodies) - 1
        mass[last] = d("mlast", mass[last] + mp)
        hmom[last] = [d(f"hlast{'xyz'[r]}", hmom[last][r] + mp * c[r]) for r in range(3)]
        cc = c[0] ** 2 + c[1] ** 2 + c[2] ** 2
        Io[last] = fill_symmetric([[d(f"Iolast{r + 1}{k + 1}", Io[last][r][k] + mp * ((cc if r == k else 0) - c[r] * c[k]))
                                if k >= r else None for k in range(3)] for r in range(3)])
    return mass, hmom, Io


def _rnea_forward(d: Namer, R, P, dq, mass, hmom, Io, g0,
                  parents: Sequence[int], ddq=None) -> Tuple[List[Vector], List[Vector], list]:
    """RNEA forward pass (base accelerated by ``+g0 e_z``): each body's force, moment, rates.

    ``ddq``: the joint accelerations (None: zero, which gives ``h``). Each body starts
    from its parent's rates (``parents[i]``, -1: the base).
    The rates are ``(w_i, dw_i)``, body ``i``'s angular velocity and acceleration in its frame.
    """
    zero = [sp.Integer(0)] * 3
    base = (zero, zero, [sp.Integer(0), sp.Integer(0), g0])
    forces, moments, rates, accs = [], [], [], []
    for i in range(len(R)):
        Ri, p = R[i], P[i]
        pa = parents[i]
        w_prev, dw_prev, a_prev = base if pa < 0 else (rates[pa][0], rates[pa][1], accs[pa])
        acc = [a_prev[k] + t for k, t in enumerate(cross3(dw_prev, p))]
        if any(v != 0 for v in w_prev):
            wxp = d.vec(f"wp{i + 1}", cross3(w_prev, p))
            acc = [acc[k] + t for k, t in enumerate(cross3(w_prev, wxp))]
        acc = d.vec(f"acc{i}_", acc)
        a_i = d.vec(f"a{i + 1}", matTvec3(Ri, acc))
        wr = d.vec(f"wr{i + 1}", matTvec3(Ri, w_prev))  # previous rate in this body's frame
        w_i = [wr[0], wr[1], d(f"w{i + 1}z", wr[2] + dq[i])]
        dwr = matTvec3(Ri, dw_prev)
        dw_i = d.vec(f"dw{i + 1}", [dwr[0] + wr[1] * dq[i], dwr[1] - wr[0] * dq[i],
                                    dwr[2] if ddq is None else dwr[2] + ddq[i]])
        h_i, I_i, m_i = hmom[i], Io[i], mass[i]
        wxh = d.vec(f"wh{i + 1}", cross3(w_i, h_i))
        f_i = [m_i * a_i[k] + t + u for k, (t, u) in enumerate(zip(cross3(dw_i, h_i), cross3(w_i, wxh)))]
        Iw = d.vec(f"Iw{i + 1}", matvec3(I_i, w_i))
        n_i = [t + u + v for t, u, v in zip(matvec3(I_i, dw_i), cross3(w_i, Iw), cross3(h_i, a_i))]
        forces.append(d.vec(f"fb{i + 1}", f_i))
        moments.append(d.vec(f"nb{i + 1}", n_i))
        rates.append((w_i, dw_i))
        accs.append(a_i)
    return forces, moments, rates


def _rnea_backward(d: Namer, R, P, forces, moments, parents: Sequence[int]) -> sp.Matrix:
    """RNEA backward pass: each body's force joins its parent's; ``h_i`` is the moment about joint axis i.

    Bodies are visited from the last to the first (children come after their
    parents), so a body's force is complete when it is carried to its parent.
    """
    n = len(R)
    h = sp.zeros(n, 1)
    carried: List[list] = [[] for _ in range(n)]  # per body: (R F, R N, p x R F) of each child
    for i in reversed(range(n)):
        F, N = forces[i], moments[i]
        if carried[i]:
            F, N = list(F), list(N)
            for RF, RN, pxf in carried[i]:
                F = [F[k] + RF[k] for k in range(3)]
                N = [N[k] + RN[k] + pxf[k] for k in range(3)]
            F, N = d.vec(f"F{i + 1}", F), d.vec(f"N{i + 1}", N)
        h[i] = N[2]
        if parents[i] >= 0:
            RF = d.vec(f"RF{i + 1}", matvec3(R[i], F))
            carried[parents[i]].append((RF, matvec3(R[i], N), cross3(P[i], RF)))
    return h


def _rotate_z_inertia(d: Namer, i: int, A: Matrix3, c, s) -> Matrix3:
    """``Rz(q) A Rz(q)^T`` for the cosine and sine ``c``, ``s`` of joint ``i + 2``."""
    cc, ss, csq = d(f"cc{i + 2}", c * c), d(f"ss{i + 2}", s * s), d(f"cs{i + 2}", c * s)
    B = [[None] * 3 for _ in range(3)]
    B[0][0] = cc * A[0][0] - 2 * csq * A[0][1] + ss * A[1][1]
    B[1][1] = ss * A[0][0] + 2 * csq * A[0][1] + cc * A[1][1]
    B[0][1] = B[1][0] = csq * (A[0][0] - A[1][1]) + (cc - ss) * A[0][1]
    B[0][2] = B[2][0] = c * A[0][2] - s * A[1][2]
    B[1][2] = B[2][1] = s * A[0][2] + c * A[1][2]
    B[2][2] = A[2][2]
    return fill_symmetric([[d(f"Bz{i + 2}_{r + 1}{k + 1}", B[r][k]) if k >= r else None for k in range(3)]
                       for r in range(3)])


def _composite_inertias(d: Namer, num: ChainNumerics, R, P, cs, mass, hmom, Io) -> list:
    """CRBA backward pass: composite ``(m, h, I_o)`` of body i and its subtree about the origin of ``B_i``, in ``B_i``.

    A leaf's composite is its own inertia; a parent adds each child's composite
    carried into its frame (children in q order).
    """
    n = len(R)
    children: List[List[int]] = [[] for _ in range(n)]
    for c, pa in enumerate(num.parents):
        if pa >= 0:
            children[pa].append(c)
    composite = [None] * n
    for i in reversed(range(n)):
        cm, ch, cI = mass[i], hmom[i], Io[i]
        for c in children[i]:
            m_c, h_c, I_c = composite[c]
            Rn, p = R[c], P[c]
            co, si = cs[c]
            # Rz(q) I Rz(q)^T, then the constant R0 (exact zeros/ones keep it sparse).
            B = _rotate_z_inertia(d, c - 1, I_c, co, si)
            R0 = [[exact_number(num.bodies[c].R0[r, k]) for k in range(3)] for r in range(3)]
            RIR = [[sp.Add(*[R0[r][a] * B[a][b] * R0[k][b] for a in range(3) for b in range(3)])
                    for k in range(3)] for r in range(3)]
            hR = d.vec(f"hR{c + 1}", matvec3(Rn, h_c))
            pn = sum(float(v) ** 2 for v in num.bodies[c].p)
            diag = d(f"hp{c + 1}", 2 * dot3(p, hR) + m_c * exact_number(pn))
            cI = [[cI[r][k] + RIR[r][k] + (diag if r == k else 0)
                   - (p[r] * hR[k] + hR[r] * p[k] + m_c * p[r] * p[k]) for k in range(3)] for r in range(3)]
            ch = [ch[k] + hR[k] + m_c * p[k] for k in range(3)]
            cm = cm + m_c
        if children[i]:
            cI = fill_symmetric([[d(f"Ic{i + 1}_{r + 1}{k + 1}", cI[r][k]) if k >= r else None for k in range(3)]
                             for r in range(3)])
            ch = d.vec(f"hc{i + 1}", ch)
        composite[i] = (cm, ch, cI)
    return composite


def _crba_entries(d: Namer, R, P, composite, parents: Sequence[int]) -> sp.Matrix:
    """CRBA forward pass: ``D_ij`` by carrying the unit-rate force of joint i down to each ancestor j.

    ``D_ij`` is zero unless one of the joints is an ancestor of the other; only
    the ancestors are visited.
    """
    n = len(R)
    Dm = sp.zeros(n, n)
    for i in range(n):
        _, hc, Ic = composite[i]
        nv = [Ic[0][2], Ic[1][2], Ic[2][2]]
        fv = [-hc[1], hc[0], sp.Integer(0)]  # e_z x ... : force of the unit joint rate, -h x e_z
        Dm[i, i] = Ic[2][2]
        cur, j = i, parents[i]
        while j >= 0:
            Rn, p = R[cur], P[cur]
            fv2 = matvec3(Rn, fv)
            nv2 = [a + b for a, b in zip(matvec3(Rn, nv), cross3(p, fv2))]
            if parents[j] >= 0:
                fv = d.vec(f"cf{i + 1}_{j + 1}", fv2)
                nv = d.vec(f"cn{i + 1}_{j + 1}", nv2)
                Dm[i, j] = Dm[j, i] = nv[2]
            else:
                Dm[i, j] = Dm[j, i] = d(f"D{i + 1}_{j + 1}", nv2[2])
            cur, j = j, parents[j]
    prog = d.prog
    for i in range(n):  # name every entry (the derivations differentiate D entry by entry)
        for j in range(i + 1):
            e = Dm[i, j]
            if not e.is_Atom and e not in prog:
                Dm[i, j] = Dm[j, i] = prog.define(f"Dm{i + 1}_{j + 1}", e)
    return Dm


def _potential(d: Namer, R, P, mass, hmom, g0, parents: Sequence[int]) -> sp.Expr:
    """``g0`` times the height of every centre of mass (world z of the first moments)."""
    base = ([sp.Integer(0), sp.Integer(0), sp.Integer(1)], sp.Integer(0))
    up: list = []  # per body: (world z row in its frame, height of its origin)
    V = sp.Integer(0)
    for i in range(len(R)):
        zrow, zpos = base if parents[i] < 0 else up[parents[i]]
        zpos = d(f"zo{i + 1}", zpos + dot3(zrow, P[i]))
        zrow = d.vec(f"zr{i + 1}", [sp.Add(*[zrow[k] * R[i][k][c] for k in range(3)]) for c in range(3)])
        up.append((zrow, zpos))
        V += mass[i] * zpos + dot3(zrow, hmom[i])
    return g0 * d("Vg", V)


def _rigid_bodies(num: ChainNumerics, mass, hmom, Io) -> Tuple[RigidBody, ...]:
    """The bodies' kinematic numbers and inertials (with the payload and symbolic parts) as :class:`RigidBody`."""
    return tuple(RigidBody(parent=num.parents[i], R0=tuple(tuple(float(v) for v in row) for row in b.R0),
                           p=tuple(float(v) for v in b.p), mass=mass[i], first_moment=tuple(hmom[i]),
                           inertia=tuple(tuple(row) for row in Io[i]))
                 for i, b in enumerate(num.bodies))


def make_spatial(desc: ChainDescription, name: str, params: Tuple[Param, ...],
                 description: str, symbolic: Sequence[str] = (), rotors: Optional[Rotors] = None,
                 reduced_model: Optional[str] = None) -> FlexibleJointModel:
    """Flexible-joint model of a spatial serial chain of revolute joints.

    Parameters
    ----------
    desc : ChainDescription
        Kinematics and inertials; numbers are baked into the model.
    name : str
        Model name (a C identifier).
    params : tuple of Param
        ``K1..Kn, Jm1..Jmn, Bm1..Bmn, g0`` (see :func:`derive.spatial.spatial_params.elastic_params`),
        optionally followed by the payload (:func:`derive.spatial.spatial_params.payload_params`), then
        by the inertial parameters of the ``symbolic`` links (:func:`derive.spatial.spatial_params.inertial_params`).
    description : str
        One paragraph for the report and manifest.
    symbolic : sequence of str
        Links whose inertials are runtime parameters instead of baked numbers.
    rotors : Rotors or None
        The complete model (docs/complete-model.md): rotor ``i`` on body ``i-1``;
        ``params`` then end with the gear ratios ``N1..Nn`` (:func:`derive.core.rotors.gear_params`).
        None: the reduced model.
    reduced_model : str or None
        Recorded in the complete model (the reduced model with the same state layout).

    Returns
    -------
    FlexibleJointModel
        ``D`` (n, n), ``h`` (n, 1) and the potential as symbols of its
        :class:`Program` (see the module docstring for the algorithms); with
        rotors also the coupling ``S`` (n, n) and the motor-side bias (n, 1).
    """
    num = chain_numerics(desc, symbolic)
    n = len(num.bodies)
    gears, payload = _check_structure(num, desc, name, params, symbolic, rotors)
    sym = {p.name: sp.Symbol(p.name, real=True) for p in params}
    g0 = sym["g0"]
    q, dq, qm, dqm = state_symbols(n)
    prog = Program()
    d = Namer(prog)
    cs = joint_trig(prog, q)
    R, P = _rotations(d, num, cs)
    mass, hmom, Io = _body_inertias(d, num, sym, payload)
    if rotors is not None:
        jm, gear = [sym[f"Jm{i}"] for i in range(1, n + 1)], [sym[g] for g in gears]
        coef = [d(f"Sc{i + 1}", jm[i] / gear[i]) for i in range(n)]
        carry_rotors(d, num.bodies, rotors, [d(f"Ia{i + 1}", jm[i] / gear[i] ** 2) for i in range(n)],
                     mass, hmom, Io)
    forces, moments, rates = _rnea_forward(d, R, P, dq, mass, hmom, Io, g0, num.parents)
    complete = {}
    if rotors is not None:
        spin_moments(d, num.bodies, coef, dqm, rates, moments)
        complete = {"coupling": coupling_matrix(d, num.bodies, R, coef),
                    "motor_bias": motor_bias(d, num.bodies, coef, rates), "reduced_model": reduced_model,
                    "rotors": rotors}
    h = _rnea_backward(d, R, P, forces, moments, num.parents)
    if rotors is None:  # tau(q, dq, ddq) = D ddq + h as one RNEA, for the emitted time derivatives
        ddq = tuple(sp.Symbol(f"ddq{i + 1}", real=True) for i in range(n))
        di = Namer(prog, prefix="id_")
        f_id, n_id, _ = _rnea_forward(di, R, P, dq, mass, hmom, Io, g0, num.parents, ddq=ddq)
        complete.update(inverse_dynamics=(ddq, _rnea_backward(di, R, P, f_id, n_id, num.parents)),
                        bodies=_rigid_bodies(num, mass, hmom, Io))
    Dm = _crba_entries(d, R, P, _composite_inertias(d, num, R, P, cs, mass, hmom, Io), num.parents)
    V = _potential(d, R, P, mass, hmom, g0, num.parents)
    return FlexibleJointModel(**complete,
        name=name, n=n, params=tuple(params), q=q, dq=dq, qm=qm, dqm=dqm,
        D=Dm, h=h, potential=V,
        K=tuple(sym[f"K{i}"] for i in range(1, n + 1)),
        Jm=tuple(sym[f"Jm{i}"] for i in range(1, n + 1)),
        Bm=tuple(sym[f"Bm{i}"] for i in range(1, n + 1)),
        description=description, program=prog,
    )
