"""Reference trajectories for the link positions and their first four derivatives.

Every reference evaluates to an array ``r`` of shape ``(5, n)`` where row ``k``
is the ``k``-th time derivative of the desired link angle of each joint:
``r[0] = y1d = q_d``, ``r[1] = y2d``, ``r[2] = y3d``, ``r[3] = y4d`` and
``r[4] = y4d'`` (the term that enters the sliding-mode law).
"""
from __future__ import annotations

import math

import numpy as np

from ..validation import joint_vector

REFERENCE_KINDS = ("step", "sine", "constant")

# 9th-order "smootherstep": sigma(0) = 0, sigma(1) = 1, derivatives 1..4 vanish at both ends.
_SIGMA = np.polynomial.Polynomial([0, 0, 0, 0, 0, 126, -420, 540, -315, 70])
_SIGMA_DERIVS = [_SIGMA.deriv(k) for k in range(5)]


class Reference:
    """Base class: a desired link trajectory for ``n`` joints.

    Attributes
    ----------
    n : int
        Number of joints.
    """

    n: int

    def __call__(self, t: float) -> np.ndarray:
        """Return the desired trajectory and its derivatives at time ``t``.

        Returns
        -------
        ndarray, shape (5, n)
            Rows are ``q_d, q_d', q_d'', q_d''', q_d''''``.
        """
        raise NotImplementedError

    def sample(self, t) -> np.ndarray:
        """Evaluate on a time grid.

        Parameters
        ----------
        t : array_like, shape (N,)

        Returns
        -------
        ndarray, shape (N, 5, n)
        """
        return np.stack([self(float(tk)) for tk in np.asarray(t, dtype=float).ravel()])

    def derivative_bounds(self) -> np.ndarray:
        """Upper bounds of ``|q_d^(k)|`` over all time, ``k = 0..4``.

        Returns
        -------
        ndarray, shape (5, n)
        """
        raise NotImplementedError


class Constant(Reference):
    """Constant set point ``q_d`` (a step applied at ``t = 0``).

    Parameters
    ----------
    q_d : float or array_like, shape (n,)
        Set point in rad.
    n : int
        Number of joints.
    """

    def __init__(self, q_d, n: int = 1):
        self.n = n
        self.q_d = joint_vector(q_d, n, "q_d")

    def __call__(self, t):
        r = np.zeros((5, self.n))
        r[0] = self.q_d
        return r

    def derivative_bounds(self):
        return np.abs(self(0.0))


class SmoothStep(Reference):
    """Smooth step from ``q0`` to ``q_d`` starting at ``t0`` and lasting ``rise_time``.

    Uses the 9th-order polynomial whose derivatives up to the 4th vanish at both
    ends, so ``y4d'`` is bounded and continuous.

    Parameters
    ----------
    q_d : float or array_like, shape (n,)
        Final angle in rad.
    n : int
        Number of joints.
    q0 : float or array_like, shape (n,)
        Initial angle in rad (default 0).
    rise_time : float
        Duration of the transition in s, > 0.
    t0 : float
        Start time in s, >= 0.
    """

    def __init__(self, q_d, n: int = 1, q0=0.0, rise_time: float = 1.0, t0: float = 0.0):
        self.n = n
        self.q_d = joint_vector(q_d, n, "q_d")
        self.q0 = joint_vector(q0, n, "q0")
        if not (np.isfinite(rise_time) and rise_time > 0):
            raise ValueError(f"rise_time = {rise_time!r}: expected a finite value > 0 s")
        if not (np.isfinite(t0) and t0 >= 0):
            raise ValueError(f"t0 = {t0!r}: expected a finite value >= 0 s")
        self.rise_time = float(rise_time)
        self.t0 = float(t0)

    def __call__(self, t):
        tau = min(max((t - self.t0) / self.rise_time, 0.0), 1.0)
        span = self.q_d - self.q0
        r = np.empty((5, self.n))
        for k in range(5):
            r[k] = span * (_SIGMA_DERIVS[k](tau) / self.rise_time ** k)
        r[0] += self.q0
        if tau in (0.0, 1.0):
            r[1:] = 0.0
        return r

    def sample(self, t):
        t = np.asarray(t, dtype=float).ravel()
        tau = np.clip((t - self.t0) / self.rise_time, 0.0, 1.0)
        r = np.empty((t.size, 5, self.n))
        for k in range(5):
            r[:, k] = np.outer(_SIGMA_DERIVS[k](tau) / self.rise_time ** k, self.q_d - self.q0)
        r[:, 0] += self.q0
        r[(tau <= 0.0) | (tau >= 1.0), 1:] = 0.0
        return r

    def derivative_bounds(self):
        tau = np.linspace(0.0, 1.0, 2001)
        span = np.abs(self.q_d - self.q0)
        b = np.empty((5, self.n))
        b[0] = np.maximum(np.abs(self.q0), np.abs(self.q_d))
        for k in range(1, 5):
            b[k] = span * np.max(np.abs(_SIGMA_DERIVS[k](tau))) / self.rise_time ** k
        return b


class Sinusoid(Reference):
    """Sinusoid ``q_d(t) = offset + amplitude sin(omega t + phase)``.

    Parameters
    ----------
    amplitude : float or array_like, shape (n,)
        Amplitude in rad.
    omega : float or array_like, shape (n,)
        Angular frequency in rad/s, >= 0.
    n : int
        Number of joints.
    offset, phase : float or array_like, shape (n,)
        Offset in rad, phase in rad.
    """

    def __init__(self, amplitude=0.5, omega=1.0, n: int = 1, offset=0.0, phase=0.0):
        self.n = n
        self.amplitude = joint_vector(amplitude, n, "amplitude")
        self.omega = joint_vector(omega, n, "omega")
        if np.any(self.omega < 0):
            raise ValueError(f"omega = {self.omega.tolist()}: expected values >= 0 rad/s")
        self.offset = joint_vector(offset, n, "offset")
        self.phase = joint_vector(phase, n, "phase")

    def __call__(self, t):
        r = np.empty((5, self.n))
        arg = self.omega * t + self.phase
        for k in range(5):
            r[k] = self.amplitude * self.omega ** k * np.sin(arg + k * math.pi / 2)
        r[0] += self.offset
        return r

    def sample(self, t):
        t = np.asarray(t, dtype=float).ravel()
        arg = t[:, None, None] * self.omega + self.phase + (np.arange(5) * math.pi / 2)[None, :, None]
        r = self.amplitude * self.omega ** np.arange(5)[None, :, None] * np.sin(arg)
        r[:, 0] += self.offset
        return r

    def derivative_bounds(self):
        b = np.array([np.abs(self.amplitude) * self.omega ** k for k in range(5)])
        b[0] = np.abs(self.offset) + np.abs(self.amplitude)
        return b


class PoseSequence(Reference):
    """Smooth steps through poses: ``poses[k] -> poses[k+1]`` over ``durations[k]``, then the last pose held.

    Each move is a :class:`SmoothStep` (derivatives 1..4 zero at both ends), the next starting where the
    previous ends; the reference starts at rest at ``poses[0]``.

    Parameters
    ----------
    poses : array_like, shape (k, n)
        Link angles, rad.
    durations : array_like, shape (k - 1,)
        Move times, s, each > 0.
    """

    def __init__(self, poses, durations):
        poses = np.asarray(poses, dtype=float)
        durations = np.asarray(durations, dtype=float).ravel()
        if poses.ndim != 2 or poses.shape[0] < 1 or durations.shape != (poses.shape[0] - 1,):
            raise ValueError(f"poses with shape {poses.shape}, durations with shape {durations.shape}: expected "
                             "(k, n) poses and k - 1 durations")
        self.n = poses.shape[1]
        self.poses = poses
        starts = np.concatenate([[0.0], np.cumsum(durations)])
        self.moves = [SmoothStep(poses[k + 1], self.n, q0=poses[k], rise_time=d, t0=starts[k])
                      for k, d in enumerate(durations)]

    def _move(self, t: float):
        for move in self.moves:
            if t < move.t0 + move.rise_time:
                return move
        return self.moves[-1] if self.moves else Constant(self.poses[0], self.n)

    def __call__(self, t):
        return self._move(float(t))(float(t))

    def derivative_bounds(self):
        if not self.moves:
            return Constant(self.poses[0], self.n).derivative_bounds()
        return np.max([m.derivative_bounds() for m in self.moves], axis=0)


def make_reference(kind: str, n: int = 1, **kwargs) -> Reference:
    """Build a reference by name.

    Parameters
    ----------
    kind : {'step', 'sine', 'constant'}
        ``'step'``: :class:`SmoothStep` (kwargs ``q_d``, ``q0``, ``rise_time``, ``t0``);
        ``'sine'``: :class:`Sinusoid` (``amplitude``, ``omega``, ``offset``, ``phase``);
        ``'constant'``: :class:`Constant` (``q_d``).
    n : int
        Number of joints.

    Raises
    ------
    ValueError
        For an unknown ``kind`` or invalid arguments.
    """
    if kind == "step":
        kwargs.setdefault("q_d", 1.0)
        return SmoothStep(n=n, **kwargs)
    if kind == "sine":
        return Sinusoid(n=n, **kwargs)
    if kind == "constant":
        kwargs.setdefault("q_d", 1.0)
        return Constant(n=n, **kwargs)
    raise ValueError(f"reference = {kind!r}: expected one of {', '.join(REFERENCE_KINDS)}")
