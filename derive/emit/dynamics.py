"""The model part of ``T``, ``alpha`` and the control laws: time derivatives of the inverse dynamics.

One SX Function, the *kernel*, holds everything ``T``, ``alpha`` and their torque-sensed
counterparts need (docs/derivation.md, "Time derivatives of the inverse dynamics")::

    <model>_accel_kernel(q, dq, s, ds, p) -> (y3, y4, w, D)
    y3 = D^-1 (s - h)                        D y3 + h = s   (s: the link-side spring torque)
    y4 = D^-1 (ds - r1),   r1 = D' y3 + h'   (the time derivative of D y3 + h = s)
    w  = D'' y3 + 2 D' y4 + h''

with one LDL^T of ``D(q)``, which it also returns: ``beta = J_m K^-1 D`` of a law's core then
costs n^2 products, not a second ``D``. ``r1`` and ``w`` are first and second time derivatives of the
inverse dynamics ``tau(q, dq, a) = D(q) a + h(q, dq)`` along ``q' = dq``, ``dq' = y3``,
``a' = y4`` (``a`` frozen at ``y3``, no ``a''`` term)::

    r1 = J [dq; y3; 0],     w = d/dz (J v) v + J [y3; y4; 0],   v = [dq; y3; y4],  J = dtau/dz

where ``z = [q; dq; a]``. Spatial chains and trees take them (and ``h``) by a Taylor recursion of
the RNEA (:mod:`derive.emit.rnea_jets`); :func:`time_derivatives`, CasADi forward-mode AD of the
model's straight-line RNEA with the acceleration as an input (``model.inverse_dynamics``), is the
tests' reference; planar chains differentiate ``D a + h`` in SymPy (:func:`build_kernel`).
The state laws use ``s = K (q_m - q)``, ``ds = K (dq_m - dq)``; the torque-sensed laws
the measured ``tau_J``, ``dtau_J``. Then (:func:`elastic_kernel`, the kernel with these, for linear springs)::

    T     = [q; dq; y3; y4]
    alpha = J_m K^-1 (w + K (y3 - ddq_m)),    ddq_m = J_m^-1 (K (q - q_m) - B_m dq_m)
          = J_m K^-1 w + J_m y3 + K (q_m - q) + B_m dq_m   (as emitted)
    alpha_tau = tau_J + B_m dq_m + J_m y3 + J_m K^-1 w
    beta  = J_m K^-1 D                                       (the cores, from the kernel's D)

The same bodies build the SX Functions written to ``.casadi`` (the kernel inlined and CSE'd,
fast from Python) and their MX twins for the C file, which call the one elastic kernel: the C
holds the model part once instead of once per function (:func:`derive.emit.writer.c_functions`).
"""

from __future__ import annotations

from typing import Callable, Dict, Sequence, Tuple

import casadi as ca
import sympy as sp

from .regroup import regroup
from .rnea_jets import rnea_jets
from .crba import joint_inertia
from .ldl import ldl_factor, ldl_solve, packed_factor_fn, packed_solve_fn
from .sx import SympyToSX


def _converter(model, q, dq, p) -> SympyToSX:
    bind = {s: q[i] for i, s in enumerate(model.q)}
    bind.update({s: dq[i] for i, s in enumerate(model.dq)})
    bind.update({s: p[j] for j, s in enumerate(model.param_symbols)})
    return SympyToSX(bind, dict(model.program.definitions))


_PROGRAMMES: Dict[int, Tuple[object, ca.Function]] = {}


def programme(model) -> ca.Function:
    """``(D, h, tau)`` of ``(q, dq, a, p)`` as one SX Function, converted once per model (cached).

    ``tau(q, dq, a) = D a + h``: the model's RNEA programme with the acceleration as an input
    (``model.inverse_dynamics``, spatial chains) or ``D a + h`` (planar chains). Callers call it
    on their own expressions (a call is evaluated in C++; converting the SymPy programme again
    would cost a Python operation per node).
    """
    hit = _PROGRAMMES.get(id(model))
    if hit is not None and hit[0] is model:
        return hit[1]
    n = model.n
    q, dq, a = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("a", n)
    p = ca.SX.sym("p", len(model.params))
    conv = _converter(model, q, dq, p)
    D, h = conv(model.D), ca.vec(conv(model.h))
    if model.inverse_dynamics is not None:
        acc, tau = model.inverse_dynamics
        for i, s in enumerate(acc):
            conv.bind(s, a[i])
        t = ca.vec(conv(tau))
    else:
        t = ca.mtimes(D, a) + h
    fn = ca.Function(f"{model.name}_programme", [q, dq, a, p], [D, h, t], ["q", "dq", "a", "p"], ["D", "h", "tau"])
    _PROGRAMMES[id(model)] = (model, fn)
    return fn


def inverse_dynamics(model) -> ca.Function:
    """``tau(q, dq, a, p) = D(q) a + h(q, dq)`` (SX), from the model's RNEA programme if it has one."""
    n = model.n
    q, dq, a = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("a", n)
    p = ca.SX.sym("p", len(model.params))
    t = programme(model)(q, dq, a, p)[2]
    return ca.Function(f"{model.name}_tau", [q, dq, a, p], [t], ["q", "dq", "a", "p"], ["tau"])


def time_derivatives(model) -> Tuple[ca.Function, ca.Function]:
    """``(d1, d2)``: ``d1(z, v, p) = J v`` and ``d2(z, v, w, p) = d/dz (J v) v + J w`` of ``tau(z)``.

    ``d2`` is the second derivative at ``s = 0`` of ``tau(z + s v + s^2/2 w)`` (forward mode in
    the scalar ``s``, twice, then ``s = 0`` folded in): cheaper than nesting ``jtimes`` in ``z``.
    """
    n = model.n
    tau = inverse_dynamics(model)
    z, v, w = ca.SX.sym("z", 3 * n), ca.SX.sym("v", 3 * n), ca.SX.sym("w", 3 * n)
    p, s = ca.SX.sym("p", len(model.params)), ca.SX.sym("s")
    t = tau(z[:n], z[n:2 * n], z[2 * n:], p)
    d1 = ca.Function("d1", [z, v, p], [ca.jtimes(t, z, v)])
    zs = z + s * v + (s * s / 2) * w
    ts = tau(zs[:n], zs[n:2 * n], zs[2 * n:], p)
    second = ca.jtimes(ca.jtimes(ts, s, ca.SX(1)), s, ca.SX(1))
    at0 = ca.Function("d2s", [s, z, v, w, p], [second])(ca.SX(0), z, v, w, p)
    d2 = ca.Function("d2", [z, v, w, p], [at0])
    return d1, d2


def _stated_body_numbers(model, conv: SympyToSX) -> list:
    """The model's :class:`derive.core.model_base.RigidBody` records as stated, numbers as floats, parameters as SX."""
    def scalar(e):
        return float(e) if getattr(e, "is_Number", False) else conv(e)
    return [(b.R0, b.p, scalar(b.mass), [scalar(v) for v in b.first_moment],
             [[scalar(v) for v in row] for row in b.inertia], b.parent) for b in model.bodies]


def _body_numbers(model, conv: SympyToSX) -> list:
    """:func:`_stated_body_numbers`, regrouped (:func:`derive.emit.regroup.regroup`): the same joint torques,
    with no mass and fewer nonzero inertials per body, for the recursion of the torques and their derivatives."""
    return regroup(_stated_body_numbers(model, conv))


def build_kernel(model) -> ca.Function:
    """``<model>_accel_kernel(q, dq, s, ds, p) -> (y3, y4, w, D)`` (SX, CSE'd; see the module docstring).

    Three routes to ``h``, ``r1`` and ``w``, by what the model has:

    * ``model.bodies`` (reduced spatial chains and trees): the Taylor recursion of the RNEA
      (:mod:`derive.emit.rnea_jets`), about 20 % fewer operations than AD of the programme;
    * ``model.inverse_dynamics`` only: forward-mode AD of the RNEA programme
      (:func:`time_derivatives`; also the tests' reference for the first route);
    * neither (the closed-form planar chains, whose SymPy programme has cheap derivative rules for
      the cosines of angle differences and measured fewer operations that way): the SymPy time
      derivatives of ``D y3 + h`` (:func:`derive.core.torque.inverse_dynamics_derivatives`), converted.
    """
    return _kernel(model, "jets" if model.bodies is not None else
                   "ad" if model.inverse_dynamics is not None else "symbolic")


def _kernel(model, route: str) -> ca.Function:
    """:func:`build_kernel` by the named route (``"jets"``, ``"ad"`` or ``"symbolic"``)."""
    n = model.n
    q, dq, s, ds = (ca.SX.sym(nm, n) for nm in ("q", "dq", "s", "ds"))
    p = ca.SX.sym("p", len(model.params))
    if route == "symbolic":  # first, so that the converter knows their programme symbols
        from ..core.torque import inverse_dynamics_derivatives
        # the names of derive.core.linearize (the programme caches its derivatives along "t" by them)
        Y3 = tuple(sp.Symbol(f"y3_{i + 1}", real=True) for i in range(n))
        Y4 = tuple(sp.Symbol(f"y4_{i + 1}", real=True) for i in range(n))
        R1, W = inverse_dynamics_derivatives(model, Y3, Y4)
    zero = ca.SX.zeros(n)
    if route == "jets":  # D by the CRBA and h by the jets, both on the regrouped bodies
        bodies = _body_numbers(model, _converter(model, q, dq, p))
        g0 = p[list(model.param_names).index("g0")]
        D = joint_inertia(bodies, q)
        h = rnea_jets(bodies, q, [dq], g0, 0)[0]  # shares the velocity terms with the jets
    else:
        D, h, _ = programme(model)(q, dq, zero, p)
    factors = ldl_factor(D)
    y3 = ldl_solve(factors, s - h)
    if route == "jets":
        y4 = ldl_solve(factors, ds - rnea_jets(bodies, q, [dq, y3], g0, 1)[1])
        w = rnea_jets(bodies, q, [dq, y3, y4], g0, 2)[2]
    elif route == "ad":
        d1, d2 = time_derivatives(model)
        z = ca.vertcat(q, dq, y3)
        y4 = ldl_solve(factors, ds - d1(z, ca.vertcat(dq, y3, zero), p))
        w = d2(z, ca.vertcat(dq, y3, y4), ca.vertcat(y3, y4, zero), p)
    else:
        conv = _converter(model, q, dq, p)
        for i in range(n):
            conv.bind(Y3[i], y3[i])
        y4 = ldl_solve(factors, ds - ca.vec(conv(R1)))
        for i in range(n):
            conv.bind(Y4[i], y4[i])
        w = ca.vec(conv(W))
    return ca.Function(f"{model.name}_accel_kernel", [q, dq, s, ds, p], ca.cse([y3, y4, w, D]),
                       ["q", "dq", "s", "ds", "p"], ["y3", "y4", "w", "D"])


#: Routes of :func:`inverse_dynamics_jets`, each checked against the others by the tests.
JET_ROUTES = ("jets", "ad", "symbolic")


def inverse_dynamics_jets(model, route: str = None) -> ca.Function:
    """``<model>_id_jets(q, dq, a, da, dda, p) -> (tau, dtau, ddtau)``: the inverse dynamics and two time derivatives.

    Along a joint trajectory whose derivatives at the instant are ``(q, dq, a, da, dda)``,
    ``tau = D(q) a + h(q, dq)``, ``dtau = D' a + D da + h'``, ``ddtau = D'' a + 2 D' da + D dda + h''``
    (all SX, CSE'd). The same three routes as :func:`build_kernel`, by what the model has
    (``route`` forces one):

    * ``"jets"`` (``model.bodies``): the RNEA's Taylor recursion (:func:`derive.emit.rnea_jets.rnea_jets`)
      along ``(dq, a, da, dda)``;
    * ``"ad"``: forward-mode AD of the programme, :func:`time_derivatives` with ``v = [dq; a; da]``,
      ``w = [a; da; dda]``, exact;
    * ``"symbolic"``: the SymPy ``R1 = D' a + h'``, ``W = D'' a + 2 D' da + h''``
      (:func:`derive.core.torque.inverse_dynamics_derivatives` at ``Y3 = a``, ``Y4 = da``) plus ``D da``,
      ``D dda``.
    """
    route = route or ("jets" if model.bodies is not None else
                      "ad" if model.inverse_dynamics is not None else "symbolic")
    if route not in JET_ROUTES:
        raise ValueError(f"route = {route!r}; expected one of {', '.join(JET_ROUTES)}")
    n = model.n
    q, dq, a, da, dda = (ca.SX.sym(nm, n) for nm in ("q", "dq", "a", "da", "dda"))
    p = ca.SX.sym("p", len(model.params))
    if route == "jets":
        bodies = _body_numbers(model, _converter(model, q, dq, p))
        g0 = p[list(model.param_names).index("g0")]
        tau, dtau, ddtau = rnea_jets(bodies, q, [dq, a, da, dda], g0, 2)
    elif route == "ad":
        d1, d2 = time_derivatives(model)
        z, v = ca.vertcat(q, dq, a), ca.vertcat(dq, a, da)
        tau = programme(model)(q, dq, a, p)[2]
        dtau, ddtau = d1(z, v, p), d2(z, v, ca.vertcat(a, da, dda), p)
    else:
        from ..core.torque import inverse_dynamics_derivatives
        Y3 = tuple(sp.Symbol(f"y3_{i + 1}", real=True) for i in range(n))
        Y4 = tuple(sp.Symbol(f"y4_{i + 1}", real=True) for i in range(n))
        R1, W = inverse_dynamics_derivatives(model, Y3, Y4)
        D, _, tau = programme(model)(q, dq, a, p)
        conv = _converter(model, q, dq, p)
        for i in range(n):
            conv.bind(Y3[i], a[i])
            conv.bind(Y4[i], da[i])
        dtau = ca.vec(conv(R1)) + ca.mtimes(D, da)
        ddtau = ca.vec(conv(W)) + ca.mtimes(D, dda)
    outs = ca.cse([tau, dtau, ddtau])
    return ca.Function(f"{model.name}_id_jets", [q, dq, a, da, dda, p], outs,
                       ["q", "dq", "a", "da", "dda", "p"], ["tau", "dtau", "ddtau"])


def elastic_diagonals(model, p) -> Tuple[object, object, object]:
    """``K``, ``J_m``, ``B_m`` (column vectors) as functions of ``p`` (SX or MX)."""
    sp_syms = list(model.param_symbols)
    out = []
    for exprs in (model.K, model.Jm, model.Bm):
        col = []
        for e in exprs:
            if e in sp_syms:
                col.append(p[sp_syms.index(e)])
            elif getattr(e, "is_Number", False):
                col.append(float(e))
            else:  # an expression of parameters: convert it (rare; SX only)
                ps = ca.SX.sym("p", len(sp_syms))
                conv = SympyToSX({s: ps[j] for j, s in enumerate(sp_syms)})
                col.append(ca.Function("e", [ps], [conv(e)])(p))
        out.append(ca.vertcat(*col))
    return tuple(out)


def state_blocks(x, n: int):
    """``(q, dq, q_m, dq_m)``: the four n-blocks of the state ``x`` (SX or MX)."""
    return tuple(x[i * n:(i + 1) * n] for i in range(4))


def motor_acceleration(K, Jm, Bm, q, qm, dqm):
    """``ddq_m = J_m^-1 (K (q - q_m) - B_m dq_m)`` with no input: the last block of ``f``."""
    return (K * (q - qm) - Bm * dqm) / Jm


def _beta(Jm, K, D):
    """``J_m K^-1 D`` (SX or MX)."""
    return ca.repmat(Jm / K, 1, D.shape[1]) * D


def elastic_kernel(model, kernel: ca.Function) -> ca.Function:
    """``<model>_elastic_kernel(q, dq, s, ds, dq_m, p) -> (y3, y4, alpha, beta)``: the kernel with the linear springs' laws.

    SX, ``kernel`` (:func:`build_kernel`) inlined and CSE'd with::

        alpha = J_m K^-1 w + J_m y3 + s + B_m dq_m,    beta = J_m K^-1 D

    the same for the state (``s = K (q_m - q)``, ``ds = K (dq_m - dq)``) and the torque-sensed
    (``s = tau_J``, ``ds = dtau_J``) laws, so the C's cores are thin calls of it. The state form is
    ``J_m K^-1 (w + K (y3 - ddq_m))`` with ``J_m ddq_m = K (q - q_m) - B_m dq_m`` written out: the
    spring torque is the input, and no division by ``J_m`` (7 operations a joint instead of 10).
    """
    n = model.n
    q, dq, s, ds, dqm = (ca.SX.sym(nm, n) for nm in ("q", "dq", "s", "ds", "dq_m"))
    p = ca.SX.sym("p", len(model.params))
    K, Jm, Bm = elastic_diagonals(model, p)
    y3, y4, w, D = kernel(q, dq, s, ds, p)
    outs = ca.cse([y3, y4, Jm / K * w + Jm * y3 + s + Bm * dqm, _beta(Jm, K, D)])
    return ca.Function(f"{model.name}_elastic_kernel", [q, dq, s, ds, dqm, p], outs,
                       ["q", "dq", "s", "ds", "dq_m", "p"], ["y3", "y4", "alpha", "beta"])


def state_bodies(model, kernel: ca.Function) -> Dict[str, Callable]:
    """``T``, ``alpha`` and the law's ``core`` ``(y_hat, alpha, beta)`` of ``(x, p)`` (SX or MX), calling
    ``kernel`` (:func:`elastic_kernel`) once."""
    n = model.n

    def core(x, p):
        q, dq, qm, dqm = state_blocks(x, n)
        K, _, _ = elastic_diagonals(model, p)
        y3, y4, alpha, beta = kernel(q, dq, K * (qm - q), K * (dqm - dq), dqm, p)
        return ca.vertcat(q, dq, y3, y4), alpha, beta

    # a Function keeps only what its output depends on: T drops alpha's products and vice versa
    return {"T": lambda x, p: core(x, p)[0], "alpha": lambda x, p: core(x, p)[1], "core": core}


def torque_bodies(model, kernel: ca.Function) -> Dict[str, Callable]:
    """``T_tau``, ``alpha_tau`` and the law's ``core`` ``(y_hat, alpha, beta)`` of ``(m, p)``,
    ``m = [q; dq; tau_J; dtau_J; dq_m]``, calling ``kernel`` (:func:`elastic_kernel`) once."""
    n = model.n

    def core(m, p):
        q, dq, tau, dtau, dqm = (m[i * n:(i + 1) * n] for i in range(5))
        y3, y4, alpha, beta = kernel(q, dq, tau, dtau, dqm, p)
        return ca.vertcat(q, dq, y3, y4), alpha, beta

    return {"T_tau": lambda m, p: core(m, p)[0], "alpha_tau": lambda m, p: core(m, p)[1], "core": core}


def beta_twin(model, inertia: ca.Function) -> ca.Function:
    """MX ``<model>_beta(x, p) = J_m K^-1 D(q)`` calling the model's ``inertia`` Function (for the C file)."""
    n = model.n

    def body(x, p):
        K, Jm, _ = elastic_diagonals(model, p)
        return _beta(Jm, K, inertia(x, p))

    return mx_function(f"{model.name}_beta", body, [4 * n, len(model.params)], ["x", "p"], ["beta"])


def f_twin(model, inertia: ca.Function) -> ca.Function:
    """MX ``<model>_f(x, p)`` calling ``inertia``, the LDL^T Functions and a bias-force Function (for the C file).

    ``f = [dq; D^-1 (-h - K (q - q_m)); dq_m; J_m^-1 (K (q - q_m) - B_m dq_m)]``, the value of the
    ``.casadi`` ``f``; ``h(q, dq)`` is the model's programme with zero acceleration.
    """
    n, n_p = model.n, len(model.params)
    qs, dqs, ps = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("p", n_p)
    bias = ca.Function(f"{model.name}_bias", [qs, dqs, ps], [ca.cse(programme(model)(qs, dqs, ca.SX.zeros(n), ps)[1])])

    def body(x, p):
        q, dq, qm, dqm = state_blocks(x, n)
        K, Jm, Bm = elastic_diagonals(model, p)
        N, r = packed_factor_fn(n)(inertia(x, p))
        y3 = packed_solve_fn(n)(N, r, -(bias(q, dq, p) + K * (q - qm)))
        return ca.vertcat(dq, y3, dqm, motor_acceleration(K, Jm, Bm, q, qm, dqm))

    return mx_function(f"{model.name}_f", body, [4 * n, n_p], ["x", "p"], ["f"])


def energy_twin(model, inertia: ca.Function) -> ca.Function:
    """MX ``<model>_energy(x, p)`` calling ``inertia`` for the links' kinetic energy (for the C file).

    ``E = dq^T D(q) dq / 2 + dq_m^T J_m dq_m / 2 + (q - q_m)^T K (q - q_m) / 2 + V(q)``, the same sum
    as the ``.casadi`` Function, with ``V`` (the links' gravitational potential) its own SX Function.
    """
    n, n_p = model.n, len(model.params)
    q, p = ca.SX.sym("q", n), ca.SX.sym("p", n_p)
    V = ca.Function(f"{model.name}_potential", [q, p], [_converter(model, q, ca.SX.sym("dq", n), p)(model.potential)])

    def body(x, p):
        q, dq, qm, dqm = state_blocks(x, n)
        K, Jm, _ = elastic_diagonals(model, p)
        spring = q - qm
        return (ca.dot(dq, ca.mtimes(inertia(x, p), dq)) + ca.dot(Jm * dqm, dqm) + ca.dot(K * spring, spring)) / 2 \
            + V(q, p)

    return mx_function(f"{model.name}_energy", body, [4 * n, n_p], ["x", "p"], ["energy"])


def _traced(sym, body: Callable, sizes: Sequence[int], in_names, extra: Callable = None):
    """``(arguments, outputs)`` of ``body`` (and ``extra``) on fresh ``sym`` (``ca.SX`` or ``ca.MX``) symbols."""
    args = [sym.sym(a, s) for a, s in zip(in_names, sizes)]
    outs = body(*args)
    outs = list(outs) if isinstance(outs, tuple) else [outs]
    if extra is not None:
        outs = outs + list(extra(*args))
    return args, outs


def sx_function(name: str, body: Callable, sizes: Sequence[int], in_names, out_names, cse: bool = True,
                extra: Callable = None) -> ca.Function:
    """An SX Function ``name`` of ``body`` (the kernel inlined), outputs CSE'd together."""
    args, outs = _traced(ca.SX, body, sizes, in_names, extra)
    return ca.Function(name, args, ca.cse(outs) if cse else outs, list(in_names), list(out_names))


def mx_function(name: str, body: Callable, sizes: Sequence[int], in_names, out_names,
                extra: Callable = None) -> ca.Function:
    """The MX twin of :func:`sx_function`: same name, inputs and outputs; the kernel is a call."""
    args, outs = _traced(ca.MX, body, sizes, in_names, extra)
    return ca.Function(name, args, outs, list(in_names), list(out_names))
