"""Controllers by name, and the default gains (:mod:`fjm_runtime.control.defaults`).

>>> import fjm_runtime
>>> from fjm_runtime.control.factory import make_controller, default_delta
>>> m = fjm_runtime.load("link1")
>>> ctrl = make_controller("smc", m, {}, lam=8.0, k_s=1000.0, delta=default_delta(1000.0))
>>> float(ctrl.delta[0])
5.0
"""
from __future__ import annotations

from .adaptive import make_adaptive
from .defaults import (DEFAULT_DELTA, DEFAULT_FILTER_RATE, DEFAULT_LAYER_RATE, DEFAULT_LS_GAIN,  # noqa: F401
                       default_delta, default_K_bounds)
from .laws import SlidingModeController
from .pdg import MotorPDGravityController
from .sensing import SENSING_KINDS, torque_measurement, torque_measurement_symbolic  # noqa: F401

__all__ = ["CONTROLLER_KINDS", "REGULATION_KINDS", "SENSING_KINDS", "TORQUE_SENSED_KINDS", "DEFAULT_DELTA",
           "DEFAULT_FILTER_RATE", "DEFAULT_LAYER_RATE", "DEFAULT_LS_GAIN", "default_K_bounds", "default_delta",
           "make_controller", "torque_measurement", "torque_measurement_symbolic"]

#: The names :func:`make_controller` accepts.
CONTROLLER_KINDS = ("smc", "ismc", "fl", "sign", "adaptive")

#: Regulation laws (set point ``r[0]`` only), also accepted by :func:`make_controller`.
REGULATION_KINDS = ("pdg",)

#: The kinds that accept ``sensing='torque'`` (emitted as ``control_<kind>_tau``).
TORQUE_SENSED_KINDS = ("smc", "ismc", "fl")


def make_controller(kind: str, model, nominal_params, sensing: str = "state", **kwargs) -> SlidingModeController:
    """Build a controller by name.

    Parameters
    ----------
    kind : {'smc', 'ismc', 'fl', 'sign', 'adaptive', 'pdg'}
        ``'smc'``: paper's surface with ``sat``; ``'sign'``: the paper's
        discontinuous law; ``'ismc'``: integral surface with ``sat``; ``'fl'``:
        plain feedback linearization (no switching term, quadruple pole);
        ``'adaptive'``: online stiffness estimate in ``T``, ``alpha``, ``beta``
        (:class:`fjm_runtime.control.adaptive.AdaptiveStiffnessController`; keywords
        ``K_bounds``, ``filter_rate``, ``ls_gain``, ``integral``); ``'pdg'``: motor PD +
        gravity compensation for regulation
        (:class:`fjm_runtime.control.pdg.MotorPDGravityController`; keywords ``k_p``,
        ``k_d``, ``u_max``).
    model, nominal_params, **kwargs
        Passed to :class:`~fjm_runtime.control.laws.SlidingModeController`
        (gains not given take the defaults of :mod:`fjm_runtime.control.defaults`).
    sensing : {'state', 'torque'}
        ``'state'``: the controller reads the plant state ``x`` (4n). ``'torque'`` (smc,
        ismc, fl): it reads the torque-sensed measurement ``m = [q; dq; tau_J; dtau_J; dq_m]``
        (5n, :func:`~fjm_runtime.control.sensing.torque_measurement`) and runs the emitted
        ``control_<kind>_tau``. Either way ``controller.sensing`` and
        ``controller.measurement_size`` say which, and every method takes that measurement.

    Returns
    -------
    SlidingModeController
    """
    if sensing not in SENSING_KINDS:
        raise ValueError(f"sensing = {sensing!r}: expected one of {', '.join(SENSING_KINDS)}")
    if sensing == "torque" and kind not in TORQUE_SENSED_KINDS:
        raise ValueError(f"controller = {kind!r} with sensing = 'torque': torque-sensed laws exist for "
                         f"{', '.join(TORQUE_SENSED_KINDS)} (use sensing = 'state')")
    if kind == "pdg":
        return MotorPDGravityController(model, nominal_params, **kwargs)
    if sensing == "torque":
        kwargs["sensing"] = "torque"
    return _make_state_law(kind, model, nominal_params, **kwargs)


def _make_state_law(kind: str, model, nominal_params, **kwargs) -> SlidingModeController:
    """The controllers of :data:`CONTROLLER_KINDS` (``sensing`` already in ``kwargs`` when torque)."""
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
        return make_adaptive(model, nominal_params, **kwargs)
    raise ValueError(f"controller = {kind!r}: expected one of {', '.join(CONTROLLER_KINDS + REGULATION_KINDS)}")
