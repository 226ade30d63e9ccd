"""The layout of the sample step's state ``w`` and the settings it is built for (:class:`StepLayout`).

:func:`make_layout` turns a run's model, controller, period, substeps, sensor model, delay and
prediction flag into the sizes and constants that :mod:`fjm_runtime.sim.sample_step` needs; the
layout is hashable (a key of the compiled-step caches).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..validation import FjmValueError
from .interface import CommandInterface
from .sensor import SensorModel, measurement_blocks

__all__ = ["StepLayout", "controller_model", "make_layout"]

#: The rate limit's stand-in for "none" in the arithmetic (finite, so C and SIMD code see no inf).
_NO_LIMIT = 1e300


def controller_model(controller, plant):
    """The model the controller was built on (its predictor's model); ``plant`` if it names none."""
    for obj in (controller, getattr(controller, "base", None)):
        m = getattr(obj, "model", None)
        if m is not None:
            return m
    return plant


@dataclass(frozen=True)
class StepLayout:
    """Sizes and settings of the sample step; ``w = [x | z | m_buf | u_buf | filt | venc | off | u_last | cur]``.

    Attributes
    ----------
    n, nx, nz : int
        Joints, plant states (4n), controller states.
    sensing : {'state', 'torque', 'full'}
    nm : int
        Measurement size (4n or 5n).
    delay : int
        ``d``: ``m_buf`` holds ``d`` measurements (oldest first), ``u_buf`` ``d`` torques.
    predict : bool
    filtered : bool
        dtau_J as a filtered difference; ``filt = [tau_prev; dtau_filtered]`` (2n), else empty.
    T : float
        Control period, s.
    substeps : int
        RK4 substeps per sample of the plant.
    predict_substeps : int
        RK4 substeps per sample of the predictor (:mod:`fjm_runtime.sim.predictor` chooses them by
        accuracy); 0: the plant's ``substeps`` (:attr:`predictor_substeps` resolves it).
    a_filter : float
        ``1 - exp(-dtau_cutoff T)``.
    q_quant, q_m_quant : float
    differentiated : bool
        Velocities as filtered differences of the measured angles; ``venc = [q_prev; dq; q_m_prev;
        dq_m]`` (4n), else empty.
    a_velocity : float
        ``1 - exp(-velocity_cutoff T)``.
    offset : bool
        A constant tau_J offset per run (torque sensing); ``off`` (n), else empty.
    rate_step : tuple of float
        The largest command change per sample per joint, N m (the interface's ``rate limit x T``);
        empty: no limit.
    interface : {'motor', 'joint_torque'}
        What the law's output commands (:mod:`fjm_runtime.sim.interface`).
    lowpass_alpha : float
        ``joint_torque``: the vendor filter's gain (1.0: none). With a filter or a rate limit
        ``u_last`` (n) holds the last command ``c_{k-1}`` (after filter and limit), else empty.
    current_decay, current_mean : float
        The current loop over one substep ``h``: ``e^{-w_c h}`` and ``(1 - e^{-w_c h}) / (w_c h)``;
        with ``current_decay > 0`` ``cur`` (n) holds the motor torque, else empty (no lag).
    K_T, D_T : tuple of float
        ``joint_torque``: the inner torque loop's gains per joint.
    u_limit : tuple of float
        ``joint_torque``: the motor torque's limit per joint, N m (empty: none).

    integral : bool
        The law's first ``n`` states are the integral of the tracking error (``ismc``, ``adaptive``):
        with a rate limit they are frozen while the limit holds the torque back from where the
        error pushes it (conditional integration, as the law does at its torque limit).
    """

    n: int
    nx: int
    nz: int
    sensing: str
    nm: int
    delay: int
    predict: bool
    filtered: bool
    T: float
    substeps: int
    a_filter: float
    q_quant: float
    q_m_quant: float
    differentiated: bool = False
    a_velocity: float = 0.0
    offset: bool = False
    rate_step: tuple = ()
    integral: bool = False
    predict_substeps: int = 0

    interface: str = "motor"
    lowpass_alpha: float = 1.0
    current_decay: float = 0.0
    current_mean: float = 1.0
    K_T: tuple = ()
    D_T: tuple = ()
    u_limit: tuple = ()

    @property
    def predictor_substeps(self) -> int:
        """RK4 substeps per sample of the predictor: ``predict_substeps``, else the plant's ``substeps``."""
        return int(self.predict_substeps) or int(self.substeps)

    @property
    def n_venc(self) -> int:
        return 4 * self.n if self.differentiated else 0

    @property
    def has_last(self) -> bool:
        """True when ``w`` holds the last command (a rate limit or the vendor's filter acts against it)."""
        return bool(self.rate_step) or self.lowpass_alpha < 1.0

    @property
    def nw(self) -> int:
        return (self.nx + self.nz + self.delay * (self.nm + self.n) + (2 * self.n if self.filtered else 0)
                + self.n_venc + (self.n if self.offset else 0) + (self.n if self.has_last else 0)
                + (self.n if self.current_decay > 0 else 0))

    def slices(self):
        """``(x, z, m_buf, u_buf, filt)`` slices of ``w`` (:meth:`extra_slices` has the rest)."""
        a = self.nx; b = a + self.nz; c = b + self.delay * self.nm; d = c + self.delay * self.n
        e = d + (2 * self.n if self.filtered else 0)
        return slice(0, a), slice(a, b), slice(b, c), slice(c, d), slice(d, e)

    def extra_slices(self):
        """``(venc, off, u_last, cur)`` slices of ``w`` (empty when the feature is off)."""
        d = self.slices()[4].stop
        e = d + self.n_venc
        f = e + (self.n if self.offset else 0)
        g = f + (self.n if self.has_last else 0)
        return slice(d, e), slice(e, f), slice(f, g), slice(g, g + (self.n if self.current_decay > 0 else 0))


def make_layout(model, controller, T: float, substeps: int, sensor: SensorModel, delay: int,
                predict: bool, predict_substeps: Optional[int] = None,
                interface: CommandInterface = None) -> StepLayout:
    """The :class:`StepLayout` of a run (the controller's ``sensing`` decides the measurement).

    ``predict_substeps``: the predictor's RK4 substeps per sample (None: the plant's ``substeps``);
    an integer >= 1, else FjmValueError. ``interface``: the command interface (default
    :meth:`CommandInterface.motor`).
    """
    n = int(model.n)
    sensing = getattr(controller, "sensing", "state")
    if sensing not in ("state", "torque", "full"):
        raise FjmValueError(f"controller.sensing = {sensing!r}: expected 'state', 'torque' or 'full'")
    torque = sensing != "state"  # torque or full: the sensor measures the spring
    predicting = bool(predict and delay > 0)
    if predict_substeps is not None and (isinstance(predict_substeps, bool) or
                                         not isinstance(predict_substeps, (int, np.integer)) or predict_substeps < 1):
        raise FjmValueError(f"predict_substeps = {predict_substeps!r}: expected an integer >= 1 (RK4 substeps per "
                            "sample of the predictor)")
    interface = CommandInterface.motor() if interface is None else interface
    rate = interface.rate_limits(n)
    rate_step = tuple(float(r * T) if np.isfinite(r) else _NO_LIMIT for r in rate) \
        if interface.has_rate_limit() else ()
    return StepLayout(n=n, nx=int(model.nx), nz=int(getattr(controller, "n_states", 0)), sensing=sensing,
                      nm=len(measurement_blocks(sensing)) * n, delay=int(delay), predict=predicting,
                      filtered=torque and sensor.dtau_mode == "filtered", T=float(T), substeps=int(substeps),
                      a_filter=1.0 - math.exp(-sensor.dtau_cutoff * T), q_quant=sensor.q_quant,
                      q_m_quant=sensor.q_m_quant,
                      differentiated=sensor.velocity_mode == "differentiated",
                      a_velocity=1.0 - math.exp(-sensor.velocity_cutoff * T),
                      offset=torque and bool(np.any(sensor.offsets(n) > 0)), rate_step=rate_step,
                      integral=bool(rate_step) and str(_law_kind(controller)).split("_")[0] in INTEGRAL_LAWS
                      and int(getattr(controller, "n_states", 0)) >= n,
                      predict_substeps=int(predict_substeps) if (predicting and predict_substeps) else 0,
                      **_command_fields(model, controller, T, substeps, interface))


def _command_fields(model, controller, T: float, substeps: int, interface: CommandInterface) -> dict:
    """The :class:`StepLayout` fields of the command interface (see its attributes)."""
    n = int(model.n)
    w_h = 2.0 * math.pi * interface.current_bandwidth_hz * T / substeps
    out = {"interface": interface.kind, "lowpass_alpha": float(interface.lowpass_alpha(T)),
           "current_decay": math.exp(-w_h) if math.isfinite(w_h) else 0.0,
           "current_mean": -math.expm1(-w_h) / w_h if math.isfinite(w_h) else 1.0}
    if interface.kind == "joint_torque":
        K_T, D_T = interface.torque_gains(n)
        u_max = next((getattr(o, "u_max") for o in (controller, getattr(controller, "base", None))
                      if getattr(o, "u_max", None) is not None), None)
        limit = np.broadcast_to(np.asarray(u_max, dtype=float), (n,)) if u_max is not None else \
            getattr(model, "effort_limits", None)
        out.update(K_T=tuple(float(v) for v in K_T), D_T=tuple(float(v) for v in D_T),
                   u_limit=() if limit is None else tuple(float(v) if np.isfinite(v) else _NO_LIMIT for v in limit))
    return out


#: Laws whose first ``n`` controller states integrate the tracking error (``e1 = q - q_d``; the impedance
#: law's ``q_d - q``) and are frozen where the torque is held back (their torque-sensed forms too: ``ismc_tau``).
INTEGRAL_LAWS = ("ismc", "adaptive", "impedance")


def _law_kind(controller):
    """The emitted law's kind (``None`` for a controller that names none)."""
    for obj in (controller, getattr(controller, "base", None)):
        kind = getattr(obj, "law_kind", None)
        if kind is not None:
            return kind
    return None
