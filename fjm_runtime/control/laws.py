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

The law itself is not written here: it is emitted by ``make derive`` with every model
(``generated/<model>/control_<kind>.casadi`` and C, ``derive/emit/controls.py``) and called
(:meth:`SlidingModeController.evaluate`) or composed into CasADi graphs
(:meth:`SlidingModeController.symbolic_evaluate`) from here; this module validates the gains and
packs them into the law's ``gains`` vector (:attr:`SlidingModeController.gains`).

Controller interface used by :func:`fjm_runtime.sim.simulate.simulate`:

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

from ..validation import FjmValueError, joint_vector
from .defaults import DEFAULT_DELTA
from .sensing import SENSING_KINDS, measurement_size

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
        Boundary-layer width for ``mode='sat'``, > 0 (default
        :data:`~fjm_runtime.control.defaults.DEFAULT_DELTA`; the rule the tools use,
        ``k_s / 200``, is :func:`~fjm_runtime.control.defaults.default_delta`).
    mode : {'sat', 'sign', 'fl'}
        Switching function.
    beta_hat : array_like, shape (n, n) or scalar, optional
        Constant estimate of ``beta``; default ``beta(x; p_nom)`` at every sample.
        For link1, :func:`fjm_runtime.analysis.certificates.lemma1.beta_hat_link1` gives the paper's
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
    sensing : {'state', 'torque'}
        What the controller reads (:mod:`fjm_runtime.control.sensing`): the plant state
        ``x`` (4n; the emitted ``control_<kind>``) or the torque-sensed measurement
        ``m = [q; dq; tau_J; dtau_J; dq_m]`` (5n; the emitted ``control_<kind>_tau``,
        derived in torque coordinates, docs/torque-sensing.md). Every method's first
        state argument is that measurement (:attr:`measurement_size` long).
    """

    def __init__(self, model, nominal_params, *, lam: Optional[float] = None, c=None,
                 k_s=0.0, delta=DEFAULT_DELTA, mode: str = "sat", beta_hat=None, k_lin=None,
                 u_max=None, integral: bool = False, anti_windup: bool = True, sensing: str = "state"):
        if mode not in MODES:
            raise ValueError(f"mode = {mode!r}: expected one of {', '.join(MODES)}")
        if sensing not in SENSING_KINDS:
            raise ValueError(f"sensing = {sensing!r}: expected one of {', '.join(SENSING_KINDS)}")
        if sensing == "torque" and mode == "sign":
            raise ValueError("sensing = 'torque' with mode = 'sign': the torque-sensed laws are emitted "
                             "for smc (sat), ismc and fl; the sign law needs sensing = 'state'")
        #: ``'state'`` (reads x, 4n) or ``'torque'`` (reads m, 5n).
        self.sensing = sensing
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

    # -- the emitted law -----------------------------------------------------
    @property
    def measurement_size(self) -> int:
        """Length of the first state argument of every method: ``4n`` (x) or ``5n`` (m, torque-sensed)."""
        return measurement_size(self.sensing, self.n)

    @property
    def law_kind(self) -> str:
        """Which emitted law runs (``<model>_control_<kind>``): ``smc``, ``ismc``, ``fl``, ``adaptive``,
        or with ``sensing='torque'`` ``smc_tau``, ``ismc_tau``, ``fl_tau``."""
        base = "ismc" if self.integral else ("fl" if self.mode == "fl" else "smc")
        return base + ("_tau" if self.sensing == "torque" else "")

    def _law_z_offset(self) -> int:
        """Leading entries of the emitted law's ``z`` not held by this controller (always 0 here)."""
        return 0

    def gain_values(self) -> dict:
        """Every gain of the law, by the names of the emitted ``gains`` layout (manifest ``controls``)."""
        n = self.n
        bh = self.beta_hat if self.beta_hat is not None else np.zeros((n, n))
        return {"c": self.c, "k_s": self.k_s, "delta": self.delta, "sign": float(self.mode == "sign"),
                "k_lin": self.k_lin, "u_max": self.u_max if self.u_max is not None else np.ones(n),
                "limit": float(self.u_max is not None), "anti_windup": float(self.anti_windup),
                "use_beta_hat": float(self.beta_hat is not None), "beta_hat": bh.ravel(order="F")}

    @property
    def gains(self) -> np.ndarray:
        """The ``gains`` argument of the emitted law, packed by the model's manifest layout."""
        values = self.gain_values()
        layout = self.model.manifest["controls"][self.law_kind]["gains"]
        return np.concatenate([np.broadcast_to(np.asarray(values[b["name"]], dtype=float), (b["size"],))
                               for b in layout])

    def law_functions(self):
        """``(law, zdot)``: the emitted ``casadi.Function`` s of :attr:`law_kind` (``zdot`` None if stateless)."""
        fns = self.model.controls
        k = self.law_kind
        return fns[f"control_{k}"], fns.get(f"control_{k}_zdot")

    def _measurement(self, x) -> np.ndarray:
        """``x`` as the float vector the law reads, checked to be :attr:`measurement_size` long."""
        xa = np.asarray(x, dtype=float).ravel()
        if xa.shape != (self.measurement_size,):
            what = "x = [q; dq; q_m; dq_m]" if self.sensing == "state" else "m = [q; dq; tau_J; dtau_J; dq_m]"
            raise FjmValueError(f"measurement with shape {np.shape(x)}: expected ({self.measurement_size},), "
                                f"{what} (sensing = {self.sensing!r})")
        return xa

    def _z_full(self, z):
        off = self._law_z_offset()
        return np.concatenate([np.zeros(off), z]) if off else z

    # -- interface -----------------------------------------------------------
    def initial_state(self, t0: float, x0: np.ndarray, r0: np.ndarray) -> np.ndarray:
        """Initial controller state, shape ``(n_states,)`` (the integrator starts at 0)."""
        return np.zeros(self.n_states)

    def evaluate(self, t: float, x: np.ndarray, z: np.ndarray, r: np.ndarray) -> ControlSample:
        """Control law at one sample: the emitted ``<model>_control_<kind>``.

        Parameters
        ----------
        t : float
            Time in s.
        x : ndarray, shape (measurement_size,)
            What the controller measures: the plant state ``x`` (4n) for ``sensing='state'``,
            ``m = [q; dq; tau_J; dtau_J; dq_m]`` (5n) for ``sensing='torque'``.
        z : ndarray, shape (n_states,)
            Controller state.
        r : ndarray, shape (5, n)
            Reference and its derivatives (see :mod:`fjm_runtime.control.references`).
        """
        n = self.n
        r = np.asarray(r, dtype=float)
        law, _ = self.law_functions()
        u, s, _, u_cmd, y_hat = (np.asarray(v).ravel() for v in law(
            self._measurement(x), self._z_full(np.asarray(z, dtype=float)), r.reshape(-1),
            self.p_nom, self.gains))
        y_hat = y_hat.reshape(4, n)
        saturated = np.zeros(n, dtype=bool) if self.u_max is None else np.abs(u_cmd) > self.u_max
        return ControlSample(u, u_cmd, s, y_hat, y_hat - r[:4], saturated)

    def state_derivative(self, t: float, x: np.ndarray, z: np.ndarray, r: np.ndarray,
                         sample: ControlSample) -> np.ndarray:
        """``z'`` under the sample's held torque (the emitted ``<model>_control_<kind>_zdot``), shape (n_states,).

        ``z_int' = e1 = q_l - q_d`` with conditional-integration anti-windup (and, for
        the adaptive law, the estimator rates); the saturation test uses the last
        sample's ``u_cmd`` (zero-order hold).
        """
        if self.n_states == 0:
            return np.zeros(0)
        _, zdot = self.law_functions()
        out = np.asarray(zdot(self._measurement(x), self._z_full(np.asarray(z, dtype=float)),
                              np.asarray(r, dtype=float).reshape(-1), self.p_nom, self.gains,
                              sample.u_cmd, sample.u)).ravel()
        return out[self._law_z_offset():]

    # -- CasADi composition (fused, compiled and batch simulators) -------------
    def symbolic_evaluate(self, x, z, r, fns=None):
        """The emitted law composed into a CasADi graph.

        Parameters
        ----------
        x : casadi SX/MX, shape (measurement_size, 1)
            The measurement: ``x`` (4n) or, torque-sensed, ``m`` (5n).
        z : casadi SX/MX, shape (n_states, 1)
        r : casadi SX/MX, shape (5n, 1)
            Reference rows stacked: ``r.reshape(-1)`` of the (5, n) array.
        fns : ignored
            Kept for callers that pass the model Functions.

        Returns
        -------
        dict with ``u``, ``u_cmd``, ``s`` (n, 1) and ``y_hat`` (4n, 1).
        """
        import casadi as ca
        law, _ = self.law_functions()
        off = self._law_z_offset()
        zf = ca.vertcat(ca.DM.zeros(off), z) if off else z
        u, s, _, u_cmd, y_hat = law(x, zf, r, ca.DM(self.p_nom), ca.DM(self.gains))
        return {"u": u, "u_cmd": u_cmd, "s": s, "y_hat": y_hat}

    def symbolic_state_derivative(self, x, z, r, sample):
        """``z'`` of :meth:`state_derivative` in CasADi (``sample`` from :meth:`symbolic_evaluate`)."""
        import casadi as ca
        if self.n_states == 0:
            return ca.DM(0, 1)
        _, zdot = self.law_functions()
        off = self._law_z_offset()
        zf = ca.vertcat(ca.DM.zeros(off), z) if off else z
        out = zdot(x, zf, r, ca.DM(self.p_nom), ca.DM(self.gains), sample["u_cmd"], sample["u"])
        return out[off:]


def _params_array(model, p, field: str) -> np.ndarray:
    """``p`` (dict or array) as the model's parameter vector, shape (n_params,), checked finite."""
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
