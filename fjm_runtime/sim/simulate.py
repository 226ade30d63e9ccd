"""Closed-loop simulation, sampled-data: TRUE plant on RK4 substeps, digital controller with NOMINAL parameters.

The controller samples at ``1/dt``: at ``t_k = k dt`` it reads the measurement (with the
sensor model's noise, quantization and a computation delay of ``delay_samples``), computes
the torque, which is held over ``[t_k, t_{k+1})`` (zero-order hold), and advances its own
state once per sample (``z_{k+1} = z_k + dt z_dot_k``). The plant integrates over the sample
on ``substeps`` classical RK4 steps (default: :mod:`fjm_runtime.sim.substeps`). The sample
step is one definition (:mod:`fjm_runtime.sim.sample_step`) for every backend.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, field as dc_field
from typing import Callable, Optional

import numpy as np

from ..sim.interface import interface_from_spec
from ..sim.loops import BACKENDS
from ..sim.metrics import Metrics, compute_metrics
from ..sim.plot import DPI
from ..sim.sample_step import check_loop_settings, initial_measurement, initial_step_state
from ..sim.sensor import SensorModel, noise_array
from ..sim.step import casadi_functions
from ..sim.step_layout import make_layout
from ..sim.substeps import resolve_substeps
from ..validation import FjmValueError

__all__ = ["SimulationResult", "simulate", "stderr_progress"]


@dataclass
class SimulationResult:
    """Trajectories and metrics of one closed-loop run (``N + 1`` samples, ``n`` joints).

    Attributes
    ----------
    t : ndarray, shape (N+1,)
    x : ndarray, shape (N+1, 4n)
        Plant state ``[q_l; dq_l; q_m; dq_m]``.
    z : ndarray, shape (N+1, n_states)
        Controller state.
    u : ndarray, shape (N+1, n)
        Applied torque held over ``[t_k, t_k + dt)`` (the last row is the law at ``t_end``).
    y : ndarray, shape (N+1, 4, n)
        True linearizing coordinates ``T(x; p_true)`` (link angle, velocity,
        acceleration, jerk).
    y_hat : ndarray, shape (N+1, 4, n)
        The controller's estimate ``T(x; p_nom)``.
    ref : ndarray, shape (N+1, 5, n)
        Reference and its derivatives.
    s : ndarray, shape (N+1, n)
        Sliding variable as computed by the controller.
    e1 : ndarray, shape (N+1, n)
        Link-position error ``q_l - q_d`` (rad).
    delta : ndarray, shape (n,)
        Boundary-layer width used for the reaching time.
    metrics : Metrics
    u_max : ndarray, shape (n,) or None
        The controller's torque limit (for :func:`fjm_runtime.sim.metrics.time_at_limit`).
    settings : dict
        ``rate`` (Hz), ``dt``, ``substeps``, ``delay_samples``, ``predict``, ``sensing``, ``seed``.
    """

    t: np.ndarray
    x: np.ndarray
    z: np.ndarray
    u: np.ndarray
    y: np.ndarray
    y_hat: np.ndarray
    ref: np.ndarray
    s: np.ndarray
    e1: np.ndarray
    delta: np.ndarray
    metrics: Metrics
    u_max: Optional[np.ndarray] = None
    settings: dict = dc_field(default_factory=dict)

    def plot(self, path=None, title: str = "", dpi: int = DPI):
        """Angles, error, torque and sliding variable of this run (:func:`fjm_runtime.sim.plot.plot_run`).

        Parameters
        ----------
        path : path-like, optional
            Where to write the figure (a PNG, PDF, ... by its suffix) at ``dpi`` dots per inch.
        title : str
            The figure's title.
        dpi : int
            Resolution of the written file.

        Returns
        -------
        matplotlib.figure.Figure
            The 2 x 2 figure (still open: ``matplotlib.pyplot.close(fig)`` when done).

        Raises
        ------
        FjmValueError
            matplotlib is not installed (it is imported here, not with the runtime).
        """
        from .plot import plot_run
        return plot_run(self, title, path, dpi)


def _true_params_array(model, true_params) -> np.ndarray:
    p = {} if true_params is None else true_params
    try:
        return np.asarray(model.params_array(p, arg="true_params"), dtype=float)
    except TypeError:  # a model whose params_array has no ``arg`` keyword
        try:
            return np.asarray(model.params_array(p), dtype=float)
        except ValueError as exc:
            raise ValueError(f"true_params: {exc}") from exc


def _check_state(x, nx, field):
    a = np.asarray(x, dtype=float)
    if a.shape != (nx,):
        raise ValueError(f"{field} with shape {a.shape}: expected ({nx},) = [q_l; dq_l; q_m; dq_m]")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{field} = {a.tolist()}: expected finite values")
    return a


def simulate(model, controller, reference, *, duration: float, dt: float = 1e-3,
             true_params=None, x0=None, progress: Optional[Callable[[float], None]] = None,
             max_state: float = 1e6, backend: str = "auto", substeps: Optional[int] = None,
             sensor: Optional[SensorModel] = None, delay_samples: int = 0,
             predict: bool = False, loop: str = "sampled",
             predict_substeps: Optional[int] = None, interface=None) -> SimulationResult:
    """Simulate the sampled-data closed loop: TRUE plant, controller with its NOMINAL model.

    Parameters
    ----------
    model : Model
        ``fjm_runtime.load(name)``.
    controller : SlidingModeController
        Holds its own nominal parameters (see :mod:`fjm_runtime.control.laws`); its
        ``sensing`` (``'state'``, the default, or ``'torque'``) decides what it measures.
    reference : Reference
        ``reference(t) -> (5, n)``.
    duration : float
        Simulated time in s, > 0.
    dt : float
        Control sample time ``T`` in s, > 0 (default 1 ms): the torque is held over a sample.
    true_params : dict or array_like, optional
        Plant parameters (default: model defaults).
    x0 : array_like, shape (4n,), optional
        Initial state; default: at rest with ``q_l = q_m = q_d(0)``.
    progress : callable, optional
        Called as ``progress(fraction)`` about 20 times during the run.
    max_state : float
        ``|x|`` beyond this counts as divergence.
    backend : {'auto', 'casadi', 'compiled', 'python'}
        ``'python'``: a plain loop through ``model.f``, ``model.g`` and the controller's
        ``evaluate`` (any controller object). ``'casadi'``: the CasADi sample step folded by
        ``mapaccum`` (needs the controller's ``symbolic_evaluate``); ``'auto'`` picks it when
        possible. ``'compiled'``: the same step in C, compiled once and cached. All give the
        same trajectories to rounding.
    substeps : int, optional
        RK4 steps of the plant per sample (default: the rule of :mod:`fjm_runtime.sim.substeps`;
        a coarser forced value warns with :class:`CoarseIntegrationWarning`).
    sensor : SensorModel, optional
        Noise, quantization and the dtau_J mode (default :meth:`SensorModel.ideal`).
    delay_samples : int
        Computation delay ``d`` >= 0: the law at ``t_k`` sees the measurement of ``t_{k-d}``.
    predict : bool
        With ``d > 0``: predict the measurement ``d`` samples ahead with the NOMINAL model
        under the torques already sent (see :mod:`fjm_runtime.sim.sample_step`).
    interface : CommandInterface or str, optional
        The command interface (:mod:`fjm_runtime.sim.interface`; default ``'motor'``), or a TOML file.
    loop : {'sampled'}
        The one loop (any other name raises :class:`FjmValueError`).
    predict_substeps : int, optional
        RK4 substeps per sample of the predictor (default: the plant's ``substeps``; a design's
        recorded choice, :mod:`fjm_runtime.sim.predictor`).

    Returns
    -------
    SimulationResult

    Raises
    ------
    ValueError
        Bad durations, steps, shapes, parameters or settings (the message names the field).
    SimulationDivergedError
        The state became non-finite or exceeded ``max_state``; ``.t`` is the time.
    """
    p_true, x, n_steps = _initial_conditions(model, controller, reference, duration, dt, true_params, x0)
    sensor, delay = check_loop_settings(sensor, delay_samples, predict, loop)
    subs = resolve_substeps(substeps, model, x, p_true, float(dt))
    iface = interface_from_spec(interface, what="interface")
    L = make_layout(model, controller, float(dt), subs, sensor, delay, predict, predict_substeps, interface=iface)
    t = dt * np.arange(n_steps + 1)
    r0 = np.asarray(reference(0.0), dtype=float)
    z = np.asarray(controller.initial_state(0.0, initial_measurement(model, L, x, p_true), r0), dtype=float)
    w0 = initial_step_state(model, L, x, z, p_true, seed=int(sensor.seed), sensor=sensor, controller=controller)
    R = _reference_rows(reference, t, L.n)
    NOISE = noise_array(sensor, L.sensing, L.n, t.size)
    name = _choose_backend(backend, model, controller)
    W, AUX = BACKENDS[name](model, controller, L, p_true, w0, t, R, NOISE, progress, max_state)
    return _finish(model, controller, p_true, L, t, W, AUX, R.reshape(-1, 5, L.n),
                   _run_settings(L, dt, predict, sensor, iface, name))


def _run_settings(L, dt, predict, sensor, iface, backend) -> dict:
    """:attr:`SimulationResult.settings` of a run."""
    return {"rate": 1.0 / float(dt), "dt": float(dt), "substeps": L.substeps, "delay_samples": L.delay,
            "predict": bool(predict), "predict_substeps": L.predictor_substeps if L.predict else None,
            "sensing": L.sensing, "seed": int(sensor.seed), "backend": backend,
            "sensor": sensor.name, "interface": iface.name, "torque_rate_limit": iface.as_dict()["torque_rate_limit"]}


def _reference_rows(reference, t, n):
    """The reference at every sample time, shape (N+1, 5n)."""
    if hasattr(reference, "sample"):
        return np.asarray(reference.sample(t), dtype=float).reshape(t.size, 5 * n)
    return np.stack([np.asarray(reference(tk), dtype=float).reshape(5 * n) for tk in t])


def _initial_conditions(model, controller, reference, duration, dt, true_params, x0):
    """Check the run's arguments; ``(p_true, x0, n_steps)`` (x0 default: at rest on the reference)."""
    n, nx = int(model.n), int(model.nx)
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"duration = {duration!r}: expected a finite value > 0 s")
    if not (np.isfinite(dt) and 0 < dt <= duration):
        raise ValueError(f"dt = {dt!r}: expected a finite step with 0 < dt <= duration")
    if getattr(reference, "n", n) != n:
        raise ValueError(f"reference.n = {reference.n}: expected {n} joints for this model")
    if getattr(controller, "n", n) != n:
        raise ValueError(f"controller.n = {controller.n}: expected {n} joints for this model")
    p_true = _true_params_array(model, true_params)
    if not np.all(np.isfinite(p_true)):
        raise ValueError(f"true_params = {p_true.tolist()}: expected finite values")
    r0 = np.asarray(reference(0.0), dtype=float)
    if r0.shape != (5, n):
        raise ValueError(f"reference(0) with shape {r0.shape}: expected (5, {n})")
    if x0 is None:
        x0 = np.zeros(nx)
        x0[0:n] = r0[0]
        x0[2 * n:3 * n] = r0[0]
    x = _check_state(x0, nx, "x0")
    return p_true, x, int(round(duration / dt))


def _choose_backend(backend: str, model, controller) -> str:
    """The key of :data:`BACKENDS` that runs ``backend`` (``'auto'``: casadi when possible)."""
    if backend not in ("auto",) + tuple(BACKENDS):
        raise ValueError(f"backend = {backend!r}: expected 'auto', 'casadi', 'compiled' or 'python'")
    if backend in ("compiled", "python"):
        return backend
    fused_ok = casadi_functions(model) is not None and hasattr(controller, "symbolic_evaluate")
    if backend == "casadi" and not fused_ok:
        raise ValueError("backend = 'casadi': the model exposes no CasADi Functions or the controller "
                         "has no symbolic_evaluate; use backend='python'")
    return "casadi" if fused_ok else "python"


def _finish(model, controller, p_true, L, t, W, AUX, R, settings) -> SimulationResult:
    n = L.n
    sx, sz = L.slices()[:2]
    X, Z = W[:, sx], W[:, sz]
    U, S, Yh = AUX[:, :n], AUX[:, n:2 * n], AUX[:, 2 * n:].reshape(-1, 4, n)
    Y = _true_outputs(model, p_true, X)
    e1 = X[:, :n] - R[:, 0]
    delta = np.asarray(getattr(controller, "delta", np.full(n, np.inf)), dtype=float)
    metrics = compute_metrics(t, e1, U, S, delta)
    u_max = getattr(controller, "u_max", None)
    return SimulationResult(t=t, x=X, z=Z, u=U, y=Y, y_hat=Yh, ref=R, s=S, e1=e1, delta=delta, metrics=metrics,
                            u_max=None if u_max is None else np.asarray(u_max, dtype=float), settings=settings)


_MAPPED: dict = {}


def _mapped(fn, count: int):
    """``fn.map(count)``, built once per (function, count): building it costs ~10 ms a call."""
    key = (id(fn), int(count))
    hit = _MAPPED.get(key)
    if hit is None or hit[0] is not fn:
        if len(_MAPPED) > 64:
            _MAPPED.clear()
        hit = _MAPPED[key] = (fn, fn.map(int(count)))
    return hit[1]


def _true_outputs(model, p_true, X):
    """``T(x; p_true)`` for every row of ``X``, shape (N+1, 4, n)."""
    n = int(model.n)
    fns = casadi_functions(model)
    if fns is not None:
        T_all = _mapped(fns["T"], X.shape[0])
        return np.asarray(T_all(X.T, p_true)).T.reshape(-1, 4, n)
    return np.stack([np.asarray(model.T(xk, p_true), dtype=float).reshape(4, n) for xk in X])


def stderr_progress(label: str) -> Callable[[float], None]:
    """A ``progress`` callback printing ``label: NN %`` to stderr."""
    def report(fraction: float) -> None:
        print(f"\r{label}: {100 * fraction:3.0f} %", end="\n" if fraction >= 1 else "",
              file=sys.stderr, flush=True)
    return report
