"""The command side of the sample step: from the law's output to the motor torque the plant integrates.

Written once for numpy and CasADi through the ops objects of :mod:`fjm_runtime.sim.sample_step`:
the command interface's sample-rate stage (the vendor's filter and the rate limit, against the last
command), the conditional integration while the rate limit holds the command back, and the plant
over one sample through the interface (the joint_torque layer's inner loop and the current loop per
substep, :mod:`fjm_runtime.sim.interface`).
"""
from __future__ import annotations

import numpy as np

from .interface import gravity_function
from .step_layout import StepLayout, controller_model

__all__ = ["actuated_plant", "interface_command", "nominal_gravity", "plant_substeps", "rate_limited", "rate_windup",
           "rk4_stages", "rk4_step", "spring_torque"]


def rk4_stages(xdot, x, u0, uh, u1, p, h: float):
    """The RK4 formula over ``h`` for ``x' = xdot(x, u, p)``, the torque ``u0``, ``uh``, ``u1`` at the stages'
    times ``0, h/2, h`` (numpy or CasADi values alike)."""
    k1 = xdot(x, u0, p)
    k2 = xdot(x + 0.5 * h * k1, uh, p)
    k3 = xdot(x + 0.5 * h * k2, uh, p)
    k4 = xdot(x + h * k3, u1, p)
    return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def rk4_step(ops, x, u, p, h: float):
    """One RK4 step of ``h``; ``u`` held, or ``(u_0, u_half, u_h)`` the torque at the stages' times
    (``ops.substep`` / ``ops.substep_staged`` when the step is outlined)."""
    staged = isinstance(u, tuple)
    if getattr(ops, "substep", None) is not None:
        return ops.substep_staged(x, *u, p) if staged else ops.substep(x, u, p)
    return rk4_stages(ops.xdot, x, *(u if staged else (u, u, u)), p, h)


def plant_substeps(ops, L: StepLayout, x, u, p):
    """``substeps`` RK4 steps of ``T / substeps`` under the held ``u``."""
    for _ in range(L.substeps):
        x = rk4_step(ops, x, u, p, L.T / L.substeps)
    return x


def spring_torque(ops, x, p, n: int):
    """``(tau_J, dtau_J)`` of the state ``x`` (4n): ``psi(q_m - q)`` and ``psi'(q_m - q) (dq_m - dq)`` with the
    spring law of ``ops``'s model at parameters ``p``, each (n,)."""
    q, dq, qm, dqm = x[0:n], x[n:2 * n], x[2 * n:3 * n], x[3 * n:4 * n]
    psi, dpsi = ops.spring(qm - q, p)
    return psi, dpsi * (dqm - dq)


def motor_command(ops, L: StepLayout, x, c, p):
    """The motor torque command of a substep at ``x``: ``c`` (motor), or the joint_torque layer's inner
    loop ``(1 + K_T) (c + g(q)) - K_T tau_J - D_T dtau_J`` with the robot's torque sensor (the TRUE
    spring) and the NOMINAL gravity, clipped at the motor's limit."""
    if L.interface == "motor":
        return c
    q, tau, dtau = x[0:L.n], *spring_torque(ops, x, p, L.n)
    K_T, D_T = ops.const(L.K_T), ops.const(L.D_T)
    u = (1.0 + K_T) * (c + ops.gravity(q)) - K_T * tau - D_T * dtau
    if L.u_limit:
        lim = ops.const(L.u_limit)
        u = ops.fmin(ops.fmax(u, -lim), lim)
    return u


def actuated_plant(ops, L: StepLayout, x, cur, c, p):
    """The plant over one sample under the command ``c``, through the interface: ``(x_next, cur_next)``.

    Per substep ``h``: the motor command (:func:`motor_command`, held over the substep) and the current
    loop's exact first-order response to it, ``u(t_j + s) = u_c + (u_j - u_c) e^{-w_c s}`` (``cur`` the
    motor torque ``u_j``), taken by the RK4 stages at ``s = 0, h/2, h`` (the scheme's fourth order kept).
    Without a lag or an inner loop: :func:`plant_substeps`.
    """
    if L.interface == "motor" and not L.current_decay:
        return plant_substeps(ops, L, x, c, p), cur
    h = L.T / L.substeps
    half = L.current_decay ** 0.5
    for _ in range(L.substeps):
        u_c = motor_command(ops, L, x, c, p)
        if L.current_decay:
            u_next = u_c + (cur - u_c) * L.current_decay
            x = rk4_step(ops, x, (cur, u_c + (cur - u_c) * half, u_next), p, h)
            cur = u_next
        else:
            x = rk4_step(ops, x, u_c, p, h)
    return x, cur


def interface_command(ops, L: StepLayout, u_last, u_law):
    """The interface's command of the sample, ``(c, c_filtered)``: the law's output through the vendor
    filter (``joint_torque``: ``alpha u_law + (1 - alpha) c_{k-1}``) and the rate limit, each against
    the last command ``u_last``; ``c_filtered`` is the value before the rate limit."""
    filtered = u_law if L.lowpass_alpha >= 1.0 else L.lowpass_alpha * u_law + (1.0 - L.lowpass_alpha) * u_last
    return rate_limited(ops, L, u_last, filtered), filtered


def rate_limited(ops, L: StepLayout, u_last, u_law):
    """The applied torque: ``u_law`` moved at most ``rate_step`` from the last applied torque ``u_last``."""
    if not L.rate_step:
        return u_law
    r = ops.const(L.rate_step)
    return ops.fmin(ops.fmax(u_law, u_last - r), u_last + r)


def rate_windup(ops, L: StepLayout, zdot, u_law, u, e1):
    """``zdot`` with the error integral of the joints the rate limit holds back frozen.

    A joint is frozen while the applied ``u`` lags the law's ``u_law`` in the direction the
    measured error ``e1 = q - q_d`` asks for (``u_law > u`` with ``e1 < 0``, or ``u_law < u`` with
    ``e1 > 0``): integrating then only winds up (the law's own anti-windup sees its torque limit,
    not the rate limit, which acts after it).
    """
    if not L.integral:
        return zdot
    n = L.n
    held = (u_law > u) * (e1 < 0) + (u_law < u) * (e1 > 0)
    frozen = zdot[:n] * (1 - held)
    return ops.cat([frozen, zdot[n:L.nz]]) if L.nz > n else frozen


def nominal_gravity(controller, model):
    """``(gravity Function, p_nom)``: the gravity of the controller's model at its nominal parameters."""
    nominal = controller_model(controller, model)
    p_nom = getattr(controller, "p_nom", None)
    p_nom = nominal.params_array({}) if p_nom is None else p_nom
    return gravity_function(nominal), np.asarray(p_nom, dtype=float)
