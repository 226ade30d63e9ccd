"""Sampled-loop batches on a dask.distributed cluster, row for row equal to the local batch.

A batch of ``B`` runs (TRUE parameter rows, noise seeds, gains rows) is cut into chunks; each
chunk runs :func:`fjm_runtime.batch.runner.simulate_batch` on a worker, which rebuilds the
model, controller and reference from plain data (:class:`LoopSpec`; the compiled library is
cached per machine, :mod:`fjm_runtime.ccache`). Everything that the local batch would decide
from ALL its rows is decided once on the client and sent with the spec: the RK4 substeps per
sample (:func:`batch_substeps`; the local default is the largest over the rows, which a chunk
would compute over its own rows only) and the initial state. Every run's noise seed and gains
ride with its row. So the gathered metrics are bit-identical to one local
:func:`simulate_batch` call with the same ``substeps`` and ``x0`` (a run's arithmetic does not
depend on the other runs of its batch: OpenMP splits runs, SIMD lanes are runs).
"""
from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from ..validation import FjmValueError

__all__ = ["LoopSpec", "batch_substeps", "client_for", "initial_state", "map_ordered", "run_loop_rows",
           "run_on_cluster", "n_workers"]


@dataclass(frozen=True)
class LoopSpec:
    """What every run of a distributed batch shares (plain, picklable data).

    Attributes
    ----------
    model : str
        Model directory (``fjm_runtime.load`` of a path: built-in and user models alike); a worker on
        which that directory does not exist loads ``model_name`` (the built-in or ``$FJM_GENERATED``
        model of that name: fjm, and user models, installed on the workers).
    kind, sensing : str
        Controller kind and sensing of :func:`fjm_runtime.control.factory.make_controller`.
    nominal : dict str -> float
        The controller's nominal parameters.
    options : dict
        Controller keywords (gains of the base controller, ``u_max``); per-run gains ride as rows.
    reference : object
        A picklable reference (e.g. :class:`fjm_runtime.control.references.Sinusoid`).
    duration, dt : float
        Seconds.
    substeps : int
        RK4 steps per sample (decided on the client for the whole batch).
    sensor : SensorModel
    delay : int
    predict : bool
    x0 : tuple of float
        Initial state (decided on the client).
    simd : bool
    interface : CommandInterface, optional
        The command interface (default motor).
    """

    model: str
    kind: str
    sensing: str
    nominal: Dict[str, float]
    options: dict
    reference: object
    duration: float
    dt: float
    substeps: int
    sensor: object
    delay: int
    predict: bool
    x0: tuple
    simd: bool = True
    model_name: str = ""
    interface: object = None


_BUILT: dict = {}


def _build(spec: LoopSpec):
    """``(model, controller)`` of a spec, memoised per worker process."""
    import pickle
    key = pickle.dumps((spec.model, spec.kind, spec.sensing, sorted(spec.nominal.items()), spec.options))
    hit = _BUILT.get(key)
    if hit is None:
        import os
        from .. import load
        from ..control.factory import make_controller
        model = load(spec.model if os.path.isdir(spec.model) or not spec.model_name else spec.model_name)
        hit = (model, make_controller(spec.kind, model, dict(spec.nominal), sensing=spec.sensing, **spec.options))
        if len(_BUILT) > 8:
            _BUILT.clear()
        _BUILT[key] = hit
    return hit


def run_loop_rows(spec: LoopSpec, P: np.ndarray, seeds: np.ndarray, G: Optional[np.ndarray]) -> dict:
    """One chunk on a worker: :func:`simulate_batch` on rows ``P`` with ``seeds`` and gains ``G``.

    Returns
    -------
    dict
        ``joint_metrics`` (dict of (b, n) arrays), ``metrics`` (dict of (b,)), ``diverged``,
        ``divergence_time``, ``x_final``, ``seeds``, ``info``.
    """
    from .runner import simulate_batch
    model, controller = _build(spec)
    b = simulate_batch(model, controller, spec.reference, P, duration=spec.duration, dt=spec.dt,
                       substeps=spec.substeps, sensor=spec.sensor, delay_samples=spec.delay, predict=spec.predict,
                       seeds=seeds, gains=G, x0=np.asarray(spec.x0), simd=spec.simd, interface=spec.interface,
                       threads=1)  # the OpenMP build on one thread: the library of the local run, no second build
    return {"joint_metrics": b.joint_metrics, "metrics": b.metrics, "diverged": b.diverged,
            "divergence_time": b.divergence_time, "x_final": b.x_final, "seeds": b.seeds, "info": b.info}


def initial_state(model, reference, x0=None) -> np.ndarray:
    """The batch's initial state: ``x0``, or at rest on the reference's ``q_d(0)`` (links and motors)."""
    n, nx = int(model.n), int(model.nx)
    if x0 is not None:
        return np.asarray(x0, dtype=float)
    R0 = np.asarray(reference.sample(np.array([0.0])), dtype=float).reshape(-1)[:n]
    x = np.zeros(nx)
    x[0:n] = R0
    x[2 * n:3 * n] = R0
    return x


def batch_substeps(model, x0, P: np.ndarray, dt: float) -> int:
    """The local batch's default substeps: the largest of the rule over the distinct rows of ``P``."""
    from ..sim.substeps import resolve_substeps
    rows = np.unique(np.atleast_2d(P), axis=0)
    return max(resolve_substeps(None, model, x0, rows[i], float(dt)) for i in range(rows.shape[0]))


def _reachable(address: str, timeout: float = 5.0) -> None:
    """Refuse at once a ``tcp://host:port`` nobody listens on (dask would retry until its timeout)."""
    import socket
    from urllib.parse import urlsplit
    if not address.startswith("tcp://"):
        return
    try:
        u = urlsplit(address)
        host, port = u.hostname, u.port
    except ValueError:
        host, port = None, None
    if not host or not port:
        raise FjmValueError(f"--scheduler {address}: expected tcp://HOST:PORT, e.g. tcp://127.0.0.1:8786")
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as exc:
        raise FjmValueError(f"--scheduler {address}: cannot connect ({exc.strerror or exc}); expected the address "
                            "of a running dask scheduler") from None


@contextlib.contextmanager
def client_for(scheduler, n_workers: int = 2, processes: bool = True):
    """A ``dask.distributed.Client``: ``scheduler`` itself if it is one, else connect to the address,
    else start a local cluster of ``n_workers`` (one thread each); closed on exit unless passed in."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise FjmValueError("a dask cluster needs dask.distributed: pip install 'fjm[sweep]'") from exc
    if isinstance(scheduler, Client):
        yield scheduler
        return
    cluster = None
    if scheduler:
        _reachable(str(scheduler))
        try:
            client = Client(str(scheduler), timeout=30)
        except (OSError, TimeoutError) as exc:
            raise FjmValueError(f"--scheduler {scheduler}: cannot connect ({exc}); expected the address of a "
                                "running dask scheduler, e.g. tcp://127.0.0.1:8786") from None
    else:
        cluster = LocalCluster(n_workers=int(n_workers), threads_per_worker=1, processes=processes,
                               dashboard_address=None)
        client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def n_workers(client) -> int:
    """Worker threads of a client's cluster (at least 1)."""
    try:
        return max(1, sum(client.nthreads().values()))
    except Exception:  # pragma: no cover - scheduler without the call
        return 1


def map_ordered(client, fn: Callable, args: Sequence[tuple],
                progress: Optional[Callable[[int, int], None]] = None) -> List:
    """``[fn(*a) for a in args]`` on the cluster, results in the order of ``args``."""
    from dask.distributed import as_completed
    futures = [client.submit(fn, *a, pure=False) for a in args]
    index = {f.key: i for i, f in enumerate(futures)}
    out: List = [None] * len(futures)
    for done, fut in enumerate(as_completed(futures), 1):
        out[index[fut.key]] = fut.result()
        if progress:
            progress(done, len(futures))
    return out


def _chunks(B: int, workers: int, lanes: int = 8) -> List[slice]:
    """About two chunks per worker, each a multiple of ``lanes`` runs (whole SIMD blocks) but the last."""
    size = max(lanes, int(math.ceil(B / (2 * workers) / lanes)) * lanes)
    return [slice(i, min(B, i + size)) for i in range(0, B, size)]


def run_on_cluster(client, spec: LoopSpec, P: np.ndarray, seeds, G: Optional[np.ndarray], result_cls):
    """All rows of ``P`` in chunks on the cluster; one ``result_cls`` (a :class:`BatchResult`)."""
    P = np.atleast_2d(np.asarray(P, dtype=float))
    seeds = np.asarray(seeds, dtype=np.uint64)
    parts = map_ordered(client, run_loop_rows, [(spec, P[s], seeds[s], None if G is None else G[s])
                                                for s in _chunks(P.shape[0], n_workers(client))])
    cat = lambda key: np.concatenate([p[key] for p in parts])  # noqa: E731
    info = dict(parts[0]["info"], chunks=len(parts), threads=n_workers(client), cluster=True)
    metrics = {k: np.concatenate([p["metrics"][k] for p in parts]) for k in parts[0]["metrics"]}
    return result_cls(params=P, metrics=metrics,
                      diverged=cat("diverged"), divergence_time=cat("divergence_time"), x_final=cat("x_final"),
                      info=info, seeds=cat("seeds"),
                      joint_metrics={k: np.concatenate([p["joint_metrics"][k] for p in parts])
                                     for k in parts[0]["joint_metrics"]})
