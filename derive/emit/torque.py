"""CasADi SX Functions of the torque-sensed derivation, and the motor PD + gravity law.

For a model (the equations of :mod:`derive.core.torque`)::

    <model>_T_tau(m, p)      -> [q; dq; y3; y4]  (4n)     y3 = D^-1 (tau_J - h), y4 = D^-1 (dtau_J - R1)
    <model>_alpha_tau(m, p)  -> alpha_tau        (n)
    <model>_beta_tau(m, p)   -> beta_tau         (n, n)  = J_m K^-1 D(q)
    <model>_control_core_tau(m, p_hat) -> (y_hat, alpha, beta): the three jointly CSE'd, the
                                                             model part of the ``control_<kind>_tau`` laws

with ``m = [q; dq; tau_J; dtau_J; dq_m]`` (5n). ``T_tau``, ``alpha_tau`` and the core call the
model's elastic kernel with ``s = tau_J``, ``ds = dtau_J`` (:func:`derive.emit.dynamics.elastic_kernel`,
shared with the state laws: ``y3``, ``y4``, ``alpha``, ``beta`` from the time derivatives of the
inverse dynamics, one LDL^T of D(q)).
The SymPy route of :func:`derive.core.torque.torque_linearize` is kept for cross-checks
(:func:`build_torque_functions_symbolic`).

And the regulation law ``<model>_control_pdg(x, z, r, p, gains) -> (u, s, z_dot, u_cmd, y_hat)``
(Tomei's motor PD + gravity compensation, :func:`build_pdg`).
"""

from __future__ import annotations

from typing import Dict, List, Tuple

import casadi as ca

from ..core.linearize import Linearization
from ..core.torque import TorqueLinearization
from .dynamics import mx_function, sx_function, torque_bodies
from .impedance import split_blocks
from .ldl import ldl_factor, ldl_solve
from .sx import SympyToSX

#: Torque-coordinate functions emitted for every model, in file order, with their meaning.
TORQUE_QUANTITIES: Tuple[Tuple[str, str], ...] = (
    ("T_tau", "linearizing coordinates from the torque measurement m = [q; dq; tau_J; dtau_J; dq_m]: "
              "[q; dq; y3; y4], y3 = D^-1 (tau_J - h), y4 = D^-1 (dtau_J - D' y3 - h'), no K in them, (4n,)"),
    ("alpha_tau", "alpha in torque coordinates: tau_J + B_m dq_m + J_m y3 + J_m K^-1 (D'' y3 + 2 D' y4 + h''), "
                  "(n,)"),
    ("beta_tau", "beta in torque coordinates: J_m K^-1 D(q), (n, n)"),
)

#: Gains of ``control_pdg``: ``(name, size, meaning)`` per block (size ``"n"`` = one per joint).
PDG_GAINS: Tuple[Tuple[str, str, str], ...] = (
    ("k_p", "n", "motor position gain per joint (N m/rad), > 0"),
    ("k_d", "n", "motor rate gain per joint (N m s/rad), > 0"),
    ("u_max", "n", "torque limit per joint (N m), > 0 (used when limit = 1)"),
    ("limit", "1", "1: u = clip(u_cmd, -u_max, u_max); 0: u = u_cmd"),
)


def pdg_gains_layout(n: int) -> List[Tuple[str, int, str]]:
    """Blocks of the ``gains`` vector of ``control_pdg``: ``(name, size, meaning)`` in order."""
    return [(name, n if size == "n" else 1, meaning) for name, size, meaning in PDG_GAINS]


def _converter(tl: TorqueLinearization, m_sym: ca.SX, p: ca.SX) -> SympyToSX:
    """The symbolic route (:func:`derive.core.torque.torque_linearize`), for cross-checks."""
    model = tl.lin.model
    n = model.n
    bindings = {s: m_sym[i] for i, s in enumerate(tl.measurement)}
    bindings.update({s: p[j] for j, s in enumerate(model.param_symbols)})
    lazy: Dict[str, object] = {}

    def solved(key: str, rhs) -> ca.SX:
        if "ldl" not in lazy:
            lazy["ldl"] = ldl_factor(conv(model.D))
        if key not in lazy:
            lazy[key] = ldl_solve(lazy["ldl"], conv(rhs))
        return lazy[key]

    implicit = {}
    for i in range(n):
        implicit[tl.lin.Y3[i]] = lambda i=i: solved("y3", tl.rhs3)[i]
        implicit[tl.lin.Y4[i]] = lambda i=i: solved("y4", tl.rhs4)[i]
    conv = SympyToSX(bindings, dict(model.program.definitions), implicit)
    return conv


def build_torque_functions_symbolic(tl: TorqueLinearization) -> Dict[str, ca.Function]:
    """``T_tau``, ``alpha_tau``, ``beta_tau`` from the SymPy route (:func:`derive.core.torque.torque_linearize`).

    Not emitted: the tests compare :func:`build_torque_functions` with it.
    """
    model = tl.lin.model
    n = model.n
    m_sym = ca.SX.sym("m", 5 * n)
    p = ca.SX.sym("p", len(model.params))
    conv = _converter(tl, m_sym, p)
    out = {}
    for name, _ in TORQUE_QUANTITIES:
        v = conv(tl.outputs[name])
        v = ca.vec(v) if tl.outputs[name].shape[1] == 1 else v
        out[name] = ca.Function(f"{model.name}_{name}", [m_sym, p], [ca.cse(v)], ["m", "p"], [name])
    return out


def _beta_tau(lin: Linearization, beta: ca.Function = None) -> ca.Function:
    """``beta_tau(m, p) = J_m K^-1 D(q)``: the state law's ``beta`` with ``q`` read from ``m``.

    ``beta``: the state law's ``<model>_beta(x, p)`` (called with ``x = [q; 0; 0; 0]``: it reads q
    only), else converted from the SymPy form.
    """
    model = lin.model
    n = model.n
    m_sym = ca.SX.sym("m", 5 * n)
    p = ca.SX.sym("p", len(model.params))
    if beta is not None:
        value = beta(ca.vertcat(m_sym[:n], ca.SX.zeros(3 * n)), p)
    else:
        bindings = {s: m_sym[i] for i, s in enumerate(model.q)}
        bindings.update({s: p[j] for j, s in enumerate(model.param_symbols)})
        value = ca.cse(SympyToSX(bindings, dict(model.program.definitions))(lin.outputs["beta"]))
    return ca.Function(f"{model.name}_beta_tau", [m_sym, p], [value], ["m", "p"], ["beta_tau"])


def build_torque_functions(lin: Linearization, kernel: ca.Function,
                           beta: ca.Function = None) -> Dict[str, ca.Function]:
    """SX Functions ``<model>_<name>`` of :data:`TORQUE_QUANTITIES` and ``<model>_control_core_tau``.

    ``T_tau`` and ``alpha_tau`` call the model's ``kernel`` (:func:`derive.emit.dynamics.elastic_kernel`,
    inlined here, CSE'd); ``beta_tau`` is ``J_m K^-1 D(q)``.

    Parameters
    ----------
    lin : Linearization
    kernel : casadi.Function
        ``<model>_elastic_kernel``.
    beta : casadi.Function, optional
        The state law's ``<model>_beta`` (``beta_tau`` calls it instead of converting D again).

    Returns
    -------
    dict str -> casadi.Function
        ``"T_tau"``, ``"alpha_tau"``, ``"beta_tau"`` (inputs ``(m, p)``) and
        ``"control_core_tau"`` (inputs ``(m, p_hat)``, outputs ``y_hat``, ``alpha``, ``beta``).
    """
    model = lin.model
    n, n_p = model.n, len(model.params)
    bodies = torque_bodies(model, kernel)
    out = {name: sx_function(f"{model.name}_{name}", bodies[name], [5 * n, n_p], ["m", "p"], [name], cse=False)
           for name in ("T_tau", "alpha_tau")}  # one kernel call (CSE'd) and a few products each
    out["beta_tau"] = _beta_tau(lin, beta)
    out["control_core_tau"] = sx_function(f"{model.name}_control_core_tau", bodies["core"], [5 * n, n_p],
                                          ["m", "p_hat"], ["y_hat", "alpha", "beta"])
    return out


def torque_twins(lin: Linearization, kernel: ca.Function, beta: ca.Function) -> Dict[str, ca.Function]:
    """MX twins of :func:`build_torque_functions` for the C file: same names and signatures, one kernel call each.

    ``beta`` is the C file's ``<model>_beta`` (:func:`derive.emit.dynamics.beta_twin`), which
    ``beta_tau`` calls at ``x = [q; 0; 0; 0]``.
    """
    model = lin.model
    n, n_p = model.n, len(model.params)
    bodies = torque_bodies(model, kernel)
    out = {name: mx_function(f"{model.name}_{name}", bodies[name], [5 * n, n_p], ["m", "p"], [name])
           for name in ("T_tau", "alpha_tau")}
    out["beta_tau"] = mx_function(f"{model.name}_beta_tau",
                                  lambda m, p: beta(ca.vertcat(m[:n], ca.MX.zeros(3 * n)), p),
                                  [5 * n, n_p], ["m", "p"], ["beta_tau"])
    out["control_core_tau"] = mx_function(f"{model.name}_control_core_tau", bodies["core"], [5 * n, n_p],
                                          ["m", "p_hat"], ["y_hat", "alpha", "beta"])
    return out


def build_pdg(model) -> ca.Function:
    """``<model>_control_pdg(x, z, r, p, gains) -> (u, s, z_dot, u_cmd, y_hat)``: motor PD + gravity.

    ``q_d = r[0:n]``, ``G = h(q_d, 0)`` and ``K_nom`` from ``p`` (NOMINAL), ``q_md = q_d + K_nom^-1 G``,
    ``u_cmd = k_p (q_md - q_m) - k_d dq_m + G``, ``u`` = ``u_cmd`` clipped when ``limit``;
    ``s = q_md - q_m``; ``z`` and ``z_dot`` are empty; ``y_hat = [q; dq; 0; 0]`` (a placeholder:
    the measured link position and rate, zeros for the two upper blocks). Reads only
    ``q_m``, ``dq_m`` of ``x`` for ``u``.
    """
    n = model.n
    x, z, r = ca.SX.sym("x", 4 * n), ca.SX.sym("z", 0), ca.SX.sym("r", 5 * n)
    p = ca.SX.sym("p", len(model.params))
    layout = pdg_gains_layout(n)
    gains = ca.SX.sym("gains", sum(b[1] for b in layout))
    g = split_blocks(gains, layout)
    q_d = r[:n]
    bindings = {s: q_d[i] for i, s in enumerate(model.q)}
    bindings.update({s: ca.SX(0) for s in model.dq})
    bindings.update({s: p[j] for j, s in enumerate(model.param_symbols)})
    conv = SympyToSX(bindings, dict(model.program.definitions))
    G = ca.vec(conv(model.h))
    K_nom = ca.vertcat(*[conv(e) for e in model.K])
    q_m, dq_m = x[2 * n:3 * n], x[3 * n:4 * n]
    s = q_d + G / K_nom - q_m
    u_cmd = g["k_p"] * s - g["k_d"] * dq_m + G
    u = ca.if_else(g["limit"], ca.fmin(ca.fmax(u_cmd, -g["u_max"]), g["u_max"]), u_cmd)
    y_hat = ca.vertcat(x[:2 * n], ca.SX.zeros(2 * n))
    u, s, u_cmd = ca.cse([u, s, u_cmd])
    return ca.Function(f"{model.name}_control_pdg", [x, z, r, p, gains], [u, s, ca.SX(0, 1), u_cmd, y_hat],
                       ["x", "z", "r", "p", "gains"], ["u", "s", "z_dot", "u_cmd", "y_hat"])
