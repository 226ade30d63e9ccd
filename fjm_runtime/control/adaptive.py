"""Sliding-mode control with an online joint-stiffness estimate (issue 7 item 3, research grade).

Why
---
With nominal parameters only, ``T_hat``, ``alpha_hat`` and ``beta_hat`` are built
from ``K_nom``; the error of ``y3_hat``/``y4_hat`` (the spring torque seen
through the wrong stiffness) is what leaves the paper's controller with a
regulation offset and both sliding controllers with a tracking error. The
stiffness is the one parameter that the motor side measures almost directly,
so it can be estimated online and put back into ``T``, ``alpha`` and ``beta``.

Scheme (per joint ``i``, certainty equivalence)
-----------------------------------------------
The motor equation (docs/design.md, "The model") is linear in the stiffness::

    J_m ddq_m + B_m dq_m + K phi = u,        phi = q_m - q_l   (deflection)

Measured: the full state ``x = [q_l; dq_l; q_m; dq_m]`` and the torque ``u``
the controller applied (held over the sample); ``J_m`` and ``B_m`` are NOMINAL.
No acceleration is differentiated: every term goes through the same stable
first-order filter ``H(s) = a / (s + a)`` (``a = filter_rate``), with the
controller states ``u_f, phi_f, w_f``::

    u_f'   = a (u - u_f)             u_f(0) = 0
    phi_f' = a (phi - phi_f)         phi_f(0) = 0
    w_f'   = a (dq_m - w_f)          w_f(0) = dq_m(0)

``H[ddq_m] = a (dq_m - w_f)`` exactly (``s H(s) = a - a H(s)``), so the
filtered motor equation is a static linear regression with no derivative::

    y_f = u_f - J_m a (dq_m - w_f) - B_m w_f = K phi_f - B_m dq_m(0) e^{-a t}

The estimate ``K_hat`` follows continuous least squares on the prediction
error ``eps = y_f - K_hat phi_f``, with the scalar covariance ``P``::

    K_hat' = Proj(P phi_f eps),      P' = -P^2 phi_f^2,      P(0) = ls_gain

``Proj`` zeroes the update when ``K_hat`` is at a bound of ``[K_min, K_max]``
and the update points outward, and the value USED (and reported by
:meth:`AdaptiveStiffnessController.stiffness_estimate`) is
``clip(K_hat, K_min, K_max)``, so the controller never uses a stiffness outside
the bounds even between RK4 stages. Without projection and with exact
``J_m, B_m`` the error has the closed form
``K - K_hat(t) = (K - K_hat(0)) / (1 + P(0) int_0^t phi_f^2)``: it shrinks with
the accumulated squared filtered deflection.

The controller then uses ``p_hat = p_nom`` with the stiffness entries replaced
by ``K_hat``: ``y_hat = T(x; p_hat)``, ``alpha(x; p_hat)`` and (unless a
constant ``beta_hat`` is given) ``beta(x; p_hat)``, with the paper's surface
(``integral=False``) or the integral surface (``integral=True``) of
:class:`fjm_runtime.controllers.SlidingModeController`. The time variation of
``K_hat`` is ignored in ``y4_hat'`` (certainty equivalence); the switching term
absorbs it while the estimate moves.

Assumptions and limits (state them when quoting results)
--------------------------------------------------------
* Persistence of excitation: ``K`` is observable only through the deflection.
  At rest with zero deflection (link1 hanging at ``q = 0``, no load) nothing is
  learned and ``K_hat`` stays where it is; gravity away from the hanging
  position (``M g0 L sin q``) and link acceleration provide the deflection.
  The convergence speed scales with ``int phi_f^2`` (for link1 at 1 rad,
  ``phi`` is about 0.05-0.08 rad).
* ``J_m`` and ``B_m`` are nominal; an error in them biases ``K_hat``
  (``(J_m - J_m,nom) ddq_m`` is read as spring torque). Friction not in the
  model (Coulomb, stiction) biases it too.
* The torque entering the regression is the one applied to the motor (after
  the limit ``u_max``), assumed to be delivered exactly.
* Noise-free simulation: no measurement noise, so least squares without
  forgetting is used (the gain ``P`` decays; a slowly drifting ``K`` would need
  forgetting with a bounded ``P``, not implemented).
* The stiffness enters ``T``, ``alpha``, ``beta`` of every generated model in
  the same place; the estimator works per joint for ``link1`` (``K``, ``J_m``,
  ``B_m``) and ``planar<n>`` (``K_i``, ``Jm_i``, ``Bm_i``).

Controller state ``z`` (``n`` joints), integrated with the plant in RK4::

    [z_int (n, only with integral=True), K_hat (n), u_f (n), phi_f (n), w_f (n), P (n)]
"""
from __future__ import annotations

# The classes live in fjm_runtime.controllers (one module, no import circle); the law
# and the estimator rates above are the emitted ``<model>_control_adaptive`` (derive/emit/controls.py).
from ..control.laws import (ESTIMATOR_BLOCKS, AdaptiveStiffnessController, _param_indices,  # noqa: F401
                          make_adaptive)

__all__ = ["AdaptiveStiffnessController", "ESTIMATOR_BLOCKS", "make_adaptive"]
