"""The flatness feedforward of the nominal elastic model: the motor torque that makes the links follow a reference.

The link position ``q`` is a flat output of the reduced elastic model (docs/derivation.md): from the
reference and its first four derivatives, ``r = [q_d; q_d'; q_d''; q_d'''; q_d'''']`` (5n, rows stacked as
the control laws' ``r``), every state and the input along it follow without integration::

    tau_Jd    = D(q_d) q_d'' + h(q_d, q_d')                       link-side spring torque (inverse dynamics)
    tau_Jd'   = D' q_d'' + D q_d''' + h'                          its time derivatives along the reference
    tau_Jd''  = D'' q_d'' + 2 D' q_d''' + D q_d'''' + h''
    phi_d     = psi^-1(tau_Jd)                                    spring deflection q_m - q  (linear: tau_Jd / K)
    phi_d'    = tau_Jd' / psi'(phi_d)
    phi_d''   = (tau_Jd'' - psi''(phi_d) phi_d'^2) / psi'(phi_d)
    theta_d   = q_d + phi_d,  theta_d' = q_d' + phi_d',  theta_d'' = q_d'' + phi_d''
    u_ff      = J_m theta_d'' + B_m theta_d' + F(theta_d') + tau_Jd  (the motor equation)

``tau, tau', tau''`` come from :func:`derive.emit.dynamics.inverse_dynamics_jets` (the RNEA's Taylor
recursion for spatial chains and trees, the SymPy time derivatives for the closed-form planar chains);
``psi, psi', psi''`` and ``psi^-1`` are a nonlinear-spring model's own ``spring`` and ``spring_inverse``
Functions (:mod:`derive.emit.spring_chain`), ``F`` its motor friction at the motor rate. Along the
reference, with ``x_d = [q_d; q_d'; theta_d; theta_d']``, ``u_ff = alpha(x_d) + beta(x_d) q_d''''``: the
state law's ``y4' = nu`` at ``nu = q_d''''`` (the tests check this identity).

Emitted for every reduced model as ``<model>_feedforward(r, p) -> (tau_Jd, theta_d, dtheta_d, ddtheta_d,
u_ff)``, each (n,), ``p`` the NOMINAL parameters; not for complete models, whose rotor coupling
``S(q) ddq_m`` puts the motor acceleration in the link equation, so ``tau_Jd`` is no longer the inverse
dynamics of the links alone.
"""

from __future__ import annotations

from typing import Dict, List

import casadi as ca

from .dynamics import elastic_diagonals, inverse_dynamics_jets
from .spring_chain import friction_sx_function, inverse_sx_function, spring_sx_function

__all__ = ["FEEDFORWARD_OUTPUTS", "FEEDFORWARD_MEANING", "build_feedforward", "manifest_entry"]

#: Outputs of ``<model>_feedforward``, in order, with their meaning and unit.
FEEDFORWARD_OUTPUTS = (
    ("tau_Jd", "desired link-side joint torque: the inverse dynamics D(q_d) q_d'' + h(q_d, q_d') (N m)"),
    ("theta_d", "desired motor position q_d + psi^-1(tau_Jd) (rad, link side)"),
    ("dtheta_d", "its rate (rad/s)"),
    ("ddtheta_d", "its acceleration (rad/s^2)"),
    ("u_ff", "motor torque J_m theta_d'' + B_m theta_d' + F(theta_d') + tau_Jd (N m)"),
)

FEEDFORWARD_MEANING = ("flatness feedforward of the nominal model from the reference r = [q_d; q_d'; q_d''; "
                       "q_d'''; q_d''''] (5n): tau_Jd, theta_d, dtheta_d, ddtheta_d, u_ff, each (n,)")


def _spring_terms(model, tau, p, springs):
    """``(phi, psi', psi'')`` at the deflection ``phi = psi^-1(tau)`` per joint (linear: ``tau / K``, ``K``, 0)."""
    if model.springs is None:
        K, _, _ = elastic_diagonals(model, p)
        return tau / K, K, ca.SX.zeros(model.n)
    spring = springs.get("spring") or spring_sx_function(model)
    phi = (springs.get("spring_inverse") or inverse_sx_function(model))(tau, p)
    _, dpsi, ddpsi = spring(phi, p)
    return phi, dpsi, ddpsi


def build_feedforward(model, springs: Dict[str, ca.Function] = None) -> ca.Function:
    """``<model>_feedforward(r, p) -> (tau_Jd, theta_d, dtheta_d, ddtheta_d, u_ff)`` (SX, CSE'd; module docstring).

    Parameters
    ----------
    model : derive.core.model_base.FlexibleJointModel
        A reduced model (linear springs ``K (q_m - q)`` or the laws of ``model.springs``; motor friction
        ``model.frictions`` if any).
    springs : dict, optional
        A nonlinear-spring model's ``"spring"`` and ``"spring_inverse"`` Functions if the caller has them
        (:mod:`derive.emit.spring_chain`; built here otherwise: seconds for seven three-segment curves).

    Returns
    -------
    casadi.Function
        Inputs ``r`` (5n), ``p`` (len(params)); outputs of :data:`FEEDFORWARD_OUTPUTS`, each (n, 1).
    """
    n = model.n
    r, p = ca.SX.sym("r", 5 * n), ca.SX.sym("p", len(model.params))
    q, dq, a, da, dda = (r[k * n:(k + 1) * n] for k in range(5))
    tau, dtau, ddtau = inverse_dynamics_jets(model)(q, dq, a, da, dda, p)
    phi, dpsi, ddpsi = _spring_terms(model, tau, p, springs or {})
    dphi = dtau / dpsi
    ddphi = (ddtau - ddpsi * dphi * dphi) / dpsi
    theta, dtheta, ddtheta = q + phi, dq + dphi, a + ddphi
    _, Jm, Bm = elastic_diagonals(model, p)
    u = Jm * ddtheta + Bm * dtheta + tau
    if model.frictions:
        u = u + friction_sx_function(model)(dtheta, p)
    outs = ca.cse([tau, theta, dtheta, ddtheta, u])
    return ca.Function(f"{model.name}_feedforward", [r, p], outs, ["r", "p"],
                       [name for name, _ in FEEDFORWARD_OUTPUTS])


def manifest_entry(model_name: str, fn: ca.Function, operations: int, casadi_bytes: int) -> Dict[str, object]:
    """The manifest's ``feedforward`` entry: file, C name, inputs, outputs with meanings, size."""
    outputs: List[Dict[str, object]] = [{"name": name, "size": int(fn.size1_out(i)), "meaning": meaning}
                                        for i, (name, meaning) in enumerate(FEEDFORWARD_OUTPUTS)]
    return {"casadi_file": "feedforward.casadi", "c_name": f"{model_name}_feedforward", "meaning": FEEDFORWARD_MEANING,
            "inputs": ["r", "p"], "outputs": outputs, "operations": operations, "casadi_bytes": casadi_bytes}
