"""Large Monte Carlo sweeps on Dask: chunks of compiled batch runs, gathered into one table.

A sweep samples TRUE plant parameters around the defaults (stiffness
uniform in ``[K_min, K_max]``, the other listed parameters within a relative
spread), splits the samples into chunks, and runs each chunk with
:func:`fjm_runtime.batch.runner.simulate_batch` on a Dask worker. The controller
always uses the NOMINAL (default) parameters. Workers receive only plain
data (model name, settings, the chunk's parameter rows) and rebuild model,
controller and reference themselves; the compiled batch library is cached
per machine (:mod:`fjm_runtime.ccache`), so each worker compiles at most
once.

Without ``scheduler`` a local cluster is started (``n_workers`` processes,
one thread each); with ``scheduler="tcp://host:port"`` an existing
``dask.distributed`` scheduler is used.

The runs are THE sampled loop of :func:`fjm_runtime.sim.simulate.simulate` (sensing, sensor model,
delay, prediction: :class:`SweepSpec`). What the local batch would decide from all rows is decided
once for the whole sweep: the RK4 substeps (the largest of the rule over every row) and each run's
noise seed (``sensor.seed + run``), so the table does not depend on the chunking.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Optional

import numpy as np

from ..control.defaults import PAPER_K_RANGE
from ..drives import linear_springs
from ..validation import FjmValueError


@dataclass(frozen=True)
class SweepSpec:
    """What every run of a sweep shares (plain data, picklable).

    Attributes
    ----------
    model : str
        Generated model name.
    controller : str
        ``smc``, ``ismc``, ``fl`` or ``sign`` (see :func:`fjm_runtime.control.factory.make_controller`).
    controller_options : dict
        Extra keyword arguments of the controller (``lam``, ``k_s``, ``delta`` ...).
    reference : str
        ``step`` or ``sine`` (see :func:`fjm_runtime.control.references.make_reference`), or ``task``:
        the per-joint sines ``offset + amplitude sin(omega t + phase)`` of a design file's task
        (``reference_options``: its ``offset``, ``amplitude``, ``omega``, ``phase``).
    reference_options : dict
    duration, dt : float
        Seconds (``dt``: the control period, 1 / rate).
    sensing : {'state', 'torque'}
        What the controller measures.
    sensor : SensorModel, optional
        Noise, encoders, filters and the torque-rate limit (default ideal).
    delay_samples : int
        Computation delay, samples.
    predict : bool
        Delay compensation by the nominal-model predictor.
    substeps : int, optional
        RK4 steps per sample; :func:`sweep` sets the largest of the rule over all rows.
    x0 : tuple of float, optional
        Initial state of every run (default: at rest on the reference's start).
    interface : CommandInterface, optional
        The command interface (default motor).
    """

    model: str = "link1"
    controller: str = "smc"
    controller_options: Dict[str, float] = field(default_factory=dict)
    reference: str = "sine"
    reference_options: Dict[str, float] = field(default_factory=dict)
    duration: float = 10.0
    dt: float = 1e-3
    sensing: str = "state"
    sensor: Optional[object] = None
    delay_samples: int = 0
    predict: bool = False
    substeps: Optional[int] = None
    x0: Optional[tuple] = None
    interface: Optional[object] = None


def _inertia_names(model) -> List[str]:
    """The link inertias (kg m^2, > 0, no drive role) and the rotor inertias of ``model``: the default spread."""
    info = model.parameter_info
    return [k for k in model.param_names if info[k].role == "rotor_inertia"
            or (info[k].role is None and info[k].unit == "kg m^2" and info[k].domain == ">0")]


def sample_parameters(model, n_samples: int, seed: int = 0, k_range=PAPER_K_RANGE,
                      spread: Optional[Dict[str, float]] = None, k_relative=None) -> np.ndarray:
    """TRUE parameter rows: stiffness(es) uniform in ``k_range``, others within ``+-spread``.

    Parameters
    ----------
    model : fjm_runtime.Model
    n_samples : int
    seed : int
    k_range : (float, float)
        Bounds of every stiffness parameter (``K`` or ``K1..Kn``), N m/rad.
    k_relative : (float, float), optional
        Instead of ``k_range``: every stiffness is its default times a factor
        uniform in ``[lo, hi]`` (for arms whose joints differ in stiffness,
        e.g. the Panda's 1e4 / 3e3 N m/rad; ``(0.7, 1.3)`` is +-30 %).
    spread : dict str -> float, optional
        Relative half-width per parameter name (default: link inertia and
        motor inertia +-20 %, as in the robustness study).

    Returns
    -------
    ndarray, shape (n_samples, len(model.param_names))
    """
    if int(n_samples) < 1:
        raise FjmValueError(f"n_samples = {n_samples!r}: expected an integer >= 1")
    lo, hi = (float(v) for v in (k_range if k_relative is None else k_relative))
    if not (0 < lo <= hi and np.isfinite(hi)):
        if k_relative is None:
            raise FjmValueError(f"k_range = {k_range!r}: expected 0 < K_min <= K_max < inf")
        raise FjmValueError(f"k_relative = {k_relative!r}: expected 0 < lo <= hi < inf (factors of the defaults)")
    if spread is None:
        spread = {k: 0.2 for k in _inertia_names(model)}
    unknown = sorted(set(spread) - set(model.param_names))
    if unknown:
        raise FjmValueError(f"spread: unknown parameter name(s) {unknown}; expected among {list(model.param_names)}")
    rng = np.random.default_rng(seed)
    base = np.array([model.default_params[k] for k in model.param_names])
    P = np.tile(base, (int(n_samples), 1))
    linear_K = set(linear_springs(model))
    for j, name in enumerate(model.param_names):
        if j in linear_K:
            P[:, j] = rng.uniform(lo, hi, len(P)) * (1.0 if k_relative is None else base[j])
        elif name in spread:
            P[:, j] = base[j] * rng.uniform(1 - spread[name], 1 + spread[name], len(P))
    return P


def _build(spec: SweepSpec):
    from .. import load
    from ..control.factory import make_controller
    model = load(spec.model)
    controller = make_controller(spec.controller, model, model.default_params, sensing=spec.sensing,
                                 **spec.controller_options)
    return model, controller, sweep_reference(spec.reference, spec.reference_options, int(model.n))


def sweep_reference(kind: str, options: dict, n: int):
    """The reference of a sweep: :func:`make_reference` of ``kind``, or ``'task'``: a design file's sines."""
    from ..control.references import Sinusoid, make_reference
    if kind == "task":
        return Sinusoid(list(options["amplitude"]), list(options["omega"]), n=n, offset=list(options["offset"]),
                        phase=float(options.get("phase", 0.0)))
    return make_reference(kind, n, **options)


def run_chunk(spec: SweepSpec, params: np.ndarray, seeds=None) -> Dict[str, np.ndarray]:
    """Run one chunk of samples with the compiled batch (executed on a worker).

    ``seeds``: the noise seed of each row (default ``sensor.seed + i`` within the chunk).

    Returns
    -------
    dict str -> ndarray, each of shape (len(params),)
        The metrics of :class:`fjm_runtime.batch.BatchResult`, ``diverged``, ``divergence_time``
        and per joint ``<metric>_<j>`` (``rms_second_half``, ``peak_torque``, ``time_at_limit``,
        ``torque_jitter``, ``time_at_rate_limit``; joints from 1).
    """
    from ..batch.runner import simulate_batch
    model, controller, reference = _build(spec)
    res = simulate_batch(model, controller, reference, params, duration=spec.duration, dt=spec.dt,
                         substeps=spec.substeps, sensor=spec.sensor, delay_samples=spec.delay_samples,
                         predict=spec.predict, seeds=seeds, x0=None if spec.x0 is None else np.asarray(spec.x0),
                         interface=spec.interface, threads=1)  # one thread per Dask worker (no oversubscription), the local run's library
    out = {k: np.asarray(v) for k, v in res.metrics.items()}
    out["diverged"] = res.diverged.astype(float)
    out["divergence_time"] = np.asarray(res.divergence_time, dtype=float)
    for k, v in res.joint_metrics.items():
        for j in range(v.shape[1]):
            out[f"{k}_{j + 1}"] = np.asarray(v[:, j], dtype=float)
    return out


def resolve_spec(spec: SweepSpec, params: np.ndarray) -> SweepSpec:
    """``spec`` with the substeps of the whole sweep: the largest of the rule over every row (unless set)."""
    if spec.substeps is not None:
        return spec
    from dataclasses import replace
    from .distributed import batch_substeps, initial_state
    model, _controller, reference = _build(spec)
    x0 = initial_state(model, reference, spec.x0)
    return replace(spec, substeps=batch_substeps(model, x0, params, spec.dt))


def run_seeds(spec: SweepSpec, n: int) -> np.ndarray:
    """The noise seed of every run of a sweep: ``sensor.seed + run`` (uint64, shape (n,))."""
    base = 0 if spec.sensor is None else int(spec.sensor.seed)
    return np.array([(base + i) % 2 ** 64 for i in range(int(n))], dtype=np.uint64)


def sweep(spec: SweepSpec, params: np.ndarray, chunk_size: int = 250, scheduler: Optional[str] = None,
          n_workers: int = 2, progress: Optional[Callable[[int, int], None]] = None) -> Dict[str, np.ndarray]:
    """Run all parameter rows in chunks on Dask and gather the per-run metrics.

    Parameters
    ----------
    spec : SweepSpec
    params : ndarray, shape (B, n_params)
        TRUE parameters, e.g. from :func:`sample_parameters`.
    chunk_size : int
        Runs per Dask task.
    scheduler : str or dask.distributed.Client, optional
        Address of an existing scheduler (or a client); default: a local cluster.
    n_workers : int
        Workers of the local cluster.
    progress : callable (done, total), optional

    Returns
    -------
    dict str -> ndarray, shape (B,)
        Metrics in the order of ``params``.
    """
    P = np.atleast_2d(np.asarray(params, dtype=float))
    if int(chunk_size) < 1:
        raise FjmValueError(f"chunk_size = {chunk_size!r}: expected an integer >= 1")
    from .distributed import client_for, map_ordered
    spec = resolve_spec(spec, P)
    seeds = run_seeds(spec, len(P))
    size = int(chunk_size)
    args = [(spec, P[i:i + size], seeds[i:i + size]) for i in range(0, len(P), size)]
    with client_for(scheduler, n_workers) as client:
        parts: List[Dict[str, np.ndarray]] = map_ordered(client, run_chunk, args, progress)
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def write_table(path: Path, model, params: np.ndarray, metrics: Dict[str, np.ndarray]) -> Path:
    """One CSV row per run: index, every TRUE parameter, every metric."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = list(metrics)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["run", *model.param_names, *names])
        for i in range(len(params)):
            w.writerow([i, *[repr(float(v)) for v in params[i]], *[repr(float(metrics[k][i])) for k in names]])
    return path
