"""How finely the predictor integrates: the fewest RK4 substeps within a stated error bound.

The sampled loop's predictor (:func:`fjm_runtime.sim.sample_step.predicted_measurement`) integrates
the controller's NOMINAL model over the delay, ``d`` samples of ``T``, from the delayed measurement
under the torques already sent. The plant's substeps rule (:mod:`fjm_runtime.sim.substeps`) makes
the plant's integration exact to 1e-8 rad over 10 s from any state; the predictor only has to agree
with an exact prediction far below the noise of the measurement it stands for. The choice::

    reference  = the prediction on REFERENCE_SUBSTEPS (64) RK4 substeps per sample
    tolerance  = max(NOISE_FRACTION sigma, FLOOR) per measurement slot
                 (sigma: the noise std of the slot as the controller reads it,
                 :func:`fjm_runtime.sim.sensor.read_noise_levels`: a differentiated velocity or a
                 filtered dtau_J carries the filtered difference of its source's noise; 1e-3 of it;
                 FLOOR 1e-9 in the slot's SI unit, e.g. rad, when the sensor is noise-free)
    substeps   = the smallest s in 1..64 whose prediction differs from the reference by at most the
                 tolerance in every slot from every start: each task point's exact measurement and the
                 same with one draw of the sensor's noise (the noise excites the fast elastic modes)

Task points (:func:`task_points`): the task's start state (at rest, the torque holding it) and
:data:`TASK_POINTS` instants of the task over :data:`TASK_SECONDS`, each the nominal model's state
on the reference with the torques that keep it there, its flatness feedforward ``[q_d; dq_d;
theta_d; dtheta_d]`` and ``u_ff`` (models without a feedforward: the start state alone).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..validation import FjmValueError
from .sample_step import initial_measurement, predicted_measurement
from .sensor import SensorModel, read_noise_levels
from .step_layout import StepLayout, controller_model, make_layout

__all__ = ["FLOOR", "NOISE_FRACTION", "NOISE_SEED", "REFERENCE_SUBSTEPS", "TASK_POINTS", "TASK_SECONDS",
           "choose_predict_substeps",
           "loop_predict_substeps", "prediction_tolerance", "task_points"]

#: Substeps per sample of the reference prediction (and the most the choice returns).
REFERENCE_SUBSTEPS = 64
#: The bound, as a fraction of the sensor's noise level of each measurement slot.
NOISE_FRACTION = 1e-3
#: The bound of a slot whose signal has no noise (SI units of the slot: rad, rad/s, N m, N m/s).
FLOOR = 1e-9
#: Instants of the task checked (besides its start state), evenly over :data:`TASK_SECONDS`.
TASK_POINTS = 20
#: Seed of the noise added to each task point's measurement.
NOISE_SEED = 0
#: Length of the task checked, s (the design's final-check runs are 10 s).
TASK_SECONDS = 10.0


def prediction_tolerance(sensor: SensorModel, sensing: str, n: int, T: float) -> np.ndarray:
    """The bound on each slot of the predicted measurement: ``max(NOISE_FRACTION sigma, FLOOR)``, shape (nm,).

    ``sigma`` is the noise std of the slot as the controller reads it at the sample period ``T``
    (:func:`fjm_runtime.sim.sensor.read_noise_levels`): a velocity the loop differentiates from a noisy
    encoder is that noisy, not noise-free, so it is held to the same fraction of its noise as a measured one.
    """
    return np.maximum(NOISE_FRACTION * read_noise_levels(sensor, sensing, n, T), FLOOR)


def _holding_torque(model, x, p) -> np.ndarray:
    """The motor torque that keeps the motors' acceleration at zero at ``x`` (least squares on ``g``'s motor rows)."""
    n, nx = int(model.n), int(model.nx)
    f = np.asarray(model.f(x, p), dtype=float).reshape(nx)
    g = np.asarray(model.g(x, p), dtype=float).reshape(nx, n)
    return np.linalg.lstsq(g[3 * n:], -f[3 * n:], rcond=None)[0]


def task_points(model, reference, x0, p_nom, T: float, delay: int):
    """``(X, U)``: states (N, nx) the predictor starts from and the torques (N, delay n) it is fed.

    Row 0 is ``x0`` under the torque holding it; rows 1.. the feedforward's states at
    :data:`TASK_POINTS` instants of ``reference`` (a callable ``t -> (5, n)`` rows) and its
    ``u_ff`` at the ``delay`` sample instants from there (the feedforward of a reduced model;
    a model without one gives row 0 alone).
    """
    n, p_nom = int(model.n), np.asarray(p_nom, dtype=float)
    x0 = np.asarray(x0, dtype=float)
    X, U = [x0], [np.tile(_holding_torque(model, x0, p_nom), int(delay))]
    try:
        model.feedforward_function
    except FjmValueError:
        return np.array(X), np.array(U)
    for t in np.linspace(0.0, TASK_SECONDS, TASK_POINTS + 1)[1:]:
        _, theta, dtheta, _, _ = model.feedforward(reference(t), p_nom)
        rows = np.asarray(reference(t), dtype=float).reshape(5, n)
        X.append(np.concatenate([rows[0], rows[1], theta, dtheta]))
        U.append(np.concatenate([model.feedforward(reference(t + j * T), p_nom)[4] for j in range(int(delay))]))
    return np.array(X), np.array(U)


def _starts(model, L: StepLayout, p_nom, X, sensor: SensorModel) -> np.ndarray:
    """The measurements the predictor starts from, shape (2N, nm): each task state's exact measurement, then
    each one with one draw of the sensor's noise (seed 0; the noise excites the fast elastic modes, which
    the task alone leaves at rest)."""
    exact = np.array([initial_measurement(model, L, x, p_nom) for x in X])
    normals = np.random.default_rng(NOISE_SEED).standard_normal(exact.shape)
    return np.vstack([exact, exact + sensor.levels(L.sensing, L.n) * normals])


def _predictions(model, L: StepLayout, p_nom, M, U, substeps: int) -> np.ndarray:
    """The prediction from every start ``M`` (2N, nm) under its torques (``U`` of the N task points,
    repeated) on ``substeps`` predictor substeps, shape (2N, nm)."""
    Ls = replace(L, predict_substeps=int(substeps))
    U = np.vstack([U, U])
    return np.array([predicted_measurement(model, Ls, m, u, p_nom) for m, u in zip(M, U)])


def choose_predict_substeps(model, L: StepLayout, p_nom, X, U, sensor: SensorModel) -> int:
    """The smallest substeps in ``1..REFERENCE_SUBSTEPS`` whose prediction is within
    :func:`prediction_tolerance` of the reference in every slot from every start (module docstring).

    ``model``: the controller's (nominal) model; ``L``: a predicting layout of it; ``(X, U)``: :func:`task_points`.
    """
    if not (L.predict and L.delay > 0):
        raise FjmValueError("predict_substeps: the loop does not predict (predict off or delay 0); expected a "
                            "predicting loop")
    M = _starts(model, L, p_nom, X, sensor)
    ref = _predictions(model, L, p_nom, M, U, REFERENCE_SUBSTEPS)
    tol = prediction_tolerance(sensor, L.sensing, L.n, L.T)
    for s in range(1, REFERENCE_SUBSTEPS):
        if np.all(np.abs(_predictions(model, L, p_nom, M, U, s) - ref) <= tol):
            return s
    return REFERENCE_SUBSTEPS


def loop_predict_substeps(model, controller, sensor: SensorModel, T: float, delay: int, reference, x0) -> int:
    """The predictor substeps of a design's loop (module docstring): the controller's nominal model and
    parameters, the sensor's bound, the task ``reference`` started from ``x0``."""
    nominal = controller_model(controller, model)
    p_nom = np.asarray(controller.p_nom, dtype=float)
    L = make_layout(nominal, controller, float(T), 1, sensor, int(delay), True)
    X, U = task_points(nominal, reference, x0, p_nom, float(T), int(delay))
    return choose_predict_substeps(nominal, L, p_nom, X, U, sensor)
