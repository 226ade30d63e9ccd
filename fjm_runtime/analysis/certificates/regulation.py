"""Rest points of the closed loop: the regulation offset of a wrong stiffness and the linearized poles.

:func:`predict_regulation_offset` (link1) solves for the rest point the non-integral
law settles at when the controller's stiffness is wrong; :func:`closed_loop_eigenvalues`
(any model) linearizes the continuous-time loop at a rest point.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .link1 import link1_equilibrium, link1_params

__all__ = ["OffsetPrediction", "predict_regulation_offset", "closed_loop_eigenvalues"]


@dataclass
class OffsetPrediction:
    """Predicted steady state of a set-point regulation (link1).

    Attributes
    ----------
    q_ss : float
        Link angle at which the closed loop comes to rest (rad).
    offset : float
        ``q_ss - q_d`` (rad), exact for the controller's law (includes the boundary-layer term).
    first_order : float
        ``-(c3 / c1) (K_nom / K - 1) M g0 L sin(q_d) / J_l``: the sliding-surface
        term alone (``= -(3 / lambda^2) (...)`` for a triple pole), i.e. the
        offset when ``s = 0``; the rest, ``offset - first_order``, is the
        ``O(delta / k_s)`` boundary-layer term plus the ``sin(q_ss)`` vs
        ``sin(q_d)`` difference.
    s_ss : float
        Sliding variable at rest.
    """

    q_ss: float
    offset: float
    first_order: float
    s_ss: float



def predict_regulation_offset(model, controller, q_d: float, true_params, search: float = 1.5,
                              n_scan: int = 301) -> OffsetPrediction:
    """Steady-state regulation error of a non-integral controller on link1 with wrong parameters.

    At rest at link angle ``q`` the plant needs the holding torque
    ``u_eq = M g0 L sin(q)`` and sits at ``x(q) = [q, 0, q + M g0 L sin(q) / K, 0]``.
    The controller (nominal ``T_hat``) sees ``e3 = T3(x(q); p_nom) = (K_nom / K - 1)
    M g0 L sin(q) / J_l`` (when ``J_l``, ``M``, ``L`` are right) instead of 0, so
    the rest point solves ``u_controller(x(q)) = u_eq(q)``. We solve that scalar
    equation (scan over ``q_d +- search`` then bisection; the root nearest
    ``q_d`` is returned). Inside the boundary layer the solution is
    ``c1 e1 + c3 e3 = s_ss`` with ``s_ss = O(delta / k_s)``, i.e. ``e1 ~ -(c3/c1) e3``.

    Parameters
    ----------
    model : Model
        ``fjm_runtime.load("link1")``.
    controller : SlidingModeController
        A non-integral controller (``'sat'`` or ``'fl'``).
    q_d : float
        Constant set point (rad).
    true_params : dict or array_like
        Plant parameters.

    Returns
    -------
    OffsetPrediction
    """
    if getattr(controller, "integral", False):
        raise ValueError("controller: the integral controller has no offset (z' = e1 forces e1 -> 0)")
    if getattr(controller, "mode", "sat") == "sign":
        raise ValueError("controller.mode = 'sign': no rest point (chatters); use 'sat' or 'fl'")
    if not np.isfinite(q_d):
        raise ValueError(f"q_d = {q_d!r}: expected a finite angle (rad)")
    p_true = link1_params(dict(zip(model.param_names, np.asarray(model.params_array(true_params)).tolist())))
    p_nom = link1_params(dict(zip(model.param_names, np.asarray(controller.p_nom).tolist())))
    r = np.zeros((5, 1)); r[0, 0] = q_d
    mgl = p_true["M"] * p_true["g0"] * p_true["L"]
    z = np.zeros(0)

    def residual(q):
        x = link1_equilibrium(q, p_true)
        return float(controller.evaluate(0.0, x, z, r).u_cmd[0] - mgl * np.sin(q))

    qs = q_d + np.linspace(-search, search, n_scan)
    F = np.array([residual(q) for q in qs])
    idx = np.flatnonzero(np.sign(F[:-1]) * np.sign(F[1:]) <= 0)
    if idx.size == 0:
        raise ValueError(f"no rest point within q_d +- {search} rad for these parameters")
    i = idx[np.argmin(np.abs(qs[idx] - q_d))]
    lo, hi, flo = qs[i], qs[i + 1], F[i]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        fm = residual(mid)
        if np.sign(fm) == np.sign(flo):
            lo, flo = mid, fm
        else:
            hi = mid
    q_ss = 0.5 * (lo + hi)
    x_ss = link1_equilibrium(q_ss, p_true)
    s_ss = float(controller.evaluate(0.0, x_ss, z, r).s[0])
    c1, c3 = controller.c[0], controller.c[2]
    first = -(c3 / c1) * (p_nom["K"] / p_true["K"] - 1.0) * mgl * np.sin(q_d) / p_true["J_l"]
    return OffsetPrediction(q_ss=float(q_ss), offset=float(q_ss - q_d), first_order=float(first), s_ss=s_ss)


def closed_loop_eigenvalues(model, controller, true_params, x_eq=None, r=None, h: float = 1e-6) -> np.ndarray:
    """Eigenvalues of the continuous-time closed loop linearized at a rest point.

    The loop is ``x' = f(x; p_true) + g(x; p_true) u(x)`` with ``u`` the
    controller's law (nominal parameters, no sampling), differentiated by
    central differences. Only for controllers without internal state.

    Parameters
    ----------
    model : Model
    controller : SlidingModeController
        Non-integral controller.
    true_params : dict or array_like
    x_eq : array_like, shape (4n,), optional
        Rest point (default 0: planar chains hanging straight down, link1 at q = 0).
    r : array_like, shape (5, n), optional
        Reference held at ``x_eq`` (default: ``q_d = q_l`` of ``x_eq``, derivatives 0).
    h : float
        Difference step.

    Returns
    -------
    ndarray, shape (4n,), complex
        Sorted by decreasing real part (the first one decides stability).
    """
    if getattr(controller, "integral", False):
        raise ValueError("controller: integral controllers carry a state; linearize the augmented loop instead")
    n, nx = int(model.n), int(model.nx)
    x_eq = np.zeros(nx) if x_eq is None else np.asarray(x_eq, dtype=float)
    if x_eq.shape != (nx,):
        raise ValueError(f"x_eq with shape {x_eq.shape}: expected ({nx},)")
    if r is None:
        r = np.zeros((5, n))
        r[0] = x_eq[:n]
    p = model.params_array(true_params)
    z = np.zeros(0)

    def field(x):
        u = controller.evaluate(0.0, x, z, r).u
        return model.f(x, p) + model.g(x, p) @ u

    J = np.empty((nx, nx))
    for i in range(nx):
        dx = np.zeros(nx)
        dx[i] = h
        J[:, i] = (field(x_eq + dx) - field(x_eq - dx)) / (2 * h)
    ev = np.linalg.eigvals(J)
    return ev[np.argsort(-ev.real)]


