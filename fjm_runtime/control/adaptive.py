"""Sliding-mode control with an online joint-stiffness estimate (research grade).

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
the bounds even when the raw estimate overshoots within a sample. In continuous time, without projection and with exact
``J_m, B_m`` the error has the closed form
``K - K_hat(t) = (K - K_hat(0)) / (1 + P(0) int_0^t phi_f^2)``: it shrinks with
the accumulated squared filtered deflection.

The controller then uses ``p_hat = p_nom`` with the stiffness entries replaced
by ``K_hat``: ``y_hat = T(x; p_hat)``, ``alpha(x; p_hat)`` and (unless a
constant ``beta_hat`` is given) ``beta(x; p_hat)``, with the paper's surface
(``integral=False``) or the integral surface (``integral=True``) of
:class:`fjm_runtime.control.laws.SlidingModeController`. The time variation of
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

Controller state ``z`` (``n`` joints), advanced once per sample by the simulators' sampled-data loop
(``z_{k+1} = z_k + T z_dot_k``: the filtered regression then holds to O(T), so the estimate settles
O(T) away from ``K``; the closed form above is the continuous-time limit)::

    [z_int (n, only with integral=True), K_hat (n), u_f (n), phi_f (n), w_f (n), P (n)]
"""
from __future__ import annotations

import numpy as np

from ..drives import drive_indices, linear_stiffness_indices
from .defaults import DEFAULT_FILTER_RATE, DEFAULT_LS_GAIN, default_K_bounds
from .laws import SlidingModeController

__all__ = ["AdaptiveStiffnessController", "ESTIMATOR_BLOCKS", "make_adaptive"]

#: Names of the blocks of the estimator part of ``z``, in order.
ESTIMATOR_BLOCKS = ("K_hat", "u_f", "phi_f", "w_f", "P")


def _bounds(K_bounds, n: int):
    try:
        lo, hi = K_bounds
    except (TypeError, ValueError):
        raise ValueError(f"K_bounds = {K_bounds!r}: expected (K_min, K_max) in N m/rad") from None
    lo = np.broadcast_to(np.asarray(lo, dtype=float), (n,)).copy() if np.ndim(lo) == 0 else np.asarray(lo, float)
    hi = np.broadcast_to(np.asarray(hi, dtype=float), (n,)).copy() if np.ndim(hi) == 0 else np.asarray(hi, float)
    if lo.shape != (n,) or hi.shape != (n,):
        raise ValueError(f"K_bounds with shapes {lo.shape}, {hi.shape}: expected scalars or shape ({n},)")
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo > 0) and np.all(hi > lo)):
        raise ValueError(f"K_bounds = ({lo.tolist()}, {hi.tolist()}): expected finite 0 < K_min < K_max "
                         "(N m/rad)")
    return lo, hi


def _positive(value, field: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{field} = {value!r}: expected a number > 0") from None
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{field} = {value!r}: expected a finite value > 0")
    return v


class AdaptiveStiffnessController(SlidingModeController):
    """Sliding-mode controller using an online least-squares estimate of the joint stiffness.

    The law and the estimator are the emitted ``<model>_control_adaptive`` (and
    ``_zdot``); :mod:`fjm_runtime.control.adaptive` explains the scheme and its assumptions.

    Parameters
    ----------
    model, nominal_params
        As :class:`SlidingModeController`; the nominal stiffness is the initial
        estimate and must lie inside ``K_bounds``.
    K_bounds : (K_min, K_max)
        Stiffness bounds in N m/rad (scalars or one per joint), ``0 < K_min < K_max``;
        the estimate is projected onto them.
    filter_rate : float
        Bandwidth ``a`` of the regressor filter ``a / (s + a)``, 1/s, > 0 (default
        :data:`~fjm_runtime.control.defaults.DEFAULT_FILTER_RATE`, 20).
    ls_gain : float
        Initial least-squares covariance ``P(0)`` in 1/(rad^2 s), > 0 (default
        :data:`~fjm_runtime.control.defaults.DEFAULT_LS_GAIN`, 1e5).
    integral : bool
        Integral sliding surface (default True) or the paper's surface.
    beta_hat : optional
        Constant ``beta_hat``; default ``beta(x; p_hat)`` with the estimated stiffness.
    **kwargs
        ``lam``/``c``, ``k_s``, ``delta``, ``mode``, ``k_lin``, ``u_max``, ``anti_windup``
        as for the base class.

    Controller state ``z``: ``[z_int (n, only with integral=True), K_hat, u_f, phi_f, w_f, P]``.
    """

    def __init__(self, model, nominal_params, *, K_bounds, filter_rate: float = DEFAULT_FILTER_RATE,
                 ls_gain: float = DEFAULT_LS_GAIN, integral: bool = True, beta_hat=None, **kwargs):
        super().__init__(model, nominal_params, integral=integral, beta_hat=beta_hat, **kwargs)
        n = self.n
        self.K_min, self.K_max = _bounds(K_bounds, n)
        self.filter_rate = _positive(filter_rate, "filter_rate")
        self.ls_gain = _positive(ls_gain, "ls_gain")
        self.idx_K = linear_stiffness_indices(model, "adaptive stiffness")   # the estimator adapts K
        self.idx_Jm, self.idx_Bm = drive_indices(model, "rotor_inertia"), drive_indices(model, "damping")
        K0 = self.p_nom[self.idx_K]
        if np.any(K0 < self.K_min) or np.any(K0 > self.K_max):
            raise ValueError(f"K_bounds = ({self.K_min.tolist()}, {self.K_max.tolist()}): the nominal stiffness "
                             f"{K0.tolist()} (initial estimate) must lie inside")
        self.J_m = self.p_nom[self.idx_Jm]
        self.B_m = self.p_nom[self.idx_Bm]
        self.n_int = n if self.integral else 0
        self.n_states = self.n_int + len(ESTIMATOR_BLOCKS) * n

    @property
    def law_kind(self) -> str:
        return "adaptive"

    def _law_z_offset(self) -> int:
        # the emitted law always carries z_int; the paper's surface is c0 = 0 with z_int = 0
        return self.n - self.n_int

    def gain_values(self) -> dict:
        g = super().gain_values()
        if not self.integral:
            g["c"] = np.concatenate([[0.0], self.c])
        g.update(K_min=self.K_min, K_max=self.K_max, filter_rate=self.filter_rate)
        return g

    def stiffness_estimate(self, z) -> np.ndarray:
        """The stiffness the controller uses, ``clip(K_hat, K_min, K_max)``; ``z`` of shape
        ``(n_states,)`` or ``(N, n_states)`` (e.g. ``SimulationResult.z``) -> ``(n,)`` or ``(N, n)``."""
        z = np.asarray(z, dtype=float)
        k = self.n_int
        return np.clip(z[..., k:k + self.n], self.K_min, self.K_max)

    def params_hat(self, z) -> np.ndarray:
        """Nominal parameters with the stiffness replaced by the estimate, shape ``(n_par,)``."""
        p = self.p_nom.copy()
        p[self.idx_K] = self.stiffness_estimate(z)
        return p

    def initial_state(self, t0: float, x0: np.ndarray, r0: np.ndarray) -> np.ndarray:
        n = self.n
        x0 = np.asarray(x0, dtype=float)
        est = {"K_hat": self.p_nom[self.idx_K], "u_f": np.zeros(n), "phi_f": np.zeros(n),
               "w_f": x0[3 * n:4 * n], "P": np.full(n, self.ls_gain)}
        return np.concatenate([np.zeros(self.n_int)] + [est[b] for b in ESTIMATOR_BLOCKS])


def make_adaptive(model, nominal_params, *, K_bounds=None, **kwargs) -> AdaptiveStiffnessController:
    """``make_controller('adaptive', ...)``: ``K_bounds`` defaults to
    :func:`~fjm_runtime.control.defaults.default_K_bounds` of the nominal stiffness
    (``nominal +- 1/3``: 100-200 at 150); ``mode`` defaults to ``'sat'``."""
    if K_bounds is None:
        p = np.asarray(model.params_array(nominal_params), dtype=float)
        K_bounds = default_K_bounds(p[linear_stiffness_indices(model, "adaptive stiffness")])
    kwargs.setdefault("mode", "sat")
    return AdaptiveStiffnessController(model, nominal_params, K_bounds=K_bounds, **kwargs)
