"""A robot's own facts, read from its manifest: joint limits (:class:`JointLimits`) and its task (:class:`Task`).

A model file states them in ``[limits]`` and ``[task]`` (docs/spatial.md); derive writes them into
``manifest.json`` as ``limits`` (per key ``unit``, ``values``, ``from``) and ``task``. A manifest without
``limits`` (written before them, or a model without a URDF) falls back to the URDF's ``<limit>`` of
``source.limits``, as :attr:`fjm_runtime.model.Model.effort_limits` reads it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Optional, Tuple

import numpy as np

from .validation import REDERIVE, FjmValueError

__all__ = ["JointLimits", "Task", "joint_limits", "task_from_manifest", "START_TEXT"]

#: The design file's words for a task's ``start = "rest"`` (:func:`fjm_runtime.control.design.task_start` reads "holding gravity").
START_TEXT = {"rest": "at rest holding gravity (nominal parameters)"}


def _frozen(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits of a model, q order; ``inf`` (position: ``-inf, inf``) where none is stated.

    Attributes
    ----------
    effort : ndarray, shape (n,)
        Link-side torque limit, N m.
    velocity : ndarray, shape (n,)
        Link velocity limit, rad/s.
    torque_rate : ndarray, shape (n,)
        Torque-rate limit, N m/s.
    position : ndarray, shape (n, 2)
        ``[lower, upper]`` link angle, rad.
    origin : dict str -> tuple
        Per key (``effort``, ``velocity``, ``torque_rate``, ``position``), where each joint's value comes
        from: ``"model file"``, ``"urdf"`` or None (no limit).
    """

    effort: np.ndarray
    velocity: np.ndarray
    torque_rate: np.ndarray
    position: np.ndarray
    origin: Dict[str, Tuple[Optional[str], ...]]


def _values(entry, key: str, n: int, name: str, fill: float) -> np.ndarray:
    values = entry.get(key) if isinstance(entry, dict) else None
    if values is None:
        return np.full(n, fill)
    if len(values) != n:
        raise FjmValueError(f"model {name}: manifest limits {key} has {len(values)} entries, expected n = {n}; "
                            f"{REDERIVE}")
    return np.array([fill if v is None else float(v) for v in values])


def joint_limits(manifest: dict, n: int, urdf: Dict[str, Optional[np.ndarray]]) -> JointLimits:
    """The limits of ``manifest["limits"]``, or the URDF's (``urdf``: ``effort``, ``velocity`` (n,) and
    ``position`` (n, 2) or None, as :class:`~fjm_runtime.model.Model` reads ``source.limits``) without it."""
    name, stated = manifest.get("model", "?"), manifest.get("limits")
    if not isinstance(stated, dict):
        effort, velocity, position = (urdf.get(k) for k in ("effort", "velocity", "position"))
        effort = np.full(n, np.inf) if effort is None else np.array(effort, dtype=float)
        velocity = np.full(n, np.inf) if velocity is None else np.array(velocity, dtype=float)
        position = np.tile([-np.inf, np.inf], (n, 1)) if position is None else np.array(position, dtype=float)

        def src(a):
            return tuple("urdf" if np.any(np.isfinite(v)) else None for v in a)
        return JointLimits(_frozen(effort), _frozen(velocity), _frozen(np.full(n, np.inf)), _frozen(position),
                           {"effort": src(effort), "velocity": src(velocity), "torque_rate": (None,) * n,
                            "position": src(position)})
    pos = stated.get("position") or {}
    position = np.column_stack([_values(pos, "lower", n, name, -np.inf), _values(pos, "upper", n, name, np.inf)])
    origin = {key: tuple((stated.get(key) or {}).get("from") or (None,) * n)
              for key in ("effort", "velocity", "torque_rate", "position")}
    return JointLimits(*(_frozen(_values(stated.get(key), "values", n, name, np.inf))
                         for key in ("effort", "velocity", "torque_rate")), _frozen(position), origin)


@dataclass(frozen=True)
class Task:
    """The task a model's files state for its demo and design: per-joint sines or a sequence of poses.

    Attributes
    ----------
    kind : {'sines', 'poses'}
    n : int
    description : str
        One line; the design file records it as its reference's ``kind``.
    start : str
        ``"rest"``: at rest on the reference at ``t = 0``, the motors holding gravity.
    offset, amplitude, omega, phase : ndarray, shape (n,), or None
        Sines ``q_d = offset + amplitude sin(omega t + phase)`` (rad, rad, rad/s, rad).
    poses : ndarray, shape (k, n), or None
        Poses (rad), moved through by smooth steps of ``durations`` (s, shape (k - 1,)).
    durations : ndarray, shape (k - 1,), or None
    """

    kind: str
    n: int
    description: str
    start: str = "rest"
    offset: Optional[np.ndarray] = None
    amplitude: Optional[np.ndarray] = None
    omega: Optional[np.ndarray] = None
    phase: Optional[np.ndarray] = None
    poses: Optional[np.ndarray] = None
    durations: Optional[np.ndarray] = None

    def reference(self):
        """The task's :class:`~fjm_runtime.control.references.Reference` (``(5, n)`` per call): the
        ``'sine'`` of :func:`~fjm_runtime.control.references.make_reference`, or a
        :class:`~fjm_runtime.control.references.PoseSequence`."""
        from .control.references import PoseSequence, make_reference
        if self.kind == "poses":
            return PoseSequence(self.poses, self.durations)
        return make_reference("sine", self.n, amplitude=list(self.amplitude), omega=list(self.omega),
                              offset=list(self.offset), phase=self._phase())

    def start_pose(self) -> np.ndarray:
        """The link angles at ``t = 0``, rad, shape (n,) (the task starts at rest there)."""
        return self.reference()(0.0)[0]

    def _phase(self):
        """The phase as one number when every joint has the same (as design files record it), else a list."""
        phase = [float(v) for v in self.phase]
        return phase[0] if len(set(phase)) == 1 else phase

    def record(self) -> dict:
        """The design file's record of this task (``kind``: the description; lists; ``start`` in words)."""
        if self.kind == "poses":
            body = {"poses": self.poses.tolist(), "durations": self.durations.tolist()}
        else:
            body = {"offset": self.offset.tolist(), "amplitude": self.amplitude.tolist(),
                    "omega": self.omega.tolist(), "phase": self._phase()}
        return {"kind": self.description, **body, "start": START_TEXT[self.start]}


def task_from_manifest(manifest: dict, n: int) -> Optional[Task]:
    """The :class:`Task` of ``manifest["task"]``; None when the model states none."""
    entry = manifest.get("task")
    if not isinstance(entry, dict):
        return None
    kind = entry.get("kind")
    if kind not in ("sines", "poses") or entry.get("start", "rest") not in START_TEXT:
        raise FjmValueError(f"model {manifest.get('model', '?')}: manifest task kind {kind!r} / start "
                            f"{entry.get('start')!r}: expected 'sines' or 'poses' starting at 'rest'; {REDERIVE}")

    def arr(key):
        return None if key not in entry else _frozen(np.array(entry[key], dtype=float))
    keys = ("poses", "durations") if kind == "poses" else ("offset", "amplitude", "omega", "phase")
    fields = {key: arr(key) for key in keys}
    bad = [k for k, v in fields.items() if v is None or not np.all(np.isfinite(v))
           or (k not in ("durations",) and v.shape[-1] != n)]
    if bad:
        raise FjmValueError(f"model {manifest.get('model', '?')}: manifest task {bad[0]} missing, not finite or "
                            f"not of n = {n} per joint; {REDERIVE}")
    return Task(kind=kind, n=n, description=entry.get("description") or f"{kind} of the model file",
                start=entry.get("start", "rest"), **fields)
