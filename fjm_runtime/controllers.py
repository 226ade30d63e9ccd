"""Sliding-mode, integral sliding-mode and feedback-linearizing controllers.

All controllers act per joint on the linearizing coordinates of docs/design.md
("The model"), computed with NOMINAL parameters only (the controller never sees the
true plant)::

    y_hat = T(x; p_nom)                    four blocks of n: y1..y4
    e_i   = y_hat_i - y_id                 i = 1..4, each shape (n,)
    s     = c1 e1 + c2 e2 + c3 e3 + e4     (paper eq 10, c4 = 1)
    nu    = y4d' - (c1 e2 + c2 e3 + c3 e4) - k_s psi(s / delta) - k_lin s
    u     = alpha(x; p_nom) + beta_hat nu  (paper eq 12)

``psi`` is ``sat`` (boundary layer, the paper's simulations), ``sign`` (the
paper's eq 15, chattering) or zero (``mode='fl'``, plain feedback
linearization with the linear term ``k_lin s``; with ``k_lin = lambda`` and
``c`` from a triple pole at ``-lambda`` the error has a quadruple pole there).

The integral variant (``integral=True``) adds a controller state ``z`` with
``z' = e1`` and uses ``s = c0 z + c1 e1 + c2 e2 + c3 e3 + e4`` and
``nu = y4d' - (c0 e1 + c1 e2 + c2 e3 + c3 e4) - k_s psi(s / delta)``.

Controller interface used by :func:`fjm_runtime.simulate.simulate`:

``n_states``
    size of the internal state ``z`` (0 for the plain controller);
``initial_state(t0, x0, r0) -> (n_states,)``;
``evaluate(t, x, z, r) -> ControlSample`` (called once per sample, the
    torque is held over the step: zero-order hold, as a digital controller);
``state_derivative(t, x, z, r, sample) -> (n_states,)`` (called at every RK4
    stage, so ``z`` is integrated together with the plant).
"""
from __future__ import annotations

from math import comb
from typing import NamedTuple, Optional

import numpy as np

from .validation import joint_vector

MODES = ("sat", "sign", "fl")


class ControlSample(NamedTuple):
    """Everything the controller computed at one sample.

    Attributes
    ----------
    u : ndarray, shape (n,)
        Applied torque (after the optional limit ``u_max``), N m.
    u_cmd : ndarray, shape (n,)
        Commanded torque before the limit, N m.
    s : ndarray, shape (n,)
        Sliding variable per joint.
    y_hat : ndarray, shape (4, n)
        Linearizing coordinates computed with nominal parameters.
    e : ndarray, shape (4, n)
        ``y_hat - y_d``.
    saturated : ndarray of bool, shape (n,)
        Joints whose torque hit ``u_max``.
    """

    u: np.ndarray
    u_cmd: np.ndarray
    s: np.ndarray
    y_hat: np.ndarray
    e: np.ndarray
    saturated: np.ndarray


def coefficients_from_pole(lam: float, order: int = 3) -> np.ndarray:
    """Sliding-surface coefficients placing all ``order`` poles at ``-lam``.

    ``(p + lam)^order = p^order + c_{order-1} p^(order-1) + ... + c_0``; the
    returned array is ``[c_0, ..., c_{order-1}]`` (lowest power first), e.g.
    ``order=3``: ``[lam^3, 3 lam^2, 3 lam]`` = the paper's ``c1, c2, c3``.

    Parameters
    ----------
    lam : float
        Pole magnitude in 1/s, > 0.
    order : int
        Number of poles (3 for the paper's surface, 4 for the integral one).

    Returns
    -------
    ndarray, shape (order,)
    """
    if not (np.isfinite(lam) and lam > 0):
        raise ValueError(f"lam = {lam!r}: expected a finite pole magnitude > 0 (1/s)")
    return np.array([comb(order, k) * lam ** (order - k) for k in range(order)], dtype=float)


def _check_hurwitz(c: np.ndarray, field: str) -> None:
    # characteristic polynomial p^m + c_{m-1} p^{m-1} + ... + c_0
    roots = np.roots(np.concatenate([[1.0], c[::-1]]))
    if np.any(roots.real >= 0):
        raise ValueError(f"{field} = {c.tolist()}: the polynomial p^{c.size} + ... is not Hurwitz "
                         f"(roots {np.round(roots, 4).tolist()}); the sliding surface would be unstable")


def _joint_gain(value, n: int, field: str, positive: bool) -> np.ndarray:
    """Per-joint gain: > 0 if ``positive`` else >= 0 (see :func:`validation.joint_vector`)."""
    return joint_vector(value, n, field, minimum=0.0, strict=positive)


class SlidingModeController:
    """Paper's sliding-mode controller (eqs 10-15), optionally with integral surface.

    Parameters
    ----------
    model : Model
        Loaded model (``fjm_runtime.load``); only ``T``, ``alpha``, ``beta`` are used.
    nominal_params : dict or array_like
        NOMINAL parameters the controller believes in (dict or array in
        ``model.param_names`` order).
    lam : float, optional
        Pole magnitude (1/s): ``c`` from a triple (``integral=False``) or
        quadruple (``integral=True``) pole at ``-lam``. Give ``lam`` or ``c``.
    c : array_like, optional
        Surface coefficients, lowest first: ``[c1, c2, c3]`` or, with
        ``integral=True``, ``[c0, c1, c2, c3]``; all > 0 and Hurwitz.
    k_s : float or array_like, shape (n,)
        Switching gain (rad/s^4), >= 0; ignored (set to 0) for ``mode='fl'``.
    delta : float or array_like, shape (n,)
        Boundary-layer width for ``mode='sat'``, > 0.
    mode : {'sat', 'sign', 'fl'}
        Switching function.
    beta_hat : array_like, shape (n, n) or scalar, optional
        Constant estimate of ``beta``; default ``beta(x; p_nom)`` at every sample.
        For link1, :func:`fjm_runtime.robust.beta_hat_link1` gives the paper's
        ``(beta_max + beta_min) / 2``.
    k_lin : float or array_like, shape (n,), optional
        Linear feedback on ``s`` (1/s), >= 0. Default 0 for 'sat'/'sign' and
        ``c_last / order`` (= ``lam``) for 'fl'.
    u_max : float or array_like, shape (n,), optional
        Torque limit in N m (> 0); ``None`` = unlimited.
    integral : bool
        Use the integral sliding surface (controller state ``z' = e1``).
        Anti-windup: conditional integration, ``z_i`` is frozen while joint
        ``i``'s commanded torque exceeds ``u_max`` AND ``e1_i`` would drive it
        further into the limit (``u_cmd_i > u_max`` with ``e1_i < 0``, or
        ``u_cmd_i < -u_max`` with ``e1_i > 0``; integral action on ``u_i`` has
        the sign of ``-e1_i``).
    anti_windup : bool
        Enable the conditional integration above (default True; False only to
        demonstrate windup).
    """

    def __init__(self, model, nominal_params, *, lam: Optional[float] = None, c=None,
                 k_s=0.0, delta=0.1, mode: str = "sat", beta_hat=None, k_lin=None,
                 u_max=None, integral: bool = False, anti_windup: bool = True):
        if mode not in MODES:
            raise ValueError(f"mode = {mode!r}: expected one of {', '.join(MODES)}")
        self.model = model
        self.n = n = int(model.n)
        self.mode = mode
        self.integral = bool(integral)
        self.p_nom = _params_array(model, nominal_params, "nominal_params")
        order = 4 if self.integral else 3
        if (lam is None) == (c is None):
            raise ValueError("lam/c: give exactly one of lam (pole magnitude) or c (coefficients)")
        if lam is not None:
            self.c = coefficients_from_pole(lam, order)
        else:
            cc = np.asarray(c, dtype=float).ravel()
            if cc.shape != (order,):
                raise ValueError(f"c with shape {cc.shape}: expected ({order},) "
                                 f"({'[c0, c1, c2, c3]' if self.integral else '[c1, c2, c3]'})")
            if not np.all(np.isfinite(cc)) or np.any(cc <= 0):
                raise ValueError(f"c = {cc.tolist()}: expected finite values > 0")
            _check_hurwitz(cc, "c")
            self.c = cc
        self.k_s = np.zeros(n) if mode == "fl" else _joint_gain(k_s, n, "k_s", positive=False)
        self.delta = _joint_gain(delta, n, "delta", positive=True)
        if k_lin is None:
            k_lin = self.c[-1] / order if mode == "fl" else 0.0
        self.k_lin = _joint_gain(k_lin, n, "k_lin", positive=False)
        if beta_hat is None:
            self.beta_hat = None
        else:
            b = np.asarray(beta_hat, dtype=float)
            if b.ndim == 0:
                b = b * np.eye(n)
            if b.shape != (n, n) or not np.all(np.isfinite(b)):
                raise ValueError(f"beta_hat with shape {b.shape}: expected a finite ({n}, {n}) matrix")
            if np.any(np.linalg.eigvals(0.5 * (b + b.T)).real <= 0):
                raise ValueError(f"beta_hat = {b.tolist()}: expected a positive definite matrix")
            self.beta_hat = b
        self.u_max = None if u_max is None else _joint_gain(u_max, n, "u_max", positive=True)
        self.anti_windup = bool(anti_windup)
        self.n_states = n if self.integral else 0

    # -- interface -----------------------------------------------------------
    def initial_state(self, t0: float, x0: np.ndarray, r0: np.ndarray) -> np.ndarray:
        """Initial controller state, shape ``(n_states,)`` (the integrator starts at 0)."""
        return np.zeros(self.n_states)

    def switching(self, s: np.ndarray) -> np.ndarray:
        """``psi(s / delta)``: sat, sign or zero, shape (n,)."""
        if self.mode == "sat":
            return np.clip(s / self.delta, -1.0, 1.0)
        if self.mode == "sign":
            return np.sign(s)
        return np.zeros_like(s)

    def surface(self, e: np.ndarray, z: np.ndarray):
        """Sliding variable and the linear part of ``nu``.

        Parameters
        ----------
        e : ndarray, shape (4, n)
            Errors ``y_hat - y_d``.
        z : ndarray, shape (n_states,)
            Integrator state (ignored unless ``integral``).

        Returns
        -------
        s : ndarray, shape (n,)
        linear : ndarray, shape (n,)
            ``c1 e2 + c2 e3 + c3 e4`` (or ``c0 e1 + ... + c3 e4``).
        """
        chain = np.vstack([z[None, :], e]) if self.integral else e
        m = self.c.size
        s = self.c @ chain[:m] + chain[m]
        linear = self.c @ chain[1:m + 1]
        return s, linear

    def evaluate(self, t: float, x: np.ndarray, z: np.ndarray, r: np.ndarray) -> ControlSample:
        """Control law at one sample.

        Parameters
        ----------
        t : float
            Time in s.
        x : ndarray, shape (4n,)
            Plant state (measured).
        z : ndarray, shape (n_states,)
            Controller state.
        r : ndarray, shape (5, n)
            Reference and its derivatives (see :mod:`fjm_runtime.references`).
        """
        n = self.n
        z = np.asarray(z, dtype=float)
        p = self._params(z)
        y_hat = np.asarray(self.model.T(x, p), dtype=float).reshape(4, n)
        e = y_hat - r[:4]
        s, linear = self.surface(e, self._integrator(z))
        nu = r[4] - linear - self.k_s * self.switching(s) - self.k_lin * s
        alpha = np.asarray(self.model.alpha(x, p), dtype=float).reshape(n)
        beta = self.beta_hat if self.beta_hat is not None else \
            np.asarray(self.model.beta(x, p), dtype=float).reshape(n, n)
        u_cmd = alpha + beta @ nu
        if self.u_max is None:
            u, saturated = u_cmd, np.zeros(n, dtype=bool)
        else:
            u = np.clip(u_cmd, -self.u_max, self.u_max)
            saturated = np.abs(u_cmd) > self.u_max
        return ControlSample(u, u_cmd, s, y_hat, e, saturated)

    def state_derivative(self, t: float, x: np.ndarray, z: np.ndarray, r: np.ndarray,
                         sample: ControlSample) -> np.ndarray:
        """``z' = e1 = q_l - q_d`` with conditional-integration anti-windup, shape (n_states,).

        ``y_hat_1 = q_l`` for every model, so no model evaluation is needed; the
        saturation flags come from the last sample (zero-order hold).
        """
        if not self.integral:
            return np.zeros(0)
        e1 = x[:self.n] - r[0]
        if self.u_max is not None and self.anti_windup:
            winding = (sample.u_cmd > self.u_max) & (e1 < 0) | (sample.u_cmd < -self.u_max) & (e1 > 0)
            e1 = np.where(winding, 0.0, e1)
        return e1


    def _params(self, z) -> np.ndarray:
        """Parameters the law is evaluated with: the nominal ones here.

        Subclasses that estimate parameters online override this and
        :meth:`_integrator` (and their CasADi mirrors below).
        """
        return self.p_nom

    def _integrator(self, z):
        """The integral-surface state within the controller state ``z``."""
        return z

    # -- CasADi mirror (used by the fused simulator; must match evaluate) ----
    def _symbolic_params(self, z):
        """Parameters the law is evaluated with (CasADi): the nominal ones here.

        Subclasses that estimate parameters online override this (and
        :meth:`_symbolic_integrator` if their state holds more than ``z'= e1``).
        """
        import casadi as ca
        return ca.DM(self.p_nom)

    def _symbolic_integrator(self, z):
        """The integral-surface state within the controller state ``z``."""
        return z

    def symbolic_evaluate(self, x, z, r, fns):
        """CasADi mirror of :meth:`evaluate` for the fused simulator.

        Parameters
        ----------
        x : casadi.MX, shape (4n, 1)
        z : casadi.MX, shape (n_states, 1)
        r : casadi.MX, shape (5n, 1)
            Reference rows stacked: ``r.reshape(-1)`` of the (5, n) array.
        fns : dict
            CasADi Functions ``T``, ``alpha``, ``beta`` of ``(x, p)``.

        Returns
        -------
        dict with ``u``, ``u_cmd``, ``s`` (n, 1) and ``y_hat`` (4n, 1).
        """
        import casadi as ca
        n = self.n
        blk = lambda v, i: v[i * n:(i + 1) * n]
        p = self._symbolic_params(z)
        y_hat = fns["T"](x, p)
        e = [blk(y_hat, i) - blk(r, i) for i in range(4)]
        chain = ([self._symbolic_integrator(z)] if self.integral else []) + e
        m = self.c.size
        s = chain[m]
        linear = 0
        for j in range(m):
            s = s + float(self.c[j]) * chain[j]
            linear = linear + float(self.c[j]) * chain[j + 1]
        if self.mode == "sat":
            psi = ca.fmin(ca.fmax(s / ca.DM(self.delta), -1.0), 1.0)
        elif self.mode == "sign":
            psi = ca.sign(s)
        else:
            psi = ca.DM.zeros(n, 1)
        nu = blk(r, 4) - linear - ca.DM(self.k_s) * psi - ca.DM(self.k_lin) * s
        beta = ca.DM(self.beta_hat) if self.beta_hat is not None else ca.reshape(fns["beta"](x, p), n, n)
        u_cmd = fns["alpha"](x, p) + ca.mtimes(beta, nu)
        if self.u_max is None:
            u = u_cmd
        else:
            um = ca.DM(self.u_max)
            u = ca.fmin(ca.fmax(u_cmd, -um), um)
        return {"u": u, "u_cmd": u_cmd, "s": s, "y_hat": y_hat}

    def symbolic_state_derivative(self, x, z, r, sample):
        """CasADi mirror of :meth:`state_derivative` (``sample`` from :meth:`symbolic_evaluate`)."""
        import casadi as ca
        if not self.integral:
            return ca.MX(0, 1)
        n = self.n
        e1 = x[:n] - r[:n]
        if self.u_max is not None and self.anti_windup:
            um = ca.DM(self.u_max)
            uc = sample["u_cmd"]
            winding = (uc > um) * (e1 < 0) + (uc < -um) * (e1 > 0)
            e1 = e1 * (1 - winding)
        return e1


def _params_array(model, p, field: str) -> np.ndarray:
    if hasattr(model, "params_array"):
        try:
            a = np.asarray(model.params_array(p, arg=field), dtype=float)
        except TypeError:
            a = np.asarray(model.params_array(p), dtype=float)
    else:  # pragma: no cover - every fjm model has params_array
        a = np.asarray(p, dtype=float)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{field} = {a.tolist()}: expected finite values")
    return a


CONTROLLER_KINDS = ("smc", "ismc", "fl", "sign", "adaptive")


def make_controller(kind: str, model, nominal_params, **kwargs) -> SlidingModeController:
    """Build a controller by name.

    Parameters
    ----------
    kind : {'smc', 'ismc', 'fl', 'sign', 'adaptive'}
        ``'smc'``: paper's surface with ``sat``; ``'sign'``: the paper's
        discontinuous law; ``'ismc'``: integral surface with ``sat``; ``'fl'``:
        plain feedback linearization (no switching term, quadruple pole);
        ``'adaptive'``: online stiffness estimate in ``T``, ``alpha``, ``beta``
        (:class:`fjm_runtime.adaptive.AdaptiveStiffnessController`; keywords
        ``K_bounds``, ``filter_rate``, ``ls_gain``, ``integral``).
    model, nominal_params, **kwargs
        Passed to :class:`SlidingModeController`.
    """
    if kind == "smc":
        return SlidingModeController(model, nominal_params, mode="sat", **kwargs)
    if kind == "sign":
        return SlidingModeController(model, nominal_params, mode="sign", **kwargs)
    if kind == "ismc":
        return SlidingModeController(model, nominal_params, mode=kwargs.pop("mode", "sat"),
                                     integral=True, **kwargs)
    if kind == "fl":
        kwargs.pop("k_s", None)
        return SlidingModeController(model, nominal_params, mode="fl", **kwargs)
    if kind == "adaptive":
        from .adaptive import make_adaptive
        return make_adaptive(model, nominal_params, **kwargs)
    raise ValueError(f"controller = {kind!r}: expected one of {', '.join(CONTROLLER_KINDS)}")
