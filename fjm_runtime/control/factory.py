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

__all__ = ["CONTROLLER_KINDS", "DEFAULT_DELTA", "DEFAULT_FILTER_RATE", "DEFAULT_LAYER_RATE", "DEFAULT_LS_GAIN",
           "default_K_bounds", "default_delta", "make_controller"]

#: The names :func:`make_controller` accepts.
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
        (:class:`fjm_runtime.control.adaptive.AdaptiveStiffnessController`; keywords
        ``K_bounds``, ``filter_rate``, ``ls_gain``, ``integral``).
    model, nominal_params, **kwargs
        Passed to :class:`~fjm_runtime.control.laws.SlidingModeController`
        (gains not given take the defaults of :mod:`fjm_runtime.control.defaults`).

    Returns
    -------
    SlidingModeController
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
        return make_adaptive(model, nominal_params, **kwargs)
    raise ValueError(f"controller = {kind!r}: expected one of {', '.join(CONTROLLER_KINDS)}")
