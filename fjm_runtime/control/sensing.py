"""What a controller measures: the plant state, or the torque-sensed measurement.

A controller built with ``sensing='state'`` reads the plant state
``x = [q; dq; q_m; dq_m]`` (4n). One built with ``sensing='torque'`` reads what a
torque-sensed arm reports (link position and rate, the link-side joint torque and its
rate, the motor rate)::

    m = [q; dq; tau_J; dtau_J; dq_m]   (5n),   tau_J = K (q_m - q),  dtau_J = K (dq_m - dq)

with the TRUE stiffness ``K`` of the plant (the sensor measures the real spring).
:func:`torque_measurement` builds ``m`` from a plant state for the simulators (NumPy);
:func:`torque_measurement_symbolic` is its CasADi twin for the fused, compiled and batch
paths. Sensor noise, delay and filtering are the simulator's business, applied to ``m``.

>>> import numpy as np
>>> torque_measurement(np.array([0.1, 0.0, 0.3, 2.0]), np.array([100.0])).tolist()
[0.1, 0.0, 20.0, 200.0, 2.0]
"""
from __future__ import annotations

import numpy as np

from ..validation import FjmValueError

__all__ = ["SENSING_KINDS", "measurement_size", "torque_measurement", "torque_measurement_symbolic"]

#: The ``sensing`` values a controller accepts: ``'full'`` is everything a torque-sensed arm reports,
#: ``[q; dq; q_m; dq_m; tau_J; dtau_J]`` (6n, the signals of :data:`fjm_runtime.sim.sensor.SIGNALS` in order;
#: the motor-side impedance law reads it).
SENSING_KINDS = ("state", "torque", "full")


def measurement_size(sensing: str, n: int) -> int:
    """Length of what a controller with ``sensing`` reads: ``4n`` ('state'), ``5n`` ('torque'), ``6n`` ('full')."""
    if sensing not in SENSING_KINDS:
        raise FjmValueError(f"sensing = {sensing!r}: expected one of {', '.join(SENSING_KINDS)}")
    return {"state": 4, "torque": 5, "full": 6}[sensing] * n


def _stiffness(K, n: int) -> np.ndarray:
    k = np.asarray(K, dtype=float)
    if k.ndim == 0:
        k = np.full(n, float(k))
    if k.shape != (n,) or not np.all(np.isfinite(k)) or np.any(k <= 0):
        raise FjmValueError(f"K with shape {k.shape}: expected {n} finite stiffnesses > 0 (N m/rad), "
                            "one per joint, or one scalar")
    return k


def torque_measurement(x, K) -> np.ndarray:
    """The torque-sensed measurement of plant state(s) ``x`` under the TRUE stiffness ``K``.

    Parameters
    ----------
    x : array_like, shape (4n,) or (N, 4n)
        Plant state(s) ``[q; dq; q_m; dq_m]``.
    K : float or array_like, shape (n,)
        True joint stiffness per joint, N m/rad, > 0.

    Returns
    -------
    ndarray, shape (5n,) or (N, 5n)
        ``[q; dq; K (q_m - q); K (dq_m - dq); dq_m]``.
    """
    xa = np.asarray(x, dtype=float)
    if xa.ndim not in (1, 2) or xa.shape[-1] % 4 != 0 or xa.shape[-1] == 0:
        raise FjmValueError(f"x with shape {xa.shape}: expected (4n,) or (N, 4n) plant states "
                            "[q; dq; q_m; dq_m]")
    n = xa.shape[-1] // 4
    k = _stiffness(K, n)
    q, dq, qm, dqm = (xa[..., i * n:(i + 1) * n] for i in range(4))
    return np.concatenate([q, dq, k * (qm - q), k * (dqm - dq), dqm], axis=-1)


def torque_measurement_symbolic(x, K):
    """CasADi twin of :func:`torque_measurement` for one state.

    Parameters
    ----------
    x : casadi SX/MX, shape (4n, 1)
    K : casadi SX/MX or array_like, shape (n, 1)
        True stiffness (symbolic, e.g. taken from the plant's parameter vector, or numbers).

    Returns
    -------
    casadi SX/MX, shape (5n, 1)
    """
    import casadi as ca
    nx = int(x.shape[0])
    if nx % 4 != 0 or nx == 0:
        raise FjmValueError(f"x with {nx} rows: expected 4n rows [q; dq; q_m; dq_m]")
    n = nx // 4
    if not isinstance(K, (ca.SX, ca.MX, ca.DM)):
        K = ca.DM(_stiffness(K, n))
    q, dq, qm, dqm = (x[i * n:(i + 1) * n] for i in range(4))
    return ca.vertcat(q, dq, K * (qm - q), K * (dqm - dq), dqm)
