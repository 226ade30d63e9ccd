"""Sensor model of the sampled-data loop: noise, encoders, velocity and dtau_J filters.

The noise of a run is generated once, before the run, by :func:`standard_normals` (a
counter-based generator: the number for sample ``k`` and channel ``c`` depends only on
``(seed, k, c)``), scaled by the per-signal standard deviations (:func:`noise_array`) and
passed to the sample step as an input row per sample, so every backend (python, casadi,
compiled, and a batch engine written in C) sees the same numbers.

Channels: signal block ``b`` times ``n`` plus joint ``i`` (0-based), with the blocks
:data:`SIGNALS` = ``q, dq, q_m, dq_m, tau_J, dtau_J`` (b = 0..5). The noise row of a sample
has the layout of the controller's measurement: ``[q; dq; q_m; dq_m]`` (4n) for state
sensing (channels 0..4n-1) and ``[q; dq; tau_J; dtau_J; dq_m]`` (5n) for torque sensing
(channel blocks 0, 1, 4, 5, 3), and ``[q; dq; q_m; dq_m; tau_J; dtau_J]`` (6n) for full sensing (channels
0..6n-1), so a signal gets the same noise whichever sensing is used.
With ``velocity_mode='differentiated'`` a velocity is not measured but computed from its angle, as a
robot computes it: the dq slot carries no noise (dq is the filtered difference of the measured q),
and the dq_m slot carries the noise of the MOTOR ANGLE (channel block 2, level ``q_m``), of which
dq_m is the filtered difference (:func:`noise_slots`).

A :class:`SensorModel` describes what the controller measures and how badly; what its output
commands (the rate limit, a vendor's filter, the current loop) is the command interface's
(:mod:`fjm_runtime.sim.interface`). Presets (:data:`PRESETS`): ``ideal``, ``panda_white`` (white noise on
every signal, velocities included: the former ``panda`` preset, optimistic about velocities) and
``franka_like`` (velocities differentiated from quantized encoders, a torque-sensor offset). A user states their own in a TOML file (:func:`load_sensor_file`, format in
docs/simulation.md); :func:`sensor_from_spec` takes either.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Sequence, Tuple, Union

import numpy as np

from ..validation import FjmValueError
from .preset_file import read_preset_file

__all__ = ["DTAU_MODES", "PRESETS", "SIGNALS", "VELOCITY_MODES", "SensorModel", "linear_noise_levels",
           "load_sensor_file", "measurement_blocks", "noise_array", "noise_slots", "offset_normals",
           "read_noise_levels",
           "sensor_from_spec", "splitmix64", "standard_normals"]

#: Signal blocks of the noise channels, in channel order.
SIGNALS = ("q", "dq", "q_m", "dq_m", "tau_J", "dtau_J")

#: How dtau_J reaches the controller: measured (with its own noise) or a filtered difference of tau_J.
DTAU_MODES = ("measured", "filtered")

#: How dq (and dq_m) reach the controller: measured with their own white noise, or the filtered
#: difference of the measured (noisy, quantized) angle.
VELOCITY_MODES = ("measured", "differentiated")

#: Channel of the per-run constant tau_J offset of joint i: ``OFFSET_CHANNEL + i`` at sample 0
#: (far above the per-sample channels ``6n``, so it shares no number with them).
OFFSET_CHANNEL = 1 << 20

_MASK = (1 << 64) - 1
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MUL1 = np.uint64(0xBF58476D1CE4E5B9)
_MUL2 = np.uint64(0x94D049BB133111EB)

Level = Union[float, Sequence[float]]


def measurement_blocks(sensing: str) -> Tuple[str, ...]:
    """Signal names of the measurement blocks (n entries each) for ``'state'``, ``'torque'`` or ``'full'``
    sensing (``'full'``: every signal a torque-sensed arm reports, in :data:`SIGNALS` order)."""
    if sensing == "state":
        return ("q", "dq", "q_m", "dq_m")
    if sensing == "torque":
        return ("q", "dq", "tau_J", "dtau_J", "dq_m")
    if sensing == "full":
        return SIGNALS
    raise FjmValueError(f"sensing = {sensing!r}: expected 'state', 'torque' or 'full'")


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
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        a = np.array(np.nan)
    if a.ndim > 1 or not np.all(np.isfinite(a)) or np.any(a < 0):
        raise FjmValueError(f"SensorModel.{name} = {value!r}: expected a finite level >= 0 "
                            "(a scalar or one per joint)")
    return float(a) if a.ndim == 0 else tuple(a.tolist())


def _per_joint(value, n: int, name: str) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    a = np.broadcast_to(a, (n,)).copy() if a.ndim == 0 else a
    if a.shape != (n,):
        raise FjmValueError(f"SensorModel.{name} with {a.size} values: expected 1 or {n} (one per joint)")
    return a


@dataclass(frozen=True)
class SensorModel:
    """What the controller measures and how badly.

    Attributes
    ----------
    q, dq, q_m, dq_m, tau_J, dtau_J : float or tuple of n floats
        Standard deviation of the additive white Gaussian noise on each signal (rad, rad/s,
        rad, rad/s, N m, N m/s); ``dtau_J`` is used only with ``dtau_mode='measured'``, ``dq``
        and ``dq_m`` only with ``velocity_mode='measured'``.
    q_quant, q_m_quant : float
        Encoder quantization step of ``q`` and ``q_m`` in rad (0: none); the measured angle
        is ``step * floor((true + noise) / step + 0.5)``.
    dtau_mode : {'measured', 'filtered'}
        ``'filtered'``: ``dtau_J`` is the first-order filtered difference of the measured
        ``tau_J``, ``d_k = d_{k-1} + a ((tau_k - tau_{k-1}) / T - d_{k-1})`` with
        ``a = 1 - exp(-dtau_cutoff T)``.
    dtau_cutoff : float
        Cutoff of that filter, rad/s (> 0).
    velocity_mode : {'measured', 'differentiated'}
        ``'differentiated'``: ``dq`` (and ``dq_m``) are the filtered difference of the measured
        angle, ``v_k = v_{k-1} + a ((theta_k - theta_{k-1}) / T - v_{k-1})`` with
        ``a = 1 - exp(-velocity_cutoff T)``, ``theta`` the noisy, quantized ``q`` (``q_m``).
    velocity_cutoff : float
        Cutoff of the velocity filter, rad/s (> 0).
    tau_J_offset : float or tuple of n floats
        Standard deviation of a constant per-run offset of the torque sensor, N m (drawn once per
        run from the run's seed, :func:`offset_normals`).
    name : str
        The preset or file it came from (reports say which sensor a number is for).
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
    velocity_mode: str = "measured"
    velocity_cutoff: float = 300.0
    tau_J_offset: Level = 0.0
    name: str = "custom"
    seed: int = field(default=0)

    def __post_init__(self):
        for name in SIGNALS + ("q_quant", "q_m_quant", "tau_J_offset"):
            object.__setattr__(self, name, _level(getattr(self, name), name))
        for name in ("q_quant", "q_m_quant"):
            if not isinstance(getattr(self, name), float):
                raise FjmValueError(f"SensorModel.{name}: expected one quantization step in rad (a scalar)")
        if self.dtau_mode not in DTAU_MODES:
            raise FjmValueError(f"SensorModel.dtau_mode = {self.dtau_mode!r}: expected 'measured' or 'filtered'")
        if self.velocity_mode not in VELOCITY_MODES:
            raise FjmValueError(f"SensorModel.velocity_mode = {self.velocity_mode!r}: expected 'measured' or "
                                "'differentiated'")
        for name in ("dtau_cutoff", "velocity_cutoff"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise FjmValueError(f"SensorModel.{name} = {v!r}: expected a finite cutoff > 0 rad/s")
        if not isinstance(self.name, str) or not self.name:
            raise FjmValueError(f"SensorModel.name = {self.name!r}: expected a non-empty string")
        if isinstance(self.seed, bool) or int(self.seed) != self.seed or not 0 <= int(self.seed) < 2 ** 64:
            raise FjmValueError(f"SensorModel.seed = {self.seed!r}: expected an integer in [0, 2^64)")

    # -- presets ----------------------------------------------------------------------------------

    @classmethod
    def ideal(cls, seed: int = 0) -> "SensorModel":
        """No noise, no quantization, dtau_J and velocities measured exactly."""
        return cls(name="ideal", seed=seed)

    @classmethod
    def panda_white(cls, seed: int = 0) -> "SensorModel":
        """White noise on every signal, velocities INCLUDED (the former ``panda`` preset; optimistic).

        tau_J 0.05 N m, q and q_m 1e-4 rad, dq and dq_m 1e-3 rad/s drawn independently of q (a
        real arm differentiates its encoder angle: 1e-4 rad differentiated and filtered is
        0.01-0.08 rad/s, :meth:`franka_like`); dtau_J the filtered difference of tau_J (1000 rad/s);
        no quantization, no offset. Kept because the shipped 1 kHz / d = 1 designs
        were searched with it.
        """
        return cls(q=1e-4, dq=1e-3, q_m=1e-4, dq_m=1e-3, tau_J=0.05, dtau_J=5.0,
                   dtau_mode="filtered", dtau_cutoff=1000.0, name="panda_white", seed=seed)

    @classmethod
    def panda(cls, seed: int = 0) -> "SensorModel":
        """The former name of :meth:`panda_white` (same levels)."""
        return cls.panda_white(seed)

    @classmethod
    def franka_like(cls, seed: int = 0) -> "SensorModel":
        """A torque-sensed arm's interface as a Franka-like robot computes and accepts signals.

        * link angle q: white noise 2e-5 rad on a 20-bit encoder (step 2 pi / 2^20 = 6.0e-6 rad);
        * dq: NOT measured; the first-order filtered difference of the measured q, cutoff 300 rad/s;
        * motor angle q_m (link side): white noise 1e-5 rad on a step of 2 pi / 2^21 (a motor
          encoder seen through the gear); dq_m its filtered difference (state sensing also uses q_m);
        * tau_J: white noise 0.05 N m plus a constant per-run offset of 0.2 N m (standard deviations);
        * dtau_J: the filtered difference of tau_J, cutoff 1000 rad/s (as libfranka's dtau_J).

        libfranka's 1 N m per tick rate limit is the command interface's (``--interface franka``).
        The filtered differences are libfranka's behaviour; the noise levels,
        resolutions and cutoffs are our choice where no datasheet number exists (say so in results).
        """
        return cls(q=2e-5, q_m=1e-5, tau_J=0.05, dtau_J=0.0, q_quant=2 * math.pi / 2 ** 20,
                   q_m_quant=2 * math.pi / 2 ** 21, dtau_mode="filtered", dtau_cutoff=1000.0,
                   velocity_mode="differentiated", velocity_cutoff=300.0, tau_J_offset=0.2,
                   name="franka_like", seed=seed)

    def with_seed(self, seed: int) -> "SensorModel":
        """The same sensor with another seed."""
        return replace(self, seed=seed)

    # -- what the sample step reads ----------------------------------------------------------------

    def levels(self, sensing: str, n: int) -> np.ndarray:
        """Noise standard deviation of each slot of the noise row, shape (4n,) or (5n,) (:func:`noise_slots`)."""
        return noise_slots(self, sensing, n)[1]

    def offsets(self, n: int) -> np.ndarray:
        """The standard deviation of the tau_J offset per joint, N m, shape (n,)."""
        return _per_joint(self.tau_J_offset, n, "tau_J_offset")

    def is_ideal(self) -> bool:
        """True when the sensor adds nothing (no noise, quantization or offset; raw signals)."""
        return (all(np.all(np.asarray(getattr(self, s)) == 0) for s in SIGNALS + ("tau_J_offset",))
                and self.q_quant == 0 and self.q_m_quant == 0 and self.dtau_mode == "measured"
                and self.velocity_mode == "measured")

    def as_dict(self) -> dict:
        """The fields as plain JSON values; :meth:`from_dict` inverts it."""
        return {k: list(v) if isinstance(v, tuple) else v
                for k, v in ((k, getattr(self, k)) for k in self.__dataclass_fields__)}

    @classmethod
    def from_dict(cls, fields: dict, where: str = "sensor") -> "SensorModel":
        """A SensorModel from :meth:`as_dict` output (or a design file's ``sensor`` record).

        A record written before the rate limit moved to the command interface may carry
        ``torque_rate_limit``: it is not the sensor's and is skipped here
        (:func:`fjm_runtime.sim.interface.interface_from_record` reads it).
        """
        if not isinstance(fields, dict):
            raise FjmValueError(f"{where}: expected a table of SensorModel fields, got {type(fields).__name__}")
        fields = {k: v for k, v in fields.items() if k != _MOVED}
        unknown = sorted(set(fields) - set(cls.__dataclass_fields__))
        if unknown:
            raise FjmValueError(f"{where}: unknown field(s) {unknown}; expected among "
                                f"{sorted(cls.__dataclass_fields__)}")
        kw = dict(fields)
        for k, v in kw.items():
            if isinstance(v, list):
                kw[k] = tuple(v)
        try:
            return cls(**kw)
        except FjmValueError as exc:  # a file's key is its field's name, not the Python class's attribute
            raise FjmValueError(f"{where}: {str(exc).replace(cls.__name__ + '.', '')}") from None


#: The field that moved from the sensor model to the command interface.
_MOVED = "torque_rate_limit"

#: Preset constructors by name (``fjm ... --noise NAME``).
PRESETS = {"ideal": SensorModel.ideal, "panda_white": SensorModel.panda_white,
           "franka_like": SensorModel.franka_like}
#: Former names still accepted on the command line.
_ALIASES = {"none": "ideal", "panda": "panda_white"}


#: Largest value of a sensor file's key (noise levels, quantization steps, cutoffs, rate limit): beyond them
#: a sensor measures nothing (a 1 rad angle noise) or the number overflows the loop's products.
SENSOR_FILE_MAX = {"q": (1.0, "rad"), "q_m": (1.0, "rad"), "dq": (1e3, "rad/s"), "dq_m": (1e3, "rad/s"),
                   "tau_J": (1e6, "N m"), "dtau_J": (1e9, "N m/s"), "tau_J_offset": (1e6, "N m"),
                   "q_quant": (1.0, "rad"), "q_m_quant": (1.0, "rad"), "dtau_cutoff": (1e7, "rad/s"),
                   "velocity_cutoff": (1e7, "rad/s"), "torque_rate_limit": (1e12, "N m/s")}


def load_sensor_file(path, seed: int = 0) -> SensorModel:
    """A SensorModel from a TOML file: optional ``preset = NAME`` as the base, then field overrides.

    Keys are the :class:`SensorModel` fields (``q``, ``dq``, ``q_m``, ``dq_m``, ``tau_J``, ``dtau_J``,
    ``q_quant``, ``q_m_quant``, ``dtau_mode``, ``dtau_cutoff``, ``velocity_mode``, ``velocity_cutoff``,
    ``tau_J_offset``, ``seed``) in SI units; a level is a number or a list with one per joint.
    ``name`` defaults to the file's stem. The rate limit is the command interface's: a
    ``torque_rate_limit`` key is a one-line error that says so.

    Raises
    ------
    FjmValueError
        One line naming the file and the key.
    """
    p, base, data = read_preset_file(path, "sensor file", PRESETS, "ideal", make=lambda build: build(seed=seed))
    if _MOVED in data:
        raise FjmValueError(f"sensor file {p}: {_MOVED} moved to the interface file (--interface FILE.toml, "
                            f"key {_MOVED}): the rate limit is the command's, not the sensor's")
    for k, v in data.items():
        if k in ("dtau_mode", "velocity_mode", "name"):
            continue
        vals = v if isinstance(v, list) else [v]
        if not all(x is None or (isinstance(x, (int, float)) and not isinstance(x, bool)) for x in vals):
            raise FjmValueError(f"sensor file {p}: {k} = {v!r}; expected a number or a list of numbers")
        top, unit = SENSOR_FILE_MAX.get(k, (math.inf, ""))
        if not all(x is None or abs(x) <= top for x in vals):
            raise FjmValueError(f"sensor file {p}: {k} = {v!r}; expected 0 <= {k} <= {top:g} {unit} (no physical "
                                "sensor is worse)")
    base.update(data)
    return SensorModel.from_dict(base, where=f"sensor file {p}")


def sensor_from_spec(spec, seed: int = 0, what: str = "noise") -> SensorModel:
    """A preset name (:data:`PRESETS`, or the former names ``none``, ``panda``) or a TOML file path.

    ``what`` names the argument in the error (e.g. ``'--noise'``).
    """
    if isinstance(spec, SensorModel):
        return spec.with_seed(seed)
    name = _ALIASES.get(str(spec), str(spec))
    if name in PRESETS:
        return PRESETS[name](seed=seed)
    if str(spec).endswith(".toml") or "/" in str(spec):
        return load_sensor_file(spec, seed=seed)
    raise FjmValueError(f"{what} {spec!r}: expected a preset among {sorted(PRESETS)} or a .toml sensor file")


def noise_slots(sensor: SensorModel, sensing: str, n: int):
    """``(channels, levels)`` of the noise row: the generator channel and the std of each slot.

    The noise row has the measurement's layout (:func:`measurement_blocks`); slot ``j`` of block
    ``b`` adds ``levels[j] * standard_normals(seed, k, channels[j])`` to it. With
    ``velocity_mode='differentiated'`` the dq slot is silent (level 0) and, for torque sensing, the
    dq_m slot carries the motor ANGLE's noise (channel block ``q_m``, level ``q_m``) that the step
    differentiates; with ``dtau_mode='filtered'`` the dtau_J slot is silent.

    Returns
    -------
    channels : ndarray of int64, shape (nm,)
    levels : ndarray, shape (nm,)
    """
    blocks = measurement_blocks(sensing)
    diff = sensor.velocity_mode == "differentiated"
    chans, levs = [], []
    for name in blocks:
        src, level = name, getattr(sensor, name)
        if name == "dtau_J" and sensor.dtau_mode == "filtered":
            level = 0.0
        if name in ("dq", "dq_m") and diff:
            level = 0.0
            if name == "dq_m" and sensing == "torque":
                src, level = "q_m", sensor.q_m
        chans += [SIGNALS.index(src) * n + i for i in range(n)]
        levs.append(_per_joint(level, n, src))
    return np.asarray(chans, dtype=np.int64), np.concatenate(levs)


def linear_noise_levels(sensor: SensorModel, sensing: str, n: int) -> np.ndarray:
    """:func:`noise_slots` levels with encoder quantization folded in as uniform noise (``step^2 / 12``).

    For a linear analysis of the loop, which cannot differentiate ``floor``: the quantization error
    of an angle that moves by many steps between samples is close to white and uniform. Shape (nm,).
    """
    chans, lev = noise_slots(sensor, sensing, n)
    lev = lev.copy()
    for j, c in enumerate(chans):
        block = SIGNALS[int(c) // n]
        step = sensor.q_quant if block == "q" else sensor.q_m_quant if block == "q_m" else 0.0
        angle_slot = block in ("q", "q_m")
        if step and angle_slot:
            lev[j] = math.sqrt(lev[j] ** 2 + step ** 2 / 12.0)
    return lev


def read_noise_levels(sensor: SensorModel, sensing: str, n: int, T: float) -> np.ndarray:
    """Noise std of each measurement slot as the controller reads it, shape (nm,).

    A measured slot carries its own level (angles with quantization folded in, as
    :func:`linear_noise_levels`). A slot the loop computes as a first-order filtered difference
    ``v_k = v_{k-1} + a ((x_k - x_{k-1}) / T - v_{k-1})`` (differentiated velocities, a filtered dtau_J)
    carries what that filter makes of its source's white noise of std ``s`` (the difference is MA(1)
    with variance ``2 s^2 / T^2`` and lag-one covariance ``-s^2 / T^2``)::

        std = (a s / T) sqrt(2 / (2 - a)),    a = 1 - exp(-cutoff T)

    A constant offset (the tau_J offset) cancels in the difference.
    """
    steps = {"q": sensor.q_quant, "q_m": sensor.q_m_quant}

    def white(signal):  # the signal's own noise, an angle's quantization folded in as uniform (step^2 / 12)
        level = _per_joint(getattr(sensor, signal), n, signal)
        return np.sqrt(level ** 2 + steps.get(signal, 0.0) ** 2 / 12.0)

    out = []
    for name in measurement_blocks(sensing):
        src, cutoff = name, None
        if name in ("dq", "dq_m") and sensor.velocity_mode == "differentiated":
            src, cutoff = name[1:], sensor.velocity_cutoff
        elif name == "dtau_J" and sensor.dtau_mode == "filtered":
            src, cutoff = "tau_J", sensor.dtau_cutoff
        level = white(src)
        if cutoff is not None:
            a = 1.0 - math.exp(-float(cutoff) * float(T))
            level = (a * level / float(T)) * math.sqrt(2.0 / (2.0 - a))
        out.append(level)
    return np.concatenate(out)


def offset_normals(seed: int, n: int) -> np.ndarray:
    """The standard normals of a run's constant tau_J offsets, shape (n,) (sample 0, channels
    ``OFFSET_CHANNEL + i``: independent of every per-sample number)."""
    return standard_normals(seed, 1, [OFFSET_CHANNEL + i for i in range(n)])[0]


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
    channels, levels = noise_slots(sensor, sensing, n)
    if not np.any(levels):
        return np.zeros((int(n_samples), channels.size))
    return standard_normals(sensor.seed, n_samples, channels) * levels[None, :]
