"""Nonlinear joint springs ``tau_J = psi(phi)``, ``phi = q_m - q``, and their feedback linearization.

The linear model (:mod:`derive.core.model_base`) has ``tau_J = K (q_m - q)``. A harmonic drive stiffens
with the deflection; the usual fit is the cubic ``psi(phi) = k1 phi + k3 phi^3``. With such a spring
the model is::

    D(q) ddq + h(q, dq) = psi(q_m - q)
    J_m ddq_m + B_m dq_m + F(dq_m) + psi(q_m - q) = u

with the motor friction ``F`` of :mod:`derive.core.friction` (Coulomb and Stribeck, zero at the
built-in's defaults), and the linearizing coordinates carry the spring and its stiffness::

    y3 = D^-1 (psi(phi) - h),   y4 = L_f y3 (contains psi'(phi) (dq_m - dq)),
    beta = L_g y4^-1 = J_m D / psi'(phi),   alpha = -beta L_f y4

(``alpha`` holds ``+ F(dq_m)``: the law compensates the nominal friction as a feedforward.)

Everything is derived, not written out: the spring enters as SymPy functions ``psi_k(phi)``
(:func:`spring_functions`, the k-th derivative of psi, each one's derivative the next one) so
that :func:`derive.core.lie.lie_derivative` and :func:`derive.core.lie.ad_iterates` differentiate through
it by the chain rule; the spring law (:mod:`derive.core.spring_laws`: linear, cubic, the three-segment
datasheet curve) is substituted at the end.

Torque coordinates (the measurement ``m = [q; dq; tau_J; dtau_J; dq_m]``) read ``tau_J`` and
``dtau_J`` directly; where ``psi'`` and ``psi''`` are needed they are evaluated at the deflection
the measurement implies, ``phi_J = psi^-1(tau_J)`` (:func:`newton_inverse`, bound numerically at
emission), and ``dphi = dtau_J / psi'(phi_J)``.

One-joint models (``link1_hd``, one-link model files with a ``[spring]`` or ``[friction]`` table) are
derived here in SymPy, ``D`` inverted in closed form (their report prints the results). Several joints
(``panda_hd``, URDF model files with drive tables) keep ``D^-1`` implicit: :func:`linearize_spring` returns
no expressions and :mod:`derive.emit.spring_chain` builds the same quantities from the time derivatives of
the inverse dynamics. Pure math: no I/O.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Dict, List, Optional, Sequence, Tuple

import sympy as sp

from .friction import FRICTION_PARAMETERS, MotorFriction, check_friction, friction_functions
from .lie import DirectionalDerivative, ad_iterates, lie_bracket, lie_derivative
from .linearize import Linearization
from .model_base import FlexibleJointModel, Param, state_symbols
from .program import Program
from .spring_laws import LAW_COEFFICIENTS, SPRING_KINDS, SPRING_PARAMETERS, CubicSpring, spring_functions
from .torque import inverse_dynamics_derivatives

__all__ = ["check_spring", "make_link1_hd", "with_drive", "with_drives", "drive_parameter", "linearize_spring",
           "motor_friction", "newton_inverse", "NEWTON_STEPS", "LINK1_HD_RANGE"]

#: Declared deflection range of ``link1_hd``, rad: ``|phi| <= LINK1_HD_RANGE``.
LINK1_HD_RANGE = 0.25

#: Newton steps of the cubic law's emitted inverse (each law states its own: ``newton_steps``).
NEWTON_STEPS = 12


def check_spring(model: str, spring, values: Dict[str, float]) -> None:
    """Raise :class:`SpringError` unless ``spring``'s coefficients are finite and ``psi' > 0`` on its range
    (each law's ``check``, :mod:`derive.core.spring_laws`)."""
    spring.check(model, values)


def newton_inverse(psi, dpsi, tau, start, steps: int = NEWTON_STEPS):
    """``phi`` with ``psi(phi) = tau`` by ``steps`` Newton steps from ``phi_0 = start``.

    Works on numbers, SymPy or CasADi (no branches). Each law gives its start
    (``newton_start``) and step count (``newton_steps``, :mod:`derive.core.spring_laws`). For the cubic
    from ``tau / k1`` with ``psi' > 0`` the iterates are monotone: ``psi`` is convex on ``phi > 0`` when
    ``k3 >= 0`` (then ``tau / k1`` lies beyond the root and Newton descends to it) and concave when
    ``k3 < 0`` (then it lies short of it and Newton climbs to it); odd symmetry gives ``tau < 0``.
    ``k3 = 0`` is exact after one step. The three-segment curve starts from the inverse of the
    datasheet's piecewise line, exact outside the blends and beyond the root inside them.
    """
    phi = start
    for _ in range(steps):
        phi = phi - (psi(phi) - tau) / dpsi(phi)
    return phi


def make_link1_hd() -> FlexibleJointModel:
    """``link1`` with a cubic harmonic-drive spring ``psi(phi) = k1 phi + k3 phi^3``, ``phi = q_m - q``.

    Values and where they come from:

    * ``k1 = 75 N m/rad``: half of link1's nominal ``K = 150`` (the small-deflection stiffness of a
      harmonic drive is well below its loaded stiffness; issue: "half the nominal");
    * ``k3 = 2500 N m/rad^3``: the stiffness ``psi'(phi) = k1 + 3 k3 phi^2`` reaches link1's
      ``K = 150`` at ``phi = 0.1 rad`` (``3 k3 0.1^2 = 75``), where the spring carries
      ``psi(0.1) = 10 N m``, about the largest gravity torque ``M g0 L = 9.8 N m``: at full load
      the drive is as stiff as link1's spring, softer below;
    * declared deflection range ``|phi| <= 0.25 rad`` (2.5 x that load; ``psi' <= 543.75`` there);
    * motor friction (:mod:`derive.core.friction`) ``F_c = F_s = 0`` by default (the paper's link has
      none; a real drive's levels are runtime parameters, ``fjm identify`` fits them), Stribeck
      velocity ``v_s = 0.1 rad/s`` and regularization ``v_c = 0.01 rad/s`` (``tanh(v / v_c)`` is
      within 2 % of ``sign(v)`` above 0.023 rad/s, and its time constant ``J_m v_c / F_c`` is 20 ms at
      ``F_c = 1 N m``: resolved by any substep the sampled loop uses).

    Everything else is link1's (paper Table 1). ``K`` of the model record is ``k1 = psi'(0)``.
    """
    params = (
        Param("J_l", 1.0, "link inertia about the joint axis", "kg m^2"),
        Param("J_m", 2.0, "motor (rotor) inertia", "kg m^2"),
        Param("k1", 75.0, "spring: linear coefficient psi'(0) (half of link1's K)", "N m/rad"),
        Param("k3", 2500.0, "spring: cubic coefficient (psi' = 150 at phi = 0.1 rad)", "N m/rad^3"),
        Param("M", 1.0, "link mass", "kg"),
        Param("g0", 9.8, "gravitational acceleration", "m/s^2"),
        Param("L", 1.0, "distance joint -> link centre of mass", "m"),
        Param("B_m", 0.0, "motor viscous damping", "N m s/rad"),
        *(Param(name, default, meaning, unit) for (name, meaning, unit), default
          in zip(FRICTION_PARAMETERS, (0.0, 0.0, 0.1, 0.01))),
    )
    (q,), (dq,), (qm,), (dqm,) = (tuple(b) for b in state_symbols(1))
    J_l, J_m, k1, k3, M, g0, L, B_m, F_c, F_s, v_s, v_c = (sp.Symbol(p.name, real=True) for p in params)
    spring = CubicSpring(1, k1, k3, LINK1_HD_RANGE)
    friction = MotorFriction(1, F_c, F_s, v_s, v_c)
    defaults = {p.name: p.default for p in params}
    check_spring("link1_hd", spring, defaults)
    check_friction("link1_hd", friction, defaults)
    return FlexibleJointModel(
        name="link1_hd", n=1, params=params,
        q=(q,), dq=(dq,), qm=(qm,), dqm=(dqm,),
        D=sp.Matrix([[J_l]]), h=sp.Matrix([M * g0 * L * sp.sin(q)]), potential=-M * g0 * L * sp.cos(q),
        K=(k1,), Jm=(J_m,), Bm=(B_m,),
        description=(
            "Single-link flexible joint of the paper with a cubic (harmonic-drive) spring: "
            "J_l q'' + M g0 L sin(q) = psi(q_m - q), J_m q_m'' + B_m q_m' + F(q_m') + psi(q_m - q) = u, "
            "psi(phi) = k1 phi + k3 phi^3 (psi' > 0 on |phi| <= 0.25 rad), "
            "F(v) = (F_c + (F_s - F_c) exp(-(v/v_s)^2)) tanh(v/v_c)."
        ),
        springs=(spring,), frictions=(friction,),
    )


def with_drive(base: FlexibleJointModel, kind: str, coefficients: Dict[str, float], deflection_range: float,
               friction: Dict[str, float] = None, description: str = None) -> FlexibleJointModel:
    """``base`` (one joint, linear spring ``K``) with the spring law ``kind`` and, optionally, motor friction.

    Parameters
    ----------
    base : FlexibleJointModel
        A one-joint model with the linear spring of parameter ``base.K[0]`` (e.g. ``planar1``).
    kind : {'linear', 'cubic', 'three_segment'}
        The spring law (:mod:`derive.core.spring_laws`); its coefficients replace ``K`` in the
        parameter list (``linear`` keeps ``K``).
    coefficients : dict
        Defaults of the law's coefficients (``k1, k3`` or ``K_1, K_2, K_3, T_1, T_2, w_blend``).
    deflection_range : float
        Declared range, rad.
    friction : dict, optional
        Defaults of ``F_c, F_s, v_s, v_c`` (appended to the parameters); None: viscous damping only.

    Raises
    ------
    SpringError, FrictionError
        On the defaults (one line, names the joint).
    """
    if base.n != 1:
        raise ValueError(f"{base.name}: with_drive takes a one-joint model (n = {base.n}); use with_drives")
    return with_drives(base, [(kind, coefficients, deflection_range)], None if friction is None else [friction],
                       description)


def drive_parameter(name: str, joint: int, n: int) -> str:
    """The runtime parameter name of drive coefficient ``name`` of ``joint`` (1-based) in an ``n``-joint model.

    One joint: the coefficient's own name (``K_1``, ``F_c``); several: suffixed by the joint number
    (``K_1_3``, ``F_c_3``), as the linear models' ``K3``, ``Jm3``.
    """
    return name if n == 1 else f"{name}_{joint}"


def with_drives(base: FlexibleJointModel, springs: Sequence[Tuple[str, Dict[str, float], float]],
                frictions: Optional[Sequence[Optional[Dict[str, float]]]] = None,
                description: str = None) -> FlexibleJointModel:
    """``base`` (linear springs ``K_i``) with a spring law per joint and, optionally, motor friction per joint.

    Parameters
    ----------
    base : FlexibleJointModel
        A reduced model with linear springs of parameters ``base.K`` (``planar1``, a URDF arm).
    springs : sequence of (kind, coefficients, deflection_range), length n
        Per joint in q order: the law (:data:`derive.core.spring_laws.SPRING_KINDS`), the defaults of its
        coefficients (unsuffixed names, ``K_1`` ...; ``linear`` keeps the joint's ``K`` and its default) and
        the declared range (rad). Joint ``i``'s coefficients become the parameters
        :func:`drive_parameter` names, at the place of its ``K``.
    frictions : sequence of dict or None, length n, optional
        Per joint the defaults of ``F_c, F_s, v_s, v_c`` (None: viscous only); appended to the parameters
        in joint order. None: no friction anywhere.
    description : str, optional

    Raises
    ------
    SpringError, FrictionError
        On the defaults (one line, names the joint).
    ValueError
        On an unknown law or a length other than n.
    """
    n = base.n
    if len(springs) != n or (frictions is not None and len(frictions) != n):
        raise ValueError(f"{base.name}: {len(springs)} spring laws for {n} joints; expected one per joint")
    K_names = [str(k) for k in base.K]
    by_K: Dict[str, List[Param]] = {}
    laws: List[Tuple[str, Tuple[str, ...]]] = []
    for j, (kind, coefficients, _) in enumerate(springs, 1):
        if kind not in SPRING_KINDS:
            raise ValueError(f"spring law {kind!r}; expected one of {', '.join(map(repr, SPRING_KINDS))}")
        if kind == "linear":
            laws.append((kind, (K_names[j - 1],)))
            continue
        names = tuple(drive_parameter(c, j, n) for c in LAW_COEFFICIENTS[kind])
        by_K[K_names[j - 1]] = [Param(nm, float(coefficients[c]), *SPRING_PARAMETERS[c])
                                for nm, c in zip(names, LAW_COEFFICIENTS[kind])]
        laws.append((kind, names))
    params: List[Param] = []
    for p in base.params:
        params += by_K.get(p.name, [p])
    friction_names = []
    for j, fr in enumerate(frictions or (), 1):
        if fr is None:
            friction_names.append(None)
            continue
        names = tuple(drive_parameter(name, j, n) for name, _, _ in FRICTION_PARAMETERS)
        params += [Param(nm, float(fr[name]), meaning, unit)
                   for nm, (name, meaning, unit) in zip(names, FRICTION_PARAMETERS)]
        friction_names.append(names)
    sym = {p.name: sp.Symbol(p.name, real=True) for p in params}
    defaults = {p.name: p.default for p in params}
    laws_out = []
    for j, ((kind, names), (_, _, rng)) in enumerate(zip(laws, springs), 1):
        law = SPRING_KINDS[kind](j, *(sym[c] for c in names), float(rng))
        check_spring(base.name, law, defaults)
        laws_out.append(law)
    fr_out = None
    if frictions is not None:
        fr_out = []
        for j, names in enumerate(friction_names, 1):
            if names is not None:
                fr_out.append(MotorFriction(j, *(sym[c] for c in names)))
                check_friction(base.name, fr_out[-1], defaults)
        fr_out = tuple(fr_out)
    extra = {}
    if n == 1:  # the closed forms' intermediate symbols (a1_1, ...) inlined: the Lie derivatives must see every q
        inline = base.program.inline
        extra = dict(D=inline(base.D), h=inline(base.h), potential=inline(base.potential), program=Program())
    return replace(base, params=tuple(params), K=tuple(s.start_stiffness for s in laws_out), springs=tuple(laws_out),
                   frictions=fr_out, description=description or base.description, **extra)


def _abstract_spring(m: FlexibleJointModel) -> sp.Matrix:
    """``[psi_1(q_m1 - q_1); ...]`` with the abstract spring functions."""
    return sp.Matrix([spring_functions(i + 1)[0](m.qm[i] - m.q[i]) for i in range(m.n)])


def motor_friction(m: FlexibleJointModel) -> sp.Matrix:
    """``[F_1(dq_m1); ...]``, each joint's motor friction as the abstract function of
    :func:`derive.core.friction.friction_functions` (zeros without ``m.frictions``), (n, 1)."""
    out = sp.zeros(m.n, 1)
    for fr in m.frictions or ():
        out[fr.joint - 1, 0] = friction_functions(fr.joint)[0](m.dqm[fr.joint - 1])
    return out


def _substitute(m: FlexibleJointModel, e):
    for s in tuple(m.springs) + tuple(m.frictions or ()):
        e = s.substitute(e)
    return e


def _spans(vectors: List[sp.Matrix], w: sp.Matrix) -> sp.Expr:
    """``det [v_1 .. v_k w ...]`` restricted: 0 iff ``w`` lies in the span (square case k + 1 = N)."""
    return sp.simplify(sp.Matrix.hstack(*vectors, w).det())


def linearize_spring(m: FlexibleJointModel) -> Linearization:
    """f, g, brackets, T, alpha, beta and the torque-coordinate laws of a model with nonlinear springs.

    Returns
    -------
    Linearization
        ``Y3 = Y4 = ()`` (everything explicit). ``outputs``: ``f`` (4, 1), ``g`` (4, 1), ``ad`` (4, 4),
        ``T`` (4, 1), ``alpha`` (1, 1), ``beta`` (1, 1), ``energy``, ``inertia``; the torque-coordinate
        ``T_tau``, ``alpha_tau``, ``beta_tau`` of the measurement symbols ``measurement`` (5,) with the
        implied deflection ``phi_J`` (``implied``, bound by Newton at emission); and the report's
        ``check`` (the controllability determinant and the involutivity determinants, abstract psi).
    """
    if m.n != 1:  # several joints: D^-1 stays implicit; the emitter builds everything numerically from the
        # time derivatives of the inverse dynamics (derive/emit/spring_chain.py)
        return Linearization(model=m, Y3=(), Y4=(), W=sp.zeros(0, 0), rhs3=None, rhs4=None, outputs={})
    x = m.state
    q, dq, qm, dqm = (sp.Matrix(b) for b in (m.q, m.dq, m.qm, m.dqm))
    Dinv = m.D.inv()
    Jinv = sp.diag(*[1 / j for j in m.Jm])
    Bd = sp.diag(*m.Bm)
    psi = _abstract_spring(m)
    f = sp.Matrix.vstack(dq, Dinv * (psi - m.h), dqm, Jinv * (-psi - Bd * dqm - motor_friction(m)))
    g = sp.Matrix.vstack(sp.zeros(3 * m.n, m.n), Jinv)
    # y1 = q; y_{k+1} = L_f y_k; relative degree 4: L_g y1..y3 = 0 (checked)
    ys = [q]
    for _ in range(3):
        ys.append(lie_derivative(ys[-1], f, x).applyfunc(sp.expand))
    for k, y in enumerate(ys[:3]):
        if not sp.simplify(lie_derivative(y, g, x)).is_zero_matrix:
            raise ValueError(f"{m.name}: L_g y{k + 1} != 0; the output q does not have relative degree 4")
    a = lie_derivative(ys[3], f, x)
    b = lie_derivative(ys[3], g, x)
    beta = b.inv().applyfunc(sp.factor)
    alpha = (-beta * a).applyfunc(sp.expand)
    ad = ad_iterates(f, g, x, 3)
    # the paper's test: rank [g, ad_f g, ad_f^2 g, ad_f^3 g] = 4 and span{g, ad_f g, ad_f^2 g} involutive
    cols = [ad[:, k] for k in range(4)]
    controllability = sp.factor(sp.simplify(ad.det()))
    involutive = [((i, j), _spans(cols[:3], lie_bracket(cols[i], cols[j], x))) for i in range(3) for j in range(i + 1, 3)]

    phi = qm - q
    energy = ((dq.T * m.D * dq)[0, 0] / 2 + sum(m.Jm[i] * m.dqm[i] ** 2 for i in range(m.n)) / 2
              + sum(s.potential(phi[s.joint - 1]) for s in m.springs) + m.potential)

    torque = _torque_form(m, ys)
    state = {"f": f, "g": g, "ad": ad, "T": sp.Matrix.vstack(*ys), "alpha": alpha, "beta": beta,
             "energy": sp.Matrix([[energy]]), "inertia": m.D}
    outputs = {name: _substitute(m, e) for name, e in state.items()}
    outputs.update({name: _substitute(m, e) for name, e in torque.items() if name not in ("measurement", "implied")})
    outputs["measurement"] = torque["measurement"]
    outputs["implied"] = torque["implied"]
    outputs["abstract"] = {name: e for name, e in state.items()}
    outputs["abstract"].update({name: torque[name] for name in ("T_tau", "alpha_tau", "beta_tau")})
    outputs["check"] = {"controllability": controllability, "involutive": involutive}
    return Linearization(model=m, Y3=(), Y4=(), W=sp.zeros(0, 0), rhs3=f[m.n:2 * m.n, :], rhs4=None,
                         outputs=outputs)


def _torque_form(m: FlexibleJointModel, ys) -> Dict[str, object]:
    """``T_tau``, ``alpha_tau``, ``beta_tau`` of ``m = [q; dq; tau_J; dtau_J; dq_m]`` (abstract psi).

    As :mod:`derive.core.torque` (``E0 = D y3 + h - tau_J``, differentiated twice along the motion), with
    ``ddtau_J`` the second time derivative of ``tau_J = psi(phi)``: ``psi''(phi) dphi^2 + psi'(phi)
    ddphi``, ``ddphi = ddq_m - ddq = J_m^-1 (u - tau_J - B_m dq_m - F(dq_m)) - y3``, ``dphi = dtau_J / psi'(phi)``
    at the implied ``phi = phi_J``. ``A = nu`` (``A = dy4/dt``) is solved for ``u = alpha_tau + beta_tau nu``.
    """
    n = m.n
    tau = tuple(sp.Symbol(f"tauJ{i + 1}", real=True) for i in range(n))
    dtau = tuple(sp.Symbol(f"dtauJ{i + 1}", real=True) for i in range(n))
    phiJ = tuple(sp.Symbol(f"phiJ{i + 1}", real=True) for i in range(n))
    Y3 = tuple(sp.Symbol(f"y3_{i + 1}", real=True) for i in range(n))
    Y4 = tuple(sp.Symbol(f"y4_{i + 1}", real=True) for i in range(n))
    Dinv = m.D.inv()
    R1, W = inverse_dynamics_derivatives(m, Y3, Y4)
    y3 = Dinv * (sp.Matrix(tau) - m.h)
    y4 = Dinv * (sp.Matrix(dtau) - R1)
    u = tuple(sp.Symbol(f"u{i + 1}", real=True) for i in range(n))
    nu = tuple(sp.Symbol(f"nu{i + 1}", real=True) for i in range(n))
    # second time derivative of tau_J = psi(phi) along phi -> dphi -> ddphi (chain rule through psi_k)
    dphi, ddphi = (tuple(sp.Symbol(f"{p}{i + 1}", real=True) for i in range(n)) for p in ("dphi", "ddphi"))
    ddtau, friction = [], motor_friction(m)
    for i in range(n):
        d_t = DirectionalDerivative({phiJ[i]: dphi[i], dphi[i]: ddphi[i]})
        psi_i = spring_functions(i + 1)
        ddtau.append(d_t(d_t(psi_i[0](phiJ[i]))).subs(
            ddphi[i], (u[i] - tau[i] - m.Bm[i] * m.dqm[i] - friction[i]) / m.Jm[i] - Y3[i]).subs(
            dphi[i], dtau[i] / psi_i[1](phiJ[i])))
    # E2 = D A + W - ddtau_J = 0 with A = nu, solved for u (linear in u)
    E2 = m.D * sp.Matrix(nu) + W - sp.Matrix(ddtau)
    bind = {Y3[i]: y3[i] for i in range(n)}
    bind.update({Y4[i]: y4[i].subs(bind) for i in range(n)})
    E2 = E2.subs(bind)
    sol = sp.solve(list(E2), list(u), dict=True)
    if len(sol) != 1:
        raise ValueError(f"{m.name}: E2 = 0 is not uniquely solvable for u")
    u_sol = sp.Matrix([sol[0][ui] for ui in u])
    alpha = u_sol.subs({v: 0 for v in nu}).applyfunc(sp.expand)
    beta = u_sol.jacobian(nu).applyfunc(sp.factor)
    return {"T_tau": sp.Matrix.vstack(sp.Matrix(m.q), sp.Matrix(m.dq), y3, y4.subs(bind)),
            "alpha_tau": alpha, "beta_tau": beta,
            "measurement": tuple(m.q) + tuple(m.dq) + tau + dtau + tuple(m.dqm), "implied": phiJ}
