"""The impedance laws: control that needs no jerk, reading everything a torque-sensed arm reports.

Both laws have the signature of the other laws (:mod:`derive.emit.controls`)::

    <model>_control_<kind>(m, z, r, p, gains) -> (u, s, z_dot, u_cmd, y_hat)

with ``m = [q; dq; q_m; dq_m; tau_J; dtau_J]`` (6n, :data:`FULL_MEASUREMENT`), ``z`` (n) the integral of
``q_d - q``, ``r`` (5n) the reference rows stacked and ``p`` the NOMINAL parameters:

``impedance`` (the ``motor`` interface: ``u`` is the motor torque)
    ``(tau_Jd, theta_d, dtheta_d, _, u_ff) = feedforward(r, p)`` (:mod:`derive.emit.feedforward`);
    ``u_cmd = u_ff + K_p (theta_d - q_m) + K_d (dtheta_d - dq_m) + K_T (tau_Jd - tau_J) + K_i z``;
    ``s = theta_d - q_m``. Motor-side impedance with torque feedback (Albu-Schaeffer, Ott, Hirzinger, IJRR 2007).
``joint_impedance`` (the ``joint_torque`` interface: ``u`` is the desired LINK-side torque without gravity, the
    vendor layer adds it)
    ``u_cmd = D(q_d) q_d'' + C(q_d, q_d') q_d' + K_q (q_d - q) + D_q (q_d' - dq) + K_i z``;
    ``s = q_d - q``. The rigid feedforward is the inverse dynamics minus the gravity torque,
    ``tau(q_d, q_d', q_d'') - h(q_d, 0)`` (:func:`derive.emit.dynamics.programme`).

Both: ``u = clip(u_cmd, -u_max, u_max)`` when ``limit``; ``z' = q_d - q``, frozen on a joint whose ``u_cmd``
is beyond ``u_max`` in the direction its error pushes (conditional integration, when ``anti_windup``);
``y_hat = [q; dq; 0; 0]`` (a placeholder for the linearizing coordinates, as ``pdg``'s).
"""

from __future__ import annotations

from typing import Dict, List, Tuple

import casadi as ca

from .dynamics import programme

__all__ = ["FULL_MEASUREMENT", "IMPEDANCE_KINDS", "build_impedance_laws", "impedance_gains_layout",
           "impedance_manifest", "impedance_state_layout", "split_blocks"]

#: Layout of the full measurement both laws read: everything a torque-sensed arm reports.
FULL_MEASUREMENT = "[q; dq; q_m; dq_m; tau_J; dtau_J]"

#: The impedance laws, in file order, with their meaning.
IMPEDANCE_KINDS: Tuple[Tuple[str, str], ...] = (
    ("impedance", "motor-side impedance with torque feedback about the flatness feedforward: u = u_ff + K_p "
                  "(theta_d - q_m) + K_d (dtheta_d - dq_m) + K_T (tau_Jd - tau_J) + K_i z, z' = q_d - q; reads m (6n)"),
    ("joint_impedance", "joint impedance for a joint-torque interface: tau_d = D(q_d) q_d'' + C(q_d, q_d') q_d' + "
                        "K_q (q_d - q) + D_q (q_d' - dq) + K_i z, no gravity (the robot adds it); reads m (6n)"),
)

_LIMITS = (
    ("K_i", True, "link-error integral gain per joint (N m/(rad s)), >= 0"),
    ("u_max", True, "torque limit per joint (N m), > 0 (used when limit = 1)"),
    ("limit", False, "1: u = clip(u_cmd, -u_max, u_max); 0: u = u_cmd"),
    ("anti_windup", False, "1: freeze z_i while u_cmd_i is beyond u_max_i and q_d_i - q_i pushes further"),
)

#: Each law's gains: ``(name, per joint?, meaning)``.
GAINS = {
    "impedance": (
        ("K_p", True, "motor position gain per joint on theta_d - q_m (N m/rad), >= 0"),
        ("K_d", True, "motor rate gain per joint on dtheta_d - dq_m (N m s/rad), >= 0"),
        ("K_T", True, "joint-torque feedback per joint on tau_Jd - tau_J (1), > -1 (-0.7: the motor seems 3.3x "
                      "heavier)")) + _LIMITS,
    "joint_impedance": (
        ("K_q", True, "link stiffness per joint on q_d - q (N m/rad), >= 0"),
        ("D_q", True, "link damping per joint on q_d' - dq (N m s/rad), >= 0")) + _LIMITS,
}


def impedance_gains_layout(kind: str, n: int) -> List[Tuple[str, int, str]]:
    """Blocks of the ``gains`` vector of ``control_<kind>``: ``(name, size, meaning)`` in order."""
    return [(name, n if joint else 1, meaning) for name, joint, meaning in GAINS[kind]]


def impedance_state_layout(kind: str, n: int) -> List[Tuple[str, int, str]]:
    """Blocks of ``z`` of ``control_<kind>``: the integral of ``q_d - q``."""
    return [("z_int", n, "integral of q_d - q (rad s)")]


def split_blocks(v, layout) -> Dict[str, object]:
    """``v`` (SX or MX) cut into the named blocks of ``layout`` (``(name, size, meaning)`` in order)."""
    out, k = {}, 0
    for name, size, _ in layout:
        out[name] = v[k:k + size]
        k += size
    return out


def _integral_zdot(n, m, r, g, u_cmd):
    """``z' = q_d - q``, frozen on a joint whose ``u_cmd`` is beyond ``u_max`` the way the error pushes it."""
    e = r[:n] - m[:n]
    um = g["u_max"]
    winding = g["limit"] * g["anti_windup"] * ((u_cmd > um) * (e > 0) + (u_cmd < -um) * (e < 0))
    return ca.if_else(winding, type(m).zeros(n), e)


def _rigid_feedforward(model) -> ca.Function:
    """``(r, p) -> D(q_d) q_d'' + C(q_d, q_d') q_d'``: the inverse dynamics without gravity (SX, CSE'd)."""
    n = model.n
    r, p = ca.SX.sym("r", 5 * n), ca.SX.sym("p", len(model.params))
    q, dq, a = r[:n], r[n:2 * n], r[2 * n:3 * n]
    prog = programme(model)
    tau = prog(q, dq, a, p)[2] - prog(q, ca.SX.zeros(n), ca.SX.zeros(n), p)[1]
    return ca.Function(f"{model.name}_rigid_feedforward", [r, p], [ca.cse(tau)], ["r", "p"], ["tau"])


def _laws(model, feedforward: ca.Function):
    """``kind -> law(m, z, r, p, g) -> (u_cmd, s)`` of both laws (``g`` the gains' blocks)."""
    n = model.n
    rigid = _rigid_feedforward(model)

    def impedance(m, z, r, p, g):
        tau_d, theta, dtheta, _, u_ff = feedforward(r, p)
        qm, dqm, tau = m[2 * n:3 * n], m[3 * n:4 * n], m[4 * n:5 * n]
        u_cmd = (u_ff + g["K_p"] * (theta - qm) + g["K_d"] * (dtheta - dqm) + g["K_T"] * (tau_d - tau)
                 + g["K_i"] * z)
        return u_cmd, theta - qm

    def joint_impedance(m, z, r, p, g):
        e = r[:n] - m[:n]
        return rigid(r, p) + g["K_q"] * e + g["D_q"] * (r[n:2 * n] - m[n:2 * n]) + g["K_i"] * z, e

    return {"impedance": impedance, "joint_impedance": joint_impedance}


def build_impedance_laws(model, feedforward: ca.Function) -> Dict[str, ca.Function]:
    """``control_<kind>`` (MX, calling ``feedforward`` or the rigid feedforward once) and ``control_<kind>_zdot``
    (SX) of both laws of :data:`IMPEDANCE_KINDS` (module docstring)."""
    n, n_par = model.n, len(model.params)
    out: Dict[str, ca.Function] = {}
    for kind, body in _laws(model, feedforward).items():
        glay = impedance_gains_layout(kind, n)
        ng = sum(b[1] for b in glay)
        m, z, r = ca.MX.sym("m", 6 * n), ca.MX.sym("z", n), ca.MX.sym("r", 5 * n)
        p, gains = ca.MX.sym("p", n_par), ca.MX.sym("gains", ng)
        g = split_blocks(gains, glay)
        u_cmd, s = body(m, z, r, p, g)
        um = g["u_max"]
        u = ca.if_else(g["limit"], ca.fmin(ca.fmax(u_cmd, -um), um), u_cmd)
        y_hat = ca.vertcat(m[:2 * n], ca.MX.zeros(2 * n))
        out[f"control_{kind}"] = ca.Function(
            f"{model.name}_control_{kind}", [m, z, r, p, gains], [u, s, _integral_zdot(n, m, r, g, u_cmd), u_cmd, y_hat],
            ["m", "z", "r", "p", "gains"], ["u", "s", "z_dot", "u_cmd", "y_hat"])
        ms, zs, rs = ca.SX.sym("m", 6 * n), ca.SX.sym("z", n), ca.SX.sym("r", 5 * n)
        ps, gs, uc, uu = ca.SX.sym("p", n_par), ca.SX.sym("gains", ng), ca.SX.sym("u_cmd", n), ca.SX.sym("u", n)
        zd = ca.cse(_integral_zdot(n, ms, rs, split_blocks(gs, glay), uc))
        out[f"control_{kind}_zdot"] = ca.Function(
            f"{model.name}_control_{kind}_zdot", [ms, zs, rs, ps, gs, uc, uu], [zd],
            ["m", "z", "r", "p", "gains", "u_cmd", "u"], ["z_dot"])
    return out


def impedance_manifest(kind: str, n: int) -> Dict[str, object]:
    """The manifest's measurement, ``s`` and ``y_hat`` of ``control_<kind>`` (besides its ``z`` and ``gains``)."""
    entry: Dict[str, object] = {
        "measurement": {"argument": "m", "size": 6 * n, "layout": FULL_MEASUREMENT,
                        "meaning": "first argument is everything a torque-sensed arm reports (6n): link and motor "
                                   "positions and rates, the joint torque and its rate"},
        "y_hat": "[q; dq; 0; 0], a placeholder for the linearizing coordinates"}
    if kind == "impedance":
        entry["measurement"]["feedforward"] = "feedforward(r, p): tau_Jd, theta_d, dtheta_d, u_ff"
        entry["s"] = "theta_d - q_m, motor-position error (rad)"
        entry["output"] = "u: the motor torque (the motor interface)"
    else:
        entry["s"] = "q_d - q, link-position error (rad)"
        entry["output"] = ("u: the desired link-side joint torque tau_d WITHOUT gravity (a joint-torque interface "
                           "adds it)")
    return entry
