"""The sampled-data batch: inputs of the compiled fold, the runner choice, per-run metrics.

:func:`run_sampled_batch` is the body of :func:`fjm_runtime.batch.runner.simulate_batch`
(``loop='sampled'``): it builds the step of :mod:`fjm_runtime.batch.sampled` once per (model,
controller structure, layout) (compiled and cached by source hash, :mod:`fjm_runtime.ccache`),
fills one accumulator row per run (initial step state, zero sums, TRUE parameters) and turns the
final accumulators into the figures of :mod:`fjm_runtime.sim.metrics`.
"""
from __future__ import annotations

import numpy as np

from ..ccache import DEFAULT_FLAGS
from ..control.impedance import ImpedanceController, JointImpedanceController
from ..control.laws import SlidingModeController
from ..sim.metrics import metrics_from_sums
from ..sim.interface import interface_from_spec
from ..sim.sample_step import check_loop_settings, initial_measurement, initial_step_state
from ..sim.step_layout import make_layout
from ..sim.sensor import SensorModel, noise_slots
from ..sim.substeps import resolve_substeps
from ..validation import FjmValueError
from . import simd
from .sampled import GainInput, jitter_half_width, sampled_metric_step
from .scalar import sampled_scalar_runner

__all__ = ["JOINT_METRICS", "batch_seeds", "build_sampled_runner", "run_sampled_batch"]

#: Per-joint figures of :attr:`BatchResult.joint_metrics` (the ``fjm simulate --json`` names).
JOINT_METRICS = ("rms_second_half", "peak_torque", "time_at_limit", "torque_jitter", "time_at_rate_limit")

_RUNNERS: dict = {}


def batch_seeds(sensor: SensorModel, B: int, seeds=None) -> np.ndarray:
    """The noise seed of each run: ``seeds`` (checked) or ``sensor.seed + i``, shape (B,) uint64."""
    if seeds is None:
        return np.array([(int(sensor.seed) + i) % 2 ** 64 for i in range(B)], dtype=np.uint64)
    vals = [int(v) for v in np.asarray(seeds).ravel()]
    if len(vals) != B or any(not 0 <= v < 2 ** 64 for v in vals):
        raise FjmValueError(f"seeds with {len(vals)} entries: expected {B} integers in [0, 2^64), one per run")
    return np.array(vals, dtype=np.uint64)


def _step_controller(controller):
    """A :class:`GainInput` for a sliding-mode or impedance law (gains per run), else the controller itself."""
    # the impedance laws' emitted Functions take the sliding-mode law's arguments; adaptive keeps its own gains
    if type(controller) in (SlidingModeController, ImpedanceController, JointImpedanceController):
        return GainInput(controller)
    return controller


def _gain_rows(ctrl, controller, gains, B: int):
    if not isinstance(ctrl, GainInput):
        if gains is not None:
            raise FjmValueError(f"gains: per-run gains need a sliding-mode controller, not {type(controller).__name__}")
        return None
    G = np.tile(np.asarray(controller.gains, dtype=float), (B, 1)) if gains is None else \
        np.asarray(gains, dtype=float)
    if G.ndim == 1:
        G = np.tile(G, (B, 1))
    if G.shape != (B, ctrl.n_gains) or not np.all(np.isfinite(G)):
        raise FjmValueError(f"gains with shape {G.shape}: expected finite ({B}, {ctrl.n_gains}) rows of the "
                            f"{controller.law_kind} gains layout")
    return G


def build_sampled_runner(model, ctrl, L, max_state: float, width: int, want_simd: bool, parallel: bool,
                         on_fallback=None):
    """``(runner, reason, step, acc_layout)``, built once per key and kept in memory."""
    key = (id(model), id(getattr(ctrl, "base", ctrl)), L, float(max_state), int(width), bool(want_simd),
           bool(parallel))
    hit = _RUNNERS.get(key)
    if hit is not None and hit[0] is model and hit[1] is getattr(ctrl, "base", ctrl):
        return hit[2]
    step, A = sampled_metric_step(model, ctrl, L, max_state, width)
    runner, reason = None, "simd=False requested"
    if want_simd:
        runner, reason = simd.simd_runner_or_reason(step, A.n_par, parallel, nm=L.nm)
        if runner is None and on_fallback is not None:
            on_fallback(reason)
    if runner is None:
        runner = sampled_scalar_runner(step, L.nm, DEFAULT_FLAGS, parallel)
    if len(_RUNNERS) > 16:
        _RUNNERS.clear()
    _RUNNERS[key] = (model, getattr(ctrl, "base", ctrl), (runner, reason, step, A))
    return runner, reason, step, A


def _x0(model, R0, x0):
    n, nx = int(model.n), int(model.nx)
    if x0 is None:
        x0 = np.zeros(nx)
        x0[0:n] = R0[:n]
        x0[2 * n:3 * n] = R0[:n]
    x0 = np.asarray(x0, dtype=float)
    if x0.shape != (nx,) or not np.all(np.isfinite(x0)):
        raise FjmValueError(f"x0 with shape {x0.shape}: expected finite ({nx},) = [q_l; dq_l; q_m; dq_m]")
    return x0


def _check(duration, dt, sensor, delay, predict):
    if not (np.isfinite(duration) and duration > 0):
        raise FjmValueError(f"duration = {duration!r}: expected a finite value > 0 s")
    if not (np.isfinite(dt) and 0 < dt <= duration):
        raise FjmValueError(f"dt = {dt!r}: expected a finite step with 0 < dt <= duration")
    return check_loop_settings(sensor, delay, predict)[0]


def _flags(N: int, h: int, t) -> np.ndarray:
    """``[in_second_half, k, is_first, is_last, applied, jitter_full]`` per sample, shape (N+1, 6)."""
    k = np.arange(N + 1)
    return np.column_stack([t >= 0.5 * t[-1], k, k == 0, k == N, k < N, (k < N) & (k >= 2 * h)]).astype(float)


def _initial_rows(model, ctrl, controller, L, A, P, G, x0, R0, sensor, seeds):
    rows = []
    for i in range(P.shape[0]):
        m0 = initial_measurement(model, L, x0, P[i])
        z = np.asarray(controller.initial_state(0.0, m0, R0.reshape(5, L.n)), dtype=float)
        if G is not None:
            z = np.concatenate([z, G[i]])
        w0 = initial_step_state(model, L, x0, z, P[i], seed=int(seeds[i]), sensor=sensor, controller=ctrl)
        rows.append(A.initial(w0, P[i]))
    return np.vstack(rows)


def run_sampled_batch(model, controller, reference, P, *, duration, dt, substeps, sensor, delay, predict, seeds,
                      gains, x0, max_state, trajectories, parallel, simd, threads, result_cls, want_simd_runner,
                      interface=None):
    """The sampled-data batch (see :func:`fjm_runtime.batch.runner.simulate_batch`); a ``result_cls``."""
    sensor = _check(duration, dt, sensor, delay, predict)
    interface = interface_from_spec(interface, what="interface")
    n, B, N = int(model.n), P.shape[0], int(round(duration / dt))
    t = dt * np.arange(N + 1)
    R = np.asarray(reference.sample(t), dtype=float).reshape(N + 1, 5 * n)
    x0 = _x0(model, R[0], x0)
    subs = int(substeps) if substeps is not None else \
        max(resolve_substeps(None, model, x0, P[i], float(dt)) for i in range(B))
    if substeps is not None:
        resolve_substeps(subs, model, x0, P[0], float(dt))   # validates, warns when coarse
    ctrl = _step_controller(controller)
    G = _gain_rows(ctrl, controller, gains, B)
    L = make_layout(model, ctrl, float(dt), subs, sensor, int(delay), bool(predict), interface=interface)
    h = jitter_half_width(float(dt))
    runner, reason, step, A = build_sampled_runner(model, ctrl, L, max_state, 2 * h + 1, simd, parallel,
                                                   want_simd_runner)
    sd = batch_seeds(sensor, B, seeds)
    ACC0 = _initial_rows(model, ctrl, controller, L, A, P, G, x0, R[0], sensor, sd)
    channels, levels = noise_slots(sensor, L.sensing, n)
    acc, used = runner.run(ACC0, R, _flags(N, h, t), levels, channels, sd, threads if parallel else 1)
    info = {"path": runner.path_name, "reason": reason, "threads": used, "lanes": runner.lanes,
            "openmp": runner.openmp, "instructions": int(step.n_instructions()), "library": str(runner.path),
            "substeps": subs, "loop": "sampled", "sensing": L.sensing, "delay_samples": int(delay),
            "predict": bool(predict), "interface": interface.name}
    metrics, joint, diverged, first_bad, x_fin = _metrics(A, acc, L, t, R[N, :n], h)
    results = None
    if trajectories:
        results = _trajectories(model, controller, reference, P, G, gains, diverged, sd, sensor, dict(
            duration=duration, dt=dt, x0=x0, max_state=max_state, substeps=subs, delay_samples=int(delay),
            predict=bool(predict), interface=interface))
    return result_cls(params=P, metrics=metrics, diverged=diverged,
                      divergence_time=np.where(diverged, first_bad * dt, np.nan), x_final=x_fin,
                      results=results, info=info, joint_metrics=joint, seeds=sd)


def _metrics(A, acc, L, t, q_end, h):
    """``(metrics, joint_metrics, diverged, first_bad, x_final)`` from the final accumulators."""
    n, N = L.n, t.size - 1
    x_fin = acc[:, :L.nx]
    get = lambda name: A.get(acc, name)  # noqa: E731
    metrics = metrics_from_sums(t, np.max(np.abs(x_fin[:, :n] - q_end), axis=1), get("e2_all")[:, 0],
                                get("e2_half_all")[:, 0], get("max_u")[:, 0], get("last_out")[:, 0],
                                get("tv")[:, 0], n)
    n_half = int(np.count_nonzero(t >= 0.5 * t[-1]))
    cnt = N - 2 * h
    if cnt > 0:
        mean = get("jit_sum") / cnt
        jitter = np.sqrt(np.maximum(get("jit_sq") / cnt - mean ** 2, 0.0))
    else:
        jitter = np.full((acc.shape[0], n), np.nan)
    joint = {"rms_second_half": np.sqrt(get("e2_half_j") / n_half), "peak_torque": get("peak_j").copy(),
             "time_at_limit": get("limit_j") / N, "torque_jitter": jitter,
             "time_at_rate_limit": get("rate_j") / N}
    first_bad = get("first_bad")[:, 0]
    diverged = first_bad >= 0
    metrics = {k: np.array(v, dtype=float) for k, v in metrics.items()}
    for v in list(metrics.values()) + list(joint.values()):
        v[diverged] = np.nan
    return metrics, joint, diverged, first_bad, x_fin


def _trajectories(model, controller, reference, P, G, gains, diverged, sd, sensor, kw):
    from ..sim.simulate import simulate
    if gains is not None:
        raise FjmValueError("trajectories=True with per-run gains: simulate each run with its own controller")
    return [None if diverged[i] else
            simulate(model, controller, reference, true_params=P[i], sensor=sensor.with_seed(int(sd[i])),
                     backend="compiled", **kw) for i in range(P.shape[0])]
