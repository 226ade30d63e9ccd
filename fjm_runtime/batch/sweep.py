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
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Optional

import numpy as np

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
        ``step`` or ``sine`` (see :func:`fjm_runtime.control.references.make_reference`).
    reference_options : dict
    duration, dt : float
        Seconds.
    """

    model: str = "link1"
    controller: str = "smc"
    controller_options: Dict[str, float] = field(default_factory=dict)
    reference: str = "sine"
    reference_options: Dict[str, float] = field(default_factory=dict)
    duration: float = 10.0
    dt: float = 1e-3


def sample_parameters(model, n_samples: int, seed: int = 0, k_range=(100.0, 200.0),
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
        spread = {k: 0.2 for k in model.param_names if k in ("J_l", "J_m") or k.startswith(("Jm", "I"))}
    unknown = sorted(set(spread) - set(model.param_names))
    if unknown:
        raise FjmValueError(f"spread: unknown parameter name(s) {unknown}; expected among {list(model.param_names)}")
    rng = np.random.default_rng(seed)
    base = np.array([model.default_params[k] for k in model.param_names])
    P = np.tile(base, (int(n_samples), 1))
    for j, name in enumerate(model.param_names):
        if name == "K" or (name.startswith("K") and name[1:].isdigit()):
            P[:, j] = rng.uniform(lo, hi, len(P)) * (1.0 if k_relative is None else base[j])
        elif name in spread:
            P[:, j] = base[j] * rng.uniform(1 - spread[name], 1 + spread[name], len(P))
    return P


def _build(spec: SweepSpec):
    from .. import load
    from ..control.factory import make_controller
    from ..control.references import make_reference
    model = load(spec.model)
    controller = make_controller(spec.controller, model, model.default_params, **spec.controller_options)
    reference = make_reference(spec.reference, model.n, **spec.reference_options)
    return model, controller, reference


def run_chunk(spec: SweepSpec, params: np.ndarray) -> Dict[str, np.ndarray]:
    """Run one chunk of samples with the compiled batch (executed on a worker).

    Returns
    -------
    dict str -> ndarray, each of shape (len(params),)
        The metrics of :class:`fjm_runtime.batch.BatchResult` plus ``diverged``.
    """
    from ..batch.runner import simulate_batch
    model, controller, reference = _build(spec)
    res = simulate_batch(model, controller, reference, params, duration=spec.duration, dt=spec.dt,
                         parallel=False)  # one thread per Dask worker: no oversubscription
    out = {k: np.asarray(v) for k, v in res.metrics.items()}
    out["diverged"] = res.diverged.astype(float)
    return out


def _client(scheduler: Optional[str], n_workers: int):
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise RuntimeError("fjm sweep needs dask.distributed: pip install 'fjm[sweep]'") from exc
    if scheduler:
        return Client(scheduler), None
    cluster = LocalCluster(n_workers=int(n_workers), threads_per_worker=1, processes=True,
                           dashboard_address=None)
    return Client(cluster), cluster


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
    scheduler : str, optional
        Address of an existing scheduler; default: a local cluster.
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
    chunks = [P[i:i + int(chunk_size)] for i in range(0, len(P), int(chunk_size))]
    client, cluster = _client(scheduler, n_workers)
    try:
        from dask.distributed import as_completed
        futures = client.map(run_chunk, [spec] * len(chunks), chunks, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        parts: List[Optional[Dict[str, np.ndarray]]] = [None] * len(chunks)
        for done, fut in enumerate(as_completed(futures), 1):
            parts[index[fut.key]] = fut.result()
            if progress:
                progress(done, len(chunks))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
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
