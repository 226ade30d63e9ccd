"""Batch closed-loop runs: many TRUE plants, one controller, one compiled call.

:func:`simulate_batch` folds THE sample step of :mod:`fjm_runtime.sim.sample_step` over the
samples while accumulating the per-run metrics (:mod:`fjm_runtime.batch.sampled`; sensor noise
generated in C per run and sample, so no trajectory is stored), maps that over the runs (OpenMP
when the compiler supports it) and compiles the whole thing once (cached like the single-run
backend, :mod:`fjm_runtime.ccache`). The inputs, the runner choice and the metrics are
:mod:`fjm_runtime.batch.sampled_runner`; the scalar C loop is :mod:`fjm_runtime.batch.scalar`,
the SIMD form :mod:`fjm_runtime.batch.simd`.

Which code ran is recorded in :attr:`BatchResult.info` (``info["path"]`` is one
of :data:`PATHS`); a requested SIMD form that cannot be used falls back to the
scalar loop only with a :class:`SimdFallbackWarning` naming the reason.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Dict, List, Optional

import numpy as np

from ..sim.sample_step import check_loop_settings
from .scalar import threads_arg

__all__ = ["METRIC_NAMES", "PATHS", "BatchResult", "SimdFallbackWarning", "simulate_batch"]

METRIC_NAMES = ("final_error", "rms_error", "rms_error_second_half", "max_abs_u",
                "reaching_time", "total_variation_u")

#: Values of ``BatchResult.info["path"]``: the SIMD form for the instruction set it was
#: built for (``simd-generic``: no x86 vector flags known, lanes left to the compiler),
#: or the scalar C loop.
PATHS = ("simd-avx512", "simd-avx2", "simd-sse2", "simd-generic", "scalar")


class SimdFallbackWarning(RuntimeWarning):
    """``simd=True`` was requested but the scalar loop ran (the message names why)."""


@dataclass
class BatchResult:
    """Per-run results of :func:`simulate_batch` (``B`` runs).

    Attributes
    ----------
    params : ndarray, shape (B, n_params)
        TRUE parameters of each run (``param_names`` order).
    metrics : dict str -> ndarray, shape (B,)
        The fields of :class:`fjm_runtime.sim.metrics.Metrics`; NaN for diverged runs.
    diverged : ndarray of bool, shape (B,)
    divergence_time : ndarray, shape (B,)
        First time the state was non-finite or beyond ``max_state`` (NaN if never).
    x_final : ndarray, shape (B, 4n)
    results : list of SimulationResult or None
        Full trajectories, only with ``trajectories=True``.
    joint_metrics : dict str -> ndarray, shape (B, n)
        Per joint (sampled loop): ``rms_second_half`` (rad), ``peak_torque`` (N m),
        ``time_at_limit`` (fraction), ``torque_jitter`` (N m; NaN if the run is shorter than the
        20 ms window); NaN rows for diverged runs.
    seeds : ndarray of uint64, shape (B,) or None
        The noise seed of each run (sampled loop).
    info : dict
        How the batch ran: ``path`` (one of :data:`PATHS`), ``reason`` (why the
        scalar loop ran; ``None`` on a SIMD path), ``threads`` (OpenMP threads
        used), ``lanes`` (runs per vector statement, 1 for scalar),
        ``instructions`` (SX instructions of one step) and ``library`` (the
        compiled shared object).
    """

    params: np.ndarray
    metrics: Dict[str, np.ndarray]
    diverged: np.ndarray
    divergence_time: np.ndarray
    x_final: np.ndarray
    results: Optional[list] = None
    info: dict = field(default_factory=dict)
    joint_metrics: Dict[str, np.ndarray] = field(default_factory=dict)
    seeds: Optional[np.ndarray] = None

    def table(self) -> List[dict]:
        """One dict per run: parameters by name are not known here; index, metrics, diverged."""
        return [dict(run=i, diverged=bool(self.diverged[i]),
                     **{k: float(v[i]) for k, v in self.metrics.items()})
                for i in range(self.diverged.size)]



def simulate_batch(model, controller, reference, params_true_array, *, duration: float,
                   dt: float = 1e-3, substeps: Optional[int] = None, sensor=None, delay_samples: int = 0,
                   predict: bool = False, seeds=None, gains=None, x0=None, max_state: float = 1e6,
                   trajectories: bool = False, parallel: bool = True, simd: bool = True,
                   threads: Optional[int] = None, loop: str = "sampled", interface=None) -> BatchResult:
    """Run ``B`` sampled-data closed loops (one per row of ``params_true_array``) in one compiled call.

    Each run is :func:`fjm_runtime.sim.simulate.simulate` with the same settings (THE sample
    step of :mod:`fjm_runtime.sim.sample_step`: sensor noise, delay, prediction, ZOH, plant on
    RK4 substeps), so a row equals the single run on the same TRUE parameters and seed to rounding.

    Parameters
    ----------
    model, controller, reference
        As for :func:`simulate`; the controller (NOMINAL parameters) and the reference are shared.
    params_true_array : array_like, shape (B, n_params)
        TRUE plant parameters per run, columns in ``model.param_names`` order.
    duration, dt, x0, max_state, delay_samples, predict
        As for :func:`simulate` (``x0`` shared by all runs).
    substeps : int, optional
        RK4 plant steps per sample; default the largest of the rule of
        :mod:`fjm_runtime.sim.substeps` over the rows (one value for the whole batch).
    sensor : SensorModel, optional
        Noise levels, quantization and dtau_J mode shared by all runs (default ideal).
    seeds : array_like of int, shape (B,), optional
        Noise seed per run; default ``sensor.seed + i`` for run ``i``.
    gains : array_like, shape (B, n_gains), optional
        The emitted law's ``gains`` vector per run (a sliding-mode controller only; default
        ``controller.gains`` for every run): one build serves every candidate of a gain search.
    trajectories : bool
        Also return every run's :class:`SimulationResult` (compiled backend, one run at a time).
    parallel, simd, threads
        OpenMP across runs; vector lanes across runs (falls back to the scalar loop with a
        :class:`SimdFallbackWarning`); threads for this call (default all cores).
    interface : CommandInterface or str, optional
        The command interface shared by all runs (as for :func:`simulate`; default ``'motor'``).
    loop : {'sampled'}
        The one loop (any other name raises :class:`FjmValueError`).

    Returns
    -------
    BatchResult
        ``metrics`` (the :class:`Metrics` fields) and ``joint_metrics`` (per joint, shape (B, n):
        ``rms_second_half``, ``peak_torque``, ``time_at_limit``, ``torque_jitter``).
    """
    check_loop_settings(sensor, delay_samples, predict, loop)
    from .sampled_runner import run_sampled_batch
    P = _true_params_rows(model, params_true_array)
    threads_arg(threads)
    return run_sampled_batch(model, controller, reference, P, duration=duration, dt=dt, substeps=substeps,
                             sensor=sensor, delay=delay_samples, predict=predict, seeds=seeds, gains=gains, x0=x0,
                             max_state=max_state, trajectories=trajectories, parallel=parallel, simd=simd,
                             threads=threads, result_cls=BatchResult, want_simd_runner=_warn_fallback,
                             interface=interface)


def _warn_fallback(reason: str) -> None:
    warnings.warn(f"simulate_batch: scalar loop instead of SIMD: {reason}", SimdFallbackWarning, stacklevel=4)


def _true_params_rows(model, params_true_array) -> np.ndarray:
    """``params_true_array`` checked, shape (B, n_params) (one row given as a vector is one run)."""
    P = np.asarray(params_true_array, dtype=float)
    if P.ndim == 1 and P.size == len(model.param_names):
        P = P[None, :]
    if P.ndim != 2 or P.shape[1] != len(model.param_names) or P.shape[0] < 1:
        raise ValueError(f"params_true_array with shape {np.shape(params_true_array)}: expected "
                         f"(B, {len(model.param_names)}) with columns {', '.join(model.param_names)}")
    if not np.all(np.isfinite(P)):
        raise ValueError("params_true_array: expected finite values")
    return P
