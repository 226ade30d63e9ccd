"""The Monte Carlo stages of a design: many candidates on many TRUE plants, here or on a cluster.

:class:`DesignLoops` holds what every evaluation of a design shares (model, law, nominal
parameters, reference, initial state, sensor, rate, delay, prediction) and runs candidate gains x
parameter rows in ONE batch (the law's gains vector rides per run, so one compiled library
serves every candidate). ``client=None`` runs it in this process
(:func:`fjm_runtime.batch.runner.simulate_batch`, OpenMP over the runs); a
``dask.distributed.Client`` runs it in chunks on the cluster
(:func:`fjm_runtime.batch.distributed.run_on_cluster`). The substeps and the initial state are
decided here for the whole batch and passed to both, so the two give the same numbers bit for bit.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from ...control.factory import make_controller
from ...sim.interface import CommandInterface
from ...control.references import make_reference
from .thresholds import Thresholds, run_cost

__all__ = ["DesignLoops"]


class DesignLoops:
    """Model, law, reference, sensor and batch settings shared by every evaluation of a design.

    Parameters
    ----------
    model : fjm_runtime.Model
    kind, sensing : str
    rate : float
        Control rate, Hz.
    delay : int
        Computation delay, samples.
    sensor : SensorModel
    u_max : sequence of float or None
        Torque limits per joint.
    threads : int or None
        OpenMP threads of a local batch.
    simd : bool
    predict : bool
    reference : object, optional
        Default: 0.5 rad sines at 1 rad/s about q = 0.
    x0 : ndarray (nx,), optional
        Default: at rest on the reference's start.
    task : dict, optional
        How the record describes the task.
    nominal : dict str -> float, optional
        The controller's nominal parameters (default: the model's defaults).
    thresholds : Thresholds, optional
    client : dask.distributed.Client, optional
        Run the batches on this cluster.
    interface : CommandInterface, optional
        The command interface (default motor).
    """

    def __init__(self, model, kind, sensing, rate, delay, sensor, u_max, threads, simd, predict=False,
                 reference=None, x0=None, task=None, nominal=None, thresholds: Optional[Thresholds] = None,
                 client=None, interface=None):
        from ...batch.distributed import initial_state
        self.model, self.kind, self.sensing, self.delay = model, kind, sensing, int(delay)
        self.dt, self.sensor, self.u_max, self.threads, self.simd = 1.0 / rate, sensor, u_max, threads, simd
        self.predict = bool(predict)
        self.interface = CommandInterface.motor() if interface is None else interface
        self.reference = make_reference("sine", int(model.n), amplitude=0.5, omega=1.0) if reference is None \
            else reference
        self.x0 = initial_state(model, self.reference, x0)
        self.task = task or {"kind": "sine", "amplitude": 0.5, "omega": 1.0}
        self.nominal = dict(model.default_params) if nominal is None else dict(nominal)
        self.thresholds = thresholds or Thresholds()
        self.client = client
        self._subs: dict = {}
        self.batches = 0
        self.runs = 0

    def controller(self, g: dict):
        """The law with gains ``g`` on the nominal parameters."""
        return make_controller(self.kind, self.model, self.nominal, sensing=self.sensing, u_max=self.u_max, **g)

    def substeps(self, P) -> int:
        """RK4 substeps for rows ``P``: the largest of the rule over them (memoised per row)."""
        from ...sim.substeps import resolve_substeps
        out = 1
        for row in np.atleast_2d(P):
            key = row.tobytes()
            if key not in self._subs:
                self._subs[key] = resolve_substeps(None, self.model, self.x0, row, float(self.dt))
            out = max(out, self._subs[key])
        return out

    def run(self, cands, P, duration, seed, delay=None):
        """Every candidate on every row of ``P``: a BatchResult of ``len(cands) x len(P)`` runs, candidate-major.

        ``seed``: an int (row ``i`` gets noise seed ``seed + i``) or one seed per row.
        """
        from ...batch.runner import BatchResult, simulate_batch
        P = np.atleast_2d(np.asarray(P, dtype=float))
        ctrls = [self.controller(g) for g in cands]
        G = np.vstack([np.tile(c.gains, (P.shape[0], 1)) for c in ctrls])
        row_seeds = seed + np.arange(P.shape[0]) if np.ndim(seed) == 0 else np.asarray(seed)
        seeds = np.tile(row_seeds, len(cands))
        rows = np.tile(P, (len(cands), 1))
        d = self.delay if delay is None else int(delay)
        subs = self.substeps(P)
        self.batches += 1
        self.runs += rows.shape[0]
        if self.client is None:
            return simulate_batch(self.model, ctrls[0], self.reference, rows, duration=duration, dt=self.dt,
                                  substeps=subs, sensor=self.sensor, delay_samples=d, seeds=seeds, gains=G,
                                  threads=self.threads, simd=self.simd, predict=self.predict, x0=self.x0,
                                  interface=self.interface)
        from ...batch.distributed import LoopSpec, run_on_cluster
        spec = LoopSpec(model=str(self.model.directory), model_name=self.model.name, kind=self.kind,
                        sensing=self.sensing, nominal=self.nominal, options=dict(cands[0], u_max=self.u_max),
                        reference=self.reference,
                        duration=float(duration), dt=self.dt, substeps=subs, sensor=self.sensor, delay=d,
                        predict=self.predict, x0=tuple(self.x0.tolist()), simd=self.simd, interface=self.interface)
        return run_on_cluster(self.client, spec, rows, seeds, G, BatchResult)

    def batch(self, cands, P, duration, seed, delay=None):
        """``(cost (n_cand, n_rows), BatchResult)`` of :meth:`run` (cost: :func:`run_cost`)."""
        P = np.atleast_2d(P)
        b = self.run(cands, P, duration, seed, delay)
        return run_cost(b, self.thresholds).reshape(len(cands), P.shape[0]), b
