"""Sensor model of the sampled-data loop: per-signal Gaussian noise, encoder quantization, dtau_J mode.

The noise of a run is generated once, before the run, by :func:`standard_normals` (a
counter-based generator: the number for sample ``k`` and channel ``c`` depends only on
``(seed, k, c)``), scaled by the per-signal standard deviations (:func:`noise_array`) and
passed to the sample step as an input row per sample, so every backend (python, casadi,
compiled, and a batch engine written in C) sees the same numbers.

Channels: signal block ``b`` times ``n`` plus joint ``i`` (0-based), with the blocks
:data:`SIGNALS` = ``q, dq, q_m, dq_m, tau_J, dtau_J`` (b = 0..5). The noise row of a sample
has the layout of the controller's measurement: ``[q; dq; q_m; dq_m]`` (4n) for state
sensing (channels 0..4n-1) and ``[q; dq; tau_J; dtau_J; dq_m]`` (5n) for torque sensing
(channel blocks 0, 1, 4, 5, 3), so a signal gets the same noise whichever sensing is used.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Sequence, Tuple, Union

import numpy as np

from ..validation import FjmValueError

__all__ = ["DTAU_MODES", "SIGNALS", "SensorModel", "measurement_blocks", "noise_array", "splitmix64",
           "standard_normals"]

#: Signal blocks of the noise channels, in channel order.
SIGNALS = ("q", "dq", "q_m", "dq_m", "tau_J", "dtau_J")

#: How dtau_J reaches the controller: measured (with its own noise) or a filtered difference of tau_J.
DTAU_MODES = ("measured", "filtered")

_MASK = (1 << 64) - 1
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MUL1 = np.uint64(0xBF58476D1CE4E5B9)
_MUL2 = np.uint64(0x94D049BB133111EB)

Level = Union[float, Sequence[float]]


def measurement_blocks(sensing: str) -> Tuple[str, ...]:
    """Signal names of the measurement blocks (n entries each) for ``'state'`` or ``'torque'`` sensing."""
    if sensing == "state":
        return ("q", "dq", "q_m", "dq_m")
    if sensing == "torque":
        return ("q", "dq", "tau_J", "dtau_J", "dq_m")
    raise FjmValueError(f"sensing = {sensing!r}: expected 'state' or 'torque'")


def splitmix64(x) -> np.ndarray:
    """The splitmix64 finaliser on unsigned 64-bit integers (element-wise, wrapping arithmetic).

    ``z = x + 0x9E3779B97F4A7C15; z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EB; return z ^ (z >> 31)`` (all mod 2^64).
    """
    z = np.asarray(x, dtype=np.uint64) + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _MUL1
    z = (z ^ (z >> np.uint64(27))) * _MUL2
    return z ^ (z >> np.uint64(31))


def standard_normals(seed: int, n_samples: int, channels: Sequence[int]) -> np.ndarray:
    """Standard normal numbers ``N[k, j]`` for samples ``k = 0..n_samples-1`` and ``channels[j]``.

    The algorithm, bit for bit (``splitmix64`` as :func:`splitmix64`, all integers unsigned
    64-bit with wrap-around, ``^`` exclusive or)::

        key  = splitmix64(seed)
        h_k  = splitmix64(key ^ k)                      # k: sample index
        a    = splitmix64(h_k ^ (2 c))                  # c: channel index
        b    = splitmix64(h_k ^ (2 c + 1))
        u1   = ((a >> 11) + 0.5) * 2^-53                # in (0, 1), exact in double
        u2   = ((b >> 11) + 0.5) * 2^-53
        N    = sqrt(-2 log(u1)) * cos(2 pi u2)          # Box-Muller, cosine branch only

    ``log``, ``sqrt`` and ``cos`` are the C library's double functions (numpy's agree with
    glibc's to the last bit or one ulp; the noise enters the loop scaled by the levels).

    Parameters
    ----------
    seed : int
        0 <= seed < 2^64.
    n_samples : int
    channels : sequence of int
        Channel indices (see the module docstring).

    Returns
    -------
    ndarray, shape (n_samples, len(channels))
    """
    key = splitmix64(np.array([int(seed) & _MASK], dtype=np.uint64))[0]
    k = np.arange(int(n_samples), dtype=np.uint64)[:, None]
    c = np.asarray(channels, dtype=np.uint64)[None, :]
    h = splitmix64(key ^ k)
    a = splitmix64(h ^ (np.uint64(2) * c))
    b = splitmix64(h ^ (np.uint64(2) * c + np.uint64(1)))
    scale = 2.0 ** -53
    u1 = ((a >> np.uint64(11)).astype(np.float64) + 0.5) * scale
    u2 = ((b >> np.uint64(11)).astype(np.float64) + 0.5) * scale
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * math.pi * u2)


def _level(value, name: str) -> Level:
    a = np.asarray(value, dtype=float)
    if a.ndim > 1 or not np.all(np.isfinite(a)) or np.any(a < 0):
        raise FjmValueError(f"SensorModel.{name} = {value!r}: expected a finite level >= 0 "
                            "(a scalar or one per joint)")
    return float(a) if a.ndim == 0 else tuple(a.tolist())


@dataclass(frozen=True)
class SensorModel:
    """What the controller measures, and how badly.

    Attributes
    ----------
    q, dq, q_m, dq_m, tau_J, dtau_J : float or tuple of n floats
        Standard deviation of the additive Gaussian noise on each signal (rad, rad/s,
        rad, rad/s, N m, N m/s); ``dtau_J`` is used only with ``dtau_mode='measured'``.
    q_quant, q_m_quant : float
        Encoder quantization step of ``q`` and ``q_m`` in rad (0: none); the measured value
        is ``step * floor((true + noise) / step + 0.5)``.
    dtau_mode : {'measured', 'filtered'}
        ``'filtered'``: ``dtau_J`` is the first-order filtered difference of the measured
        ``tau_J``, ``d_k = d_{k-1} + a ((tau_k - tau_{k-1}) / T - d_{k-1})`` with
        ``a = 1 - exp(-dtau_cutoff T)``.
    dtau_cutoff : float
        Cutoff of that filter, rad/s (> 0).
    seed : int
        Seed of :func:`standard_normals` (0 <= seed < 2^64).
    """

    q: Level = 0.0
    dq: Level = 0.0
    q_m: Level = 0.0
    dq_m: Level = 0.0
    tau_J: Level = 0.0
    dtau_J: Level = 0.0
    q_quant: float = 0.0
    q_m_quant: float = 0.0
    dtau_mode: str = "measured"
    dtau_cutoff: float = 1000.0
    seed: int = field(default=0)

    def __post_init__(self):
        for name in SIGNALS + ("q_quant", "q_m_quant"):
            object.__setattr__(self, name, _level(getattr(self, name), name))
        for name in ("q_quant", "q_m_quant"):
            if not isinstance(getattr(self, name), float):
                raise FjmValueError(f"SensorModel.{name}: expected one quantization step in rad (a scalar)")
        if self.dtau_mode not in DTAU_MODES:
            raise FjmValueError(f"SensorModel.dtau_mode = {self.dtau_mode!r}: expected 'measured' or 'filtered'")
        if not (np.isfinite(self.dtau_cutoff) and self.dtau_cutoff > 0):
            raise FjmValueError(f"SensorModel.dtau_cutoff = {self.dtau_cutoff!r}: expected a finite cutoff > 0 rad/s")
        if int(self.seed) != self.seed or not 0 <= int(self.seed) < 2 ** 64:
            raise FjmValueError(f"SensorModel.seed = {self.seed!r}: expected an integer in [0, 2^64)")

    @classmethod
    def ideal(cls, seed: int = 0) -> "SensorModel":
        """No noise, no quantization, dtau_J measured exactly."""
        return cls(seed=seed)

    @classmethod
    def panda(cls, seed: int = 0) -> "SensorModel":
        """Levels of a torque-sensed arm like the Panda (our choice where no datasheet number exists).

        tau_J 0.05 N m and q 1e-4 rad (the levels of the design study); q_m 1e-4 rad;
        dq and dq_m 1e-3 rad/s (filtered encoder velocities); dtau_J the filtered difference
        of tau_J with a cutoff of 1000 rad/s (its ``dtau_J`` level, 5 N m/s, applies only if
        the mode is switched to ``'measured'``); no quantization.
        """
        return cls(q=1e-4, dq=1e-3, q_m=1e-4, dq_m=1e-3, tau_J=0.05, dtau_J=5.0,
                   dtau_mode="filtered", dtau_cutoff=1000.0, seed=seed)

    def with_seed(self, seed: int) -> "SensorModel":
        """The same sensor with another seed."""
        return replace(self, seed=seed)

    def levels(self, sensing: str, n: int) -> np.ndarray:
        """Noise standard deviations in the measurement layout, shape (4n,) or (5n,)."""
        out = []
        for name in measurement_blocks(sensing):
            level = getattr(self, name)
            if name == "dtau_J" and self.dtau_mode == "filtered":
                level = 0.0
            a = np.broadcast_to(np.asarray(level, dtype=float), (n,)) if np.ndim(level) == 0 \
                else np.asarray(level, dtype=float)
            if a.shape != (n,):
                raise FjmValueError(f"SensorModel.{name} with {a.size} levels: expected 1 or {n} (one per joint)")
            out.append(a)
        return np.concatenate(out)

    def is_ideal(self) -> bool:
        """True when the sensor adds nothing (no noise, no quantization, dtau_J measured)."""
        return (all(np.all(np.asarray(getattr(self, s)) == 0) for s in SIGNALS)
                and self.q_quant == 0 and self.q_m_quant == 0 and self.dtau_mode == "measured")


def noise_array(sensor: SensorModel, sensing: str, n: int, n_samples: int) -> np.ndarray:
    """The scaled noise of a run, one row per sample in the measurement layout.

    Parameters
    ----------
    sensor : SensorModel
    sensing : {'state', 'torque'}
    n : int
        Joints.
    n_samples : int
        Rows (samples ``k = 0..n_samples-1``).

    Returns
    -------
    ndarray, shape (n_samples, 4n) or (n_samples, 5n)
        ``levels * standard_normals(seed, k, channel)``; zeros where a level is 0.
    """
    blocks = measurement_blocks(sensing)
    channels = [SIGNALS.index(b) * n + i for b in blocks for i in range(n)]
    levels = sensor.levels(sensing, n)
    if not np.any(levels):
        return np.zeros((int(n_samples), len(channels)))
    return standard_normals(sensor.seed, n_samples, channels) * levels[None, :]
