"""The Functions of a model with nonlinear springs on several joints (``panda_hd``), from the inverse dynamics.

A one-joint drive is derived in SymPy (:func:`derive.core.spring.linearize_spring`). With several joints
``D^-1`` stays implicit, as for the linear models (:mod:`derive.emit.dynamics`): every quantity is built
from the model's kernel ``(y3, y4, w, D) = kernel(q, dq, s, ds, p)`` (the time derivatives of the inverse
dynamics ``D a + h = s``), called with the spring torque ``s = psi(phi)`` and its rate
``ds = psi'(phi) dphi``, ``phi = q_m - q``, ``dphi = dq_m - dq``, per joint. Differentiating
``D y4 + r1 = ds`` once more along the motion gives ``D y5 + w = psi''(phi) dphi^2 + psi'(phi) ddphi``
with ``ddphi = ddq_m - y3`` and ``J_m ddq_m = u - psi(phi) - B_m dq_m - F(dq_m)``; ``y5 = nu`` solved
for ``u`` (docs/real-drives.md)::

    f     = [dq; y3; dq_m; J_m^-1 (-psi - B_m dq_m - F)],   g = [0; 0; 0; J_m^-1]
    T     = [q; dq; y3; y4]
    beta  = J_m psi'^-1 D(q)
    alpha = psi + B_m dq_m + F + J_m y3 + J_m psi'^-1 (w - psi'' dphi^2)

(for ``psi = K phi``, ``F = 0`` this is :func:`derive.emit.dynamics.state_bodies`' alpha). The
torque-sensed laws read ``s = tau_J`` and ``ds = dtau_J`` from the measurement; ``psi'`` and ``psi''`` at
the implied deflection ``phi_J = psi^-1(tau_J)`` (each law's Newton steps from its start,
:func:`derive.core.spring.newton_inverse`) and
``dphi = dtau_J / psi'(phi_J)``::

    alpha_tau = tau_J + B_m dq_m + F + J_m y3 + J_m psi'(phi_J)^-1 (w - psi''(phi_J) dphi^2)
    beta_tau  = J_m psi'(phi_J)^-1 D(q)

The brackets ``ad_f^k g`` by forward-mode AD of ``f`` (:func:`derive.emit.functions.ad_by_ad`; the
linear models' closed form assumes a constant ``K``). Each quantity is built from one body (a Python
function of SX or MX arguments calling the kernel, spring and friction Functions): SX with everything
inlined and CSE'd for the ``.casadi`` files, MX calling the shared Functions for the C file, which then
holds the kernel once (:func:`c_functions`).
"""

from __future__ import annotations

from typing import Callable, Dict

import casadi as ca
import sympy as sp

from ..core.spring import newton_inverse
from .dynamics import build_kernel, elastic_diagonals, mx_function, programme, state_blocks, sx_function
from .functions import QUANTITIES, ad_by_ad
from .ldl import ldl_factor
from .sx import SympyToSX
from .torque import TORQUE_QUANTITIES

__all__ = ["spring_sx_function", "friction_sx_function", "inverse_sx_function", "chain_bodies", "build_chain_functions",
           "c_functions"]


def _law_text(e: sp.Expr) -> sp.Expr:
    """A law expression as it is converted: a polynomial expanded (short, exact); a piecewise law kept as
    derived (expanding the blend polynomial in phi cancels large terms: 1e-10 relative inside the windows)."""
    return e if e.has(sp.Piecewise) else sp.expand(e)


def _law_sx(model, law_exprs, n: int, name: str, out_names, arg: str) -> ca.Function:
    """An SX Function ``(v (n,), p) -> outputs``, joint ``i``'s entry of each output ``law_exprs[i][k]`` at ``v_i``."""
    v, p = ca.SX.sym(arg, n), ca.SX.sym("p", len(model.params))
    a = sp.Symbol("law_arg", real=True)
    pbind = {s: p[j] for j, s in enumerate(model.param_symbols)}
    cols = [[] for _ in out_names]
    for i in range(n):
        conv = SympyToSX({**pbind, a: v[i]})
        for k, e in enumerate(law_exprs(i, a)):
            cols[k].append(ca.SX(0.0) if e == 0 else conv(_law_text(e)))
    outs = [ca.cse(ca.vertcat(*c)) for c in cols]
    return ca.Function(name, [v, p], outs, [arg, "p"], list(out_names))


def spring_sx_function(model) -> ca.Function:
    """``<model>_spring(phi, p) -> (psi, dpsi, ddpsi)``, each (n,): every joint's law and two derivatives."""
    springs = {s.joint - 1: s for s in model.springs}
    return _law_sx(model, lambda i, a: [springs[i].derivative(k, a) for k in range(3)], model.n,
                   f"{model.name}_spring", ("psi", "dpsi", "ddpsi"), "phi")


def friction_sx_function(model) -> ca.Function:
    """``<model>_friction(dq_m, p) -> F``, (n,): every motor's friction (0 where the model has none)."""
    frictions = {fr.joint - 1: fr for fr in model.frictions or ()}
    return _law_sx(model, lambda i, a: [frictions[i].law(a) if i in frictions else sp.Integer(0)], model.n,
                   f"{model.name}_friction", ("F",), "dq_m")


def inverse_sx_function(model) -> ca.Function:
    """``<model>_spring_inverse(tau_J, p) -> phi_J`` (n,): per joint :func:`derive.core.spring.newton_inverse`
    with its law's start and steps (``newton_start``, ``newton_steps``)."""
    n = model.n
    tau, p = ca.SX.sym("tau_J", n), ca.SX.sym("p", len(model.params))
    a = sp.Symbol("law_arg", real=True)
    pbind = {s: p[j] for j, s in enumerate(model.param_symbols)}
    phi = []
    for i, law in enumerate(sorted(model.springs, key=lambda s: s.joint)):
        v = ca.SX.sym("v")
        conv = SympyToSX({**pbind, a: v})
        psi = ca.Function("psi", [v, p], [conv(_law_text(law.derivative(k, a))) for k in (0, 1)])
        start = SympyToSX({**pbind, a: tau[i]})(law.newton_start(a))
        phi.append(newton_inverse(lambda x: psi(x, p)[0], lambda x: psi(x, p)[1], tau[i], start, law.newton_steps))
    return ca.Function(f"{model.name}_spring_inverse", [tau, p], [ca.cse(ca.vertcat(*phi))], ["tau_J", "p"],
                       ["phi_J"])


def chain_bodies(model, parts: Dict[str, ca.Function]) -> Dict[str, Callable]:
    """Bodies ``name -> (arg, p) -> value`` of f, T, alpha, beta (of ``x``) and the torque quantities (of ``m``).

    They call the shared Functions of :func:`_parts` (kernel, spring, its inverse, friction, inertia), so the
    same body makes an SX Function (calls inlined) or an MX one.
    """
    kernel, spring, friction = parts["kernel"], parts["spring"], parts["friction"]
    inverse, inertia = parts["spring_inverse"], parts["inertia"]
    n = model.n

    def state(x, p):
        q, dq, qm, dqm = state_blocks(x, n)
        _, Jm, Bm = elastic_diagonals(model, p)
        psi, dpsi, ddpsi = spring(qm - q, p)
        dphi = dqm - dq
        y3, y4, w, D = kernel(q, dq, psi, dpsi * dphi, p)
        F = friction(dqm, p)
        alpha = psi + Bm * dqm + F + Jm * y3 + Jm / dpsi * (w - ddpsi * dphi * dphi)
        return {"T": ca.vertcat(q, dq, y3, y4), "alpha": alpha, "dpsi": dpsi, "D": D,
                "f": ca.vertcat(dq, y3, dqm, (-psi - Bm * dqm - F) / Jm)}

    def torque(m, p):
        q, dq, tau, dtau, dqm = (m[i * n:(i + 1) * n] for i in range(5))
        _, Jm, Bm = elastic_diagonals(model, p)
        _, dpsi, ddpsi = spring(inverse(tau, p), p)
        dphi = dtau / dpsi
        y3, y4, w, D = kernel(q, dq, tau, dtau, p)
        alpha = tau + Bm * dqm + friction(dqm, p) + Jm * y3 + Jm / dpsi * (w - ddpsi * dphi * dphi)
        return {"T_tau": ca.vertcat(q, dq, y3, y4), "alpha_tau": alpha, "dpsi": dpsi, "D": D}

    def beta(arg, p, dpsi, D=None):  # D: the kernel's, in a core (else D(q) by the inertia Function)
        _, Jm, _ = elastic_diagonals(model, p)
        if D is None:
            D = inertia(ca.vertcat(arg[:n], type(arg).zeros(3 * n)), p)
        return ca.repmat(Jm / dpsi, 1, n) * D

    return {
        "f": lambda x, p: state(x, p)["f"],
        "T": lambda x, p: state(x, p)["T"],
        "alpha": lambda x, p: state(x, p)["alpha"],
        "beta": lambda x, p: beta(x, p, state(x, p)["dpsi"]),
        "core": lambda x, p: (lambda s: (s["T"], s["alpha"], beta(x, p, s["dpsi"], s["D"])))(state(x, p)),
        "T_tau": lambda m, p: torque(m, p)["T_tau"],
        "alpha_tau": lambda m, p: torque(m, p)["alpha_tau"],
        "beta_tau": lambda m, p: beta(m, p, torque(m, p)["dpsi"]),
        "core_tau": lambda m, p: (lambda t: (t["T_tau"], t["alpha_tau"], beta(m, p, t["dpsi"], t["D"])))(
            torque(m, p)),
    }


def _inertia(model) -> ca.Function:
    """``<model>_inertia(x, p) -> D(q)`` (SX, CSE'd) from the model's programme."""
    n, n_p = model.n, len(model.params)
    x, p = ca.SX.sym("x", 4 * n), ca.SX.sym("p", n_p)
    D = programme(model)(x[:n], x[n:2 * n], ca.SX.zeros(n), p)[0]
    return ca.Function(f"{model.name}_inertia", [x, p], [ca.cse(D)], ["x", "p"], ["inertia"])


def _energy(model, spring_potential: Callable, inertia: ca.Function) -> ca.Function:
    """``<model>_energy(x, p)``: links' kinetic, motors' kinetic, the springs' potential ``int_0^phi psi``, gravity."""
    n, n_p = model.n, len(model.params)
    x, p = ca.SX.sym("x", 4 * n), ca.SX.sym("p", n_p)
    q, dq, qm, dqm = state_blocks(x, n)
    _, Jm, _ = elastic_diagonals(model, p)
    V = SympyToSX({**{s: q[i] for i, s in enumerate(model.q)}, **{s: p[j] for j, s in enumerate(model.param_symbols)}},
                  dict(model.program.definitions))(model.potential)
    E = (ca.dot(dq, ca.mtimes(inertia(x, p), dq)) + ca.dot(Jm * dqm, dqm)) / 2 + ca.sum1(spring_potential(qm - q, p)) + V
    return ca.Function(f"{model.name}_energy", [x, p], [ca.cse(E)], ["x", "p"], ["energy"])


def _parts(model) -> Dict[str, ca.Function]:
    """The shared SX Functions: kernel, spring, its inverse, friction, inertia, the springs' potential."""
    springs = {s.joint - 1: s for s in model.springs}
    parts = {"kernel": build_kernel(model), "spring": spring_sx_function(model),
             "friction": friction_sx_function(model), "inertia": _inertia(model),
             "potential": _law_sx(model, lambda i, a: [springs[i].potential(a)], model.n,
                                  f"{model.name}_spring_potential", ("V_spring",), "phi")}
    parts["spring_inverse"] = inverse_sx_function(model)
    return parts


def build_chain_functions(model) -> Dict[str, ca.Function]:
    """Every SX Function of the model (kernel inlined, CSE'd): the keys of
    :func:`derive.emit.spring.build_spring_functions` (quantities, torque quantities, ``spring``,
    ``spring_inverse``) and ``"_parts"``, the shared Functions (:func:`_parts`) that :func:`cores` and
    :func:`c_functions` call."""
    n, n_p = model.n, len(model.params)
    parts = _parts(model)
    bodies = chain_bodies(model, parts)
    out: Dict[str, ca.Function] = {}
    for name in ("f", "T", "alpha", "beta"):
        out[name] = sx_function(f"{model.name}_{name}", bodies[name], [4 * n, n_p], ["x", "p"], [name])
    x, p = ca.SX.sym("x", 4 * n), ca.SX.sym("p", n_p)
    q, dq, qm, dqm = state_blocks(x, n)
    _, Jm, Bm = elastic_diagonals(model, p)
    g = ca.vertcat(ca.SX.zeros(3 * n, n), ca.diag(1 / Jm))
    out["g"] = ca.Function(f"{model.name}_g", [x, p], [g], ["x", "p"], ["g"])
    D = parts["inertia"](x, p)
    psi = parts["spring"](qm - q, p)[0]
    h = programme(model)(q, dq, ca.SX.zeros(n), p)[1]
    acc_m = (-psi - Bm * dqm - parts["friction"](dqm, p)) / Jm
    ad = ad_by_ad(x, D, psi - h, acc_m, g, ldl_factor(D))
    out["ad"] = ca.Function(f"{model.name}_ad", [x, p], [ca.cse(ad)], ["x", "p"], ["ad"])
    out["energy"] = _energy(model, parts["potential"], parts["inertia"])
    out["inertia"] = parts["inertia"]
    for name, _ in TORQUE_QUANTITIES:
        out[name] = sx_function(f"{model.name}_{name}", bodies[name], [5 * n, n_p], ["m", "p"], [name])
    out["spring"], out["spring_inverse"] = parts["spring"], parts["spring_inverse"]
    assert set(out) >= {name for name, _ in QUANTITIES}
    out["_parts"] = parts
    return out


def cores(model, parts: Dict[str, ca.Function], sym=ca.SX) -> Dict[str, ca.Function]:
    """``control_core(x, p_hat)`` and ``control_core_tau(m, p_hat) -> (y_hat, alpha, beta)``: one body each
    (SX: kernel inlined and CSE'd; MX: calling the shared Functions)."""
    n, n_p = model.n, len(model.params)
    bodies = chain_bodies(model, parts)
    make = sx_function if sym is ca.SX else mx_function
    return {"control_core": make(f"{model.name}_control_core", bodies["core"], [4 * n, n_p], ["x", "p_hat"],
                                 ["y_hat", "alpha", "beta"]),
            "control_core_tau": make(f"{model.name}_control_core_tau", bodies["core_tau"], [5 * n, n_p],
                                     ["m", "p_hat"], ["y_hat", "alpha", "beta"])}


def c_functions(model, parts: Dict[str, ca.Function]) -> Dict[str, ca.Function]:
    """MX twins of f, T, alpha, beta and the torque quantities that call the shared Functions (for the C file)."""
    n, n_p = model.n, len(model.params)
    bodies = chain_bodies(model, parts)
    out = {}
    for name in ("f", "T", "alpha", "beta"):
        out[name] = mx_function(f"{model.name}_{name}", bodies[name], [4 * n, n_p], ["x", "p"], [name])
    for name, _ in TORQUE_QUANTITIES:
        out[name] = mx_function(f"{model.name}_{name}", bodies[name], [5 * n, n_p], ["m", "p"], [name])
    return out
