"""Every default gain of the controllers, in one place.

The boundary layer: wherever a tool (the ``fjm`` command line, the experiments, the
benchmarks) picks ``delta`` for a switching gain ``k_s`` it uses one rule,
:func:`default_delta`: ``delta = max(k_s, 1) / DEFAULT_LAYER_RATE``, so the linear slope
of ``sat(s / delta)`` inside the layer is ``k_s / delta = 200`` 1/s, well inside what a
1 ms zero-order hold tolerates (``k_s`` below 1 rad/s^4 gets the layer of ``k_s = 1`` so
that it never collapses to zero). A controller built directly without ``delta`` uses
the fixed width :data:`DEFAULT_DELTA`.

The tracking laws' pole :data:`DEFAULT_LAM`, the switching gain :data:`DEFAULT_SWITCHING_GAIN` and the
paper's stiffness range :data:`PAPER_K_RANGE` are the ones every command-line default, experiment,
benchmark and example starts from.

The adaptive stiffness estimator: regressor filter bandwidth :data:`DEFAULT_FILTER_RATE`,
initial covariance :data:`DEFAULT_LS_GAIN`, stiffness bounds :func:`default_K_bounds`.

:mod:`fjm_runtime.control.factory` re-exports these names next to ``make_controller``.
"""
from __future__ import annotations

import numpy as np

__all__ = ["DEFAULT_DELTA", "DEFAULT_FILTER_RATE", "DEFAULT_LAM", "DEFAULT_LAYER_RATE", "DEFAULT_LS_GAIN",
           "DEFAULT_SWITCHING_GAIN", "PAPER_K_RANGE", "PANDA_ISMC_TAU_START", "default_K_bounds", "default_delta"]

#: Pole magnitude ``lambda`` of the tracking laws when none is given, 1/s (the paper's link1 value).
DEFAULT_LAM = 8.0

#: Switching gain ``k_s`` when neither the caller nor the Lemma 1 bound gives one, rad/s^4.
DEFAULT_SWITCHING_GAIN = 1000.0

#: The paper's range of the TRUE joint stiffness, N m/rad (nominal 150): Lemma 1's default box, the
#: sweeps' absolute range, the adaptive estimator's projection in the experiments.
PAPER_K_RANGE = (100.0, 200.0)

#: Slope ``k_s / delta`` of the boundary layer, 1/s (see :func:`default_delta`).
DEFAULT_LAYER_RATE = 200.0

#: Boundary-layer width of a controller constructed without ``delta`` (rad/s^3).
DEFAULT_DELTA = 0.1

#: Bandwidth ``a`` of the adaptive regressor filter ``a / (s + a)``, 1/s.
DEFAULT_FILTER_RATE = 20.0

#: Initial least-squares covariance ``P(0)`` of the adaptive estimator, 1/(rad^2 s).
DEFAULT_LS_GAIN = 1e5

#: A STARTING POINT for the torque-sensed integral law on the Panda at 1 kHz
#: (``make_controller('ismc', panda, nominal, sensing='torque', **PANDA_ISMC_TAU_START)``):
#: quadruple pole at 80 1/s, ``k_lin`` 400 1/s, ``k_s`` 2000 rad/s^4, ``delta`` 10. Found by hand,
#: not by a search: the window around it is narrow and a computation delay or sensor noise
#: moves it; do not read it as tuned or certified gains.
PANDA_ISMC_TAU_START = {"lam": 80.0, "k_lin": 400.0, "k_s": 2000.0, "delta": 10.0}


def default_delta(k_s, layer_rate: float = DEFAULT_LAYER_RATE):
    """Boundary-layer width for the switching gain ``k_s``: ``max(k_s, 1) / layer_rate``.

    Parameters
    ----------
    k_s : float or array_like, shape (n,)
        Switching gain, rad/s^4, >= 0.
    layer_rate : float
        Slope ``k_s / delta`` of the layer, 1/s (default :data:`DEFAULT_LAYER_RATE`).

    Returns
    -------
    float or ndarray, shape (n,)
        ``delta`` in rad/s^3 (a float for a scalar ``k_s``).
    """
    if np.ndim(k_s) == 0:
        return max(float(k_s), 1.0) / layer_rate
    return np.maximum(np.asarray(k_s, dtype=float), 1.0) / layer_rate


def default_K_bounds(K_nom):
    """Stiffness bounds of the adaptive estimator: ``(2/3, 4/3)`` of the nominal stiffness.

    Parameters
    ----------
    K_nom : float or ndarray, shape (n,)
        Nominal joint stiffness, N m/rad.

    Returns
    -------
    (K_min, K_max) : float or ndarray, shape (n,)
        e.g. ``(100, 200)`` at ``K_nom = 150``.
    """
    return K_nom * 2.0 / 3.0, K_nom * 4.0 / 3.0
