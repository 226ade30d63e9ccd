"""The command interface of the sampled-data loop: what happens between the law's output and the motor.

The sensor model (:mod:`fjm_runtime.sim.sensor`) says what the controller measures; the
:class:`CommandInterface` says what its output commands and what the robot does with it before the
motor torque ``u`` reaches the plant. Two kinds:

``motor``
    The law commands the MOTOR torque ``u_c`` (N m, link side, Spong's ``u``) through a servo
    drive's current loop, first order: ``du/dt = w_c (u_c - u)``, ``w_c = 2 pi current_bandwidth_hz``.
    Series-elastic actuators, DLR-type drives and arms in current mode (Kinova) take this command.
    An optional torque-rate limit acts on ``u_c`` at the sample rate (none unless a file sets one).

``joint_torque``
    The vendor layer of a torque-controlled arm (Franka, KUKA FRI torque overlay, Kinova torque
    mode). The law commands a desired LINK-side joint torque ``tau_d`` WITHOUT gravity. Once per
    sample the robot low-passes it and limits its rate, each against its echo of the last command
    ``c_{k-1}`` (libfranka 0.15, ``lowpassFilter`` then ``limitRate``)::

        f_k = alpha tau_d + (1 - alpha) c_{k-1},   alpha = T / (T + 1 / (2 pi lowpass_cutoff_hz))
        c_k = clip(f_k, c_{k-1} - R T, c_{k-1} + R T)

    (``alpha = 0.386`` at 1 kHz and 100 Hz), adds the NOMINAL gravity ``g(q)`` of the controller's
    model, and its own joint-torque loop drives the motor at the plant's substeps (Albu-Schaeffer,
    Ott, Hirzinger, "A unified passivity-based control framework for position, torque and
    impedance control of flexible joint robots", IJRR 26(1), 2007, eq. 14 without the feedforward
    of ``J_m``)::

        u_c = (1 + K_T) (c_k + g(q)) - K_T tau_J - D_T dtau_J

    with ``tau_J``, ``dtau_J`` the robot's own torque sensor (the TRUE spring torque and its rate)
    and ``q`` its link encoder, then the same current loop. ``K_T > 0`` makes the motor look
    lighter (``J_m / (1 + K_T)``), ``-1 < K_T < 0`` heavier; ``D_T`` (s) damps the spring torque.

The current loop is integrated exactly over each plant substep ``h`` with the command held:
``u_{j+1} = u_c + (u_j - u_c) e^{-w_c h}``; the plant's RK4 substep takes the exact mean of ``u``
over the substep, ``u_c + (u_j - u_c) (1 - e^{-w_c h}) / (w_c h)``. The motor command is clipped
at the controller's torque limit ``u_max`` (the design's limit, from the model's effort limits).

Presets (:data:`PRESETS`): ``motor`` (the default), ``ideal`` (no lag, no limit beyond ``u_max``:
the former loop), ``joint_torque`` (libfranka's filter, no rate limit, ``K_T = D_T = 0``) and
``franka`` (libfranka's numbers with the 1 N m per tick limit on). A user states their own in a
TOML file (:func:`load_interface_file`, format in docs/simulation.md); :func:`interface_from_spec`
takes either.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Sequence, Union

import numpy as np

from ..validation import FjmValueError
from .preset_file import read_preset_file

__all__ = ["CURRENT_BANDWIDTH_HZ", "KINDS", "PRESETS", "CommandInterface", "gravity_function", "interface_from_record",
           "interface_from_spec", "load_interface_file"]

#: The kinds of command: motor torque through a current loop, or a vendor's joint-torque layer.
KINDS = ("motor", "joint_torque")

#: The default closed-loop bandwidth of the servo drive's current (torque) loop, Hz: industrial servo drives
#: close their current loop with a bandwidth of the order of 1-4 kHz; 2 kHz is the lag the torque-sensed
#: prototypes assumed (docs/simulation.md). A typical value, not a datasheet's: an arm's own goes in a file.
CURRENT_BANDWIDTH_HZ = 2000.0

Level = Union[float, Sequence[float]]

_FIELDS_WITH_INF = ("current_bandwidth_hz", "lowpass_cutoff_hz", "torque_rate_limit")


def _positive_or_inf(value, name: str) -> Level:
    """A scalar or per-joint value > 0 (``inf`` allowed: none)."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        a = np.array(np.nan)
    if a.ndim > 1 or a.size == 0 or np.any(np.isnan(a)) or np.any(a <= 0):
        raise FjmValueError(f"CommandInterface.{name} = {value!r}: expected a value > 0 (a scalar or one per "
                            "joint; inf: none)")
    return float(a) if a.ndim == 0 else tuple(a.tolist())


def _finite(value, name: str, low: float, strict: bool) -> Level:
    """A finite scalar or per-joint value above ``low`` (``strict``: ``> low``, else ``>= low``)."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        a = np.array(np.nan)
    ok = a.ndim <= 1 and a.size > 0 and np.all(np.isfinite(a)) and np.all(a > low if strict else a >= low)
    if not ok:
        raise FjmValueError(f"CommandInterface.{name} = {value!r}: expected a finite value {'>' if strict else '>='} "
                            f"{low:g} (a scalar or one per joint)")
    return float(a) if a.ndim == 0 else tuple(a.tolist())


def _per_joint(value, n: int, name: str, where: str) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    a = np.broadcast_to(a, (n,)).copy() if a.ndim == 0 else a
    if a.shape != (n,):
        raise FjmValueError(f"interface {where!r}: {name} has {a.size} values; expected 1 or {n} (one per joint of "
                            "this model; give a file with yours)")
    return a


@dataclass(frozen=True)
class CommandInterface:
    """What the law's output commands, and the robot's layer between it and the motor torque.

    Attributes
    ----------
    kind : {'motor', 'joint_torque'}
        ``'motor'``: the law's output is the motor torque command; ``'joint_torque'``: a desired
        link-side torque without gravity, through the vendor layer (module docstring).
    current_bandwidth_hz : float
        Closed-loop bandwidth of the current loop, Hz (``inf``: none, the torque is applied at once).
    torque_rate_limit : float or tuple of n floats
        Largest change of the command per second, N m/s (``inf``: none): ``|c_k - c_{k-1}| <= R T``.
    lowpass_cutoff_hz : float
        ``joint_torque`` only: the cutoff of the vendor's first-order command filter, Hz (``inf``: none).
    K_T : float or tuple of n floats
        ``joint_torque`` only: the inner loop's torque-feedback gain (> -1, dimensionless).
    D_T : float or tuple of n floats
        ``joint_torque`` only: the inner loop's torque-rate gain, s (>= 0).
    name : str
        The preset or file it came from.
    """

    kind: str = "motor"
    current_bandwidth_hz: float = CURRENT_BANDWIDTH_HZ
    torque_rate_limit: Level = math.inf
    lowpass_cutoff_hz: float = math.inf
    K_T: Level = 0.0
    D_T: Level = 0.0
    name: str = "custom"

    def __post_init__(self):
        if self.kind not in KINDS:
            raise FjmValueError(f"CommandInterface.kind = {self.kind!r}: expected 'motor' or 'joint_torque'")
        for name in _FIELDS_WITH_INF:
            object.__setattr__(self, name, _positive_or_inf(getattr(self, name), name))
        for name in ("current_bandwidth_hz", "lowpass_cutoff_hz"):
            if not isinstance(getattr(self, name), float):
                raise FjmValueError(f"CommandInterface.{name}: expected one value in Hz (a scalar)")
        object.__setattr__(self, "K_T", _finite(self.K_T, "K_T", -1.0, True))
        object.__setattr__(self, "D_T", _finite(self.D_T, "D_T", 0.0, False))
        if self.kind == "motor" and (math.isfinite(self.lowpass_cutoff_hz) or np.any(np.asarray(self.K_T) != 0)
                                     or np.any(np.asarray(self.D_T) != 0)):
            raise FjmValueError("CommandInterface: lowpass_cutoff_hz, K_T and D_T belong to kind = "
                                "'joint_torque' (the vendor layer); a 'motor' interface has none")
        if not isinstance(self.name, str) or not self.name:
            raise FjmValueError(f"CommandInterface.name = {self.name!r}: expected a non-empty string")

    # -- presets ----------------------------------------------------------------------------------

    @classmethod
    def motor(cls) -> "CommandInterface":
        """Motor torque through a 2 kHz current loop (:data:`CURRENT_BANDWIDTH_HZ`), no rate limit."""
        return cls(name="motor")

    @classmethod
    def ideal(cls) -> "CommandInterface":
        """Motor torque applied at once: no lag, no limit beyond the law's ``u_max`` (an ideal actuator)."""
        return cls(current_bandwidth_hz=math.inf, name="ideal")

    @classmethod
    def joint_torque(cls) -> "CommandInterface":
        """A vendor joint-torque layer: libfranka's 100 Hz command filter, no rate limit, ``K_T = D_T = 0``
        (the robot's torque loop passes the command through), the 2 kHz current loop."""
        return cls(kind="joint_torque", lowpass_cutoff_hz=100.0, name="joint_torque")

    @classmethod
    def franka(cls) -> "CommandInterface":
        """libfranka's layer (0.15 source, defaults of the Panda's 0.9.x): 100 Hz first-order filter
        (``kDefaultCutoffFrequency``), 1000 N m/s rate limit (``kMaxTorqueRate``, 1 N m per 1 ms tick),
        gravity added by the robot; the inner loop's gains are not published: ``K_T = -0.7`` on joints
        5-7 (their motors look 3.3x heavier, which moves the motor-spring mode below the 1 kHz
        loop's reach) and 0 on joints 1-4, ``D_T = 7e-3`` s, the values with which a modelled Franka
        layer held the Panda (docs/simulation.md); the 2 kHz current loop. For 7 joints."""
        return cls(kind="joint_torque", torque_rate_limit=1000.0, lowpass_cutoff_hz=100.0,
                   K_T=(0.0, 0.0, 0.0, 0.0, -0.7, -0.7, -0.7), D_T=7e-3, name="franka")

    # -- what the sample step reads ----------------------------------------------------------------

    def rate_limits(self, n: int) -> np.ndarray:
        """The command's rate limit per joint, N m/s, shape (n,) (``inf``: none)."""
        return _per_joint(self.torque_rate_limit, n, "torque_rate_limit", self.name)

    def has_rate_limit(self) -> bool:
        """True when some joint's command is rate limited."""
        return bool(np.any(np.isfinite(np.asarray(self.torque_rate_limit))))

    def torque_gains(self, n: int):
        """``(K_T, D_T)`` per joint, each shape (n,)."""
        return _per_joint(self.K_T, n, "K_T", self.name), _per_joint(self.D_T, n, "D_T", self.name)

    def lowpass_alpha(self, T: float) -> float:
        """libfranka's filter gain ``T / (T + 1 / (2 pi f_c))`` at the period ``T`` (1.0: no filter)."""
        if not math.isfinite(self.lowpass_cutoff_hz):
            return 1.0
        return T / (T + 1.0 / (2.0 * math.pi * self.lowpass_cutoff_hz))

    def is_ideal(self) -> bool:
        """True for a motor torque applied at once with no rate limit (the loop without an interface)."""
        return self.kind == "motor" and not math.isfinite(self.current_bandwidth_hz) and not self.has_rate_limit()

    def with_rate_limit(self, rate) -> "CommandInterface":
        """The same interface with another rate limit (N m/s; ``inf`` or None: none)."""
        return replace(self, torque_rate_limit=math.inf if rate is None else rate)

    def as_dict(self) -> dict:
        """The fields as plain JSON values (``inf`` as ``None``); :meth:`from_dict` inverts it."""
        out = {}
        for k in self.__dataclass_fields__:
            v = getattr(self, k)
            if k in _FIELDS_WITH_INF:
                v = [None if not math.isfinite(x) else x for x in v] if isinstance(v, tuple) else \
                    (None if not math.isfinite(v) else v)
            out[k] = list(v) if isinstance(v, tuple) else v
        return out

    @classmethod
    def from_dict(cls, fields: dict, where: str = "interface") -> "CommandInterface":
        """A CommandInterface from :meth:`as_dict` output (or a design file's ``interface`` record)."""
        if not isinstance(fields, dict):
            raise FjmValueError(f"{where}: expected a table of interface fields, got {type(fields).__name__}")
        unknown = sorted(set(fields) - set(cls.__dataclass_fields__))
        if unknown:
            raise FjmValueError(f"{where}: unknown field(s) {unknown}; expected among "
                                f"{sorted(cls.__dataclass_fields__)}")
        kw = dict(fields)
        for k in _FIELDS_WITH_INF:
            if k in kw:
                v = kw[k]
                kw[k] = [math.inf if x is None else x for x in v] if isinstance(v, list) else \
                    (math.inf if v is None else v)
        kw = {k: tuple(v) if isinstance(v, list) else v for k, v in kw.items()}
        try:
            return cls(**kw)
        except (FjmValueError, TypeError) as exc:
            raise FjmValueError(f"{where}: {exc}") from None


#: Preset constructors by name (``fjm ... --interface NAME``).
PRESETS = {"motor": CommandInterface.motor, "ideal": CommandInterface.ideal,
           "joint_torque": CommandInterface.joint_torque, "franka": CommandInterface.franka}


def load_interface_file(path) -> CommandInterface:
    """A CommandInterface from a TOML file: optional ``preset = NAME`` as the base, then field overrides.

    Keys are the :class:`CommandInterface` fields (``kind``, ``current_bandwidth_hz``,
    ``torque_rate_limit``, ``lowpass_cutoff_hz``, ``K_T``, ``D_T``) in SI units (frequencies in Hz,
    rates in N m/s); ``"inf"`` means none; a per-joint value is a number or a list with one per
    joint. ``name`` defaults to the file's stem.

    Raises
    ------
    FjmValueError
        One line naming the file and the key.
    """
    p, base, data = read_preset_file(path, "interface file", PRESETS, "motor")
    for k, v in data.items():
        if k in ("kind", "name"):
            continue
        if isinstance(v, str) and k in _FIELDS_WITH_INF:
            if v.strip().lower() not in ("inf", "none"):
                raise FjmValueError(f"interface file {p}: {k} = {v!r}; expected a number or 'inf'")
            data[k] = None
            continue
        vals = v if isinstance(v, list) else [v]
        if not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in vals):
            raise FjmValueError(f"interface file {p}: {k} = {v!r}; expected a number or a list of numbers")
    base.update(data)
    return CommandInterface.from_dict(base, where=f"interface file {p}")


def interface_from_spec(spec, what: str = "--interface") -> CommandInterface:
    """A preset name (:data:`PRESETS`), a TOML file path, or a CommandInterface (returned as is).

    ``what`` names the argument in the error (e.g. ``'--interface'``); None gives the default ``motor``.
    """
    if spec is None:
        return CommandInterface.motor()
    if isinstance(spec, CommandInterface):
        return spec
    if str(spec) in PRESETS:
        return PRESETS[str(spec)]()
    if str(spec).endswith(".toml") or "/" in str(spec):
        return load_interface_file(spec)
    raise FjmValueError(f"{what} {spec!r}: expected a preset among {sorted(PRESETS)} or a .toml interface file")


def interface_from_record(record: dict, where: str = "design") -> CommandInterface:
    """The interface a design record was made for.

    Its ``interface`` table (or preset name, or file) when it has one; an older record states only its sensor's
    ``torque_rate_limit`` (the rate limit lived in the sensor model then): the default ``motor``
    interface with that rate limit (none when it is null or absent).
    """
    given = record.get("interface")
    if isinstance(given, str):
        return interface_from_spec(given, what=f"{where}: interface")
    if given is not None:
        return CommandInterface.from_dict(given, where=f"{where}: interface")
    rate = (record.get("sensor") or {}).get("torque_rate_limit")
    if isinstance(rate, list):
        rate = [math.inf if x is None else x for x in rate]
        rate = tuple(rate) if len(rate) > 1 else rate[0]
    try:
        return CommandInterface.motor().with_rate_limit(rate)
    except FjmValueError as exc:
        raise FjmValueError(f"{where}: sensor: {exc}") from None


_GRAVITY: dict = {}


def gravity_function(model):
    """The model's gravity torque ``g(q) = dV/dq`` as a CasADi Function ``(q (n), p) -> g (n)``, N m.

    The gradient of the model's total energy (``energy`` Function) with respect to the link angles at
    rest with the springs undeflected (``x = [q; 0; q; 0]``, the motor angles held): kinetic and spring
    terms vanish there, so it is the potential's gradient, for reduced and complete models alike.
    Built once per model object.
    """
    hit = _GRAVITY.get(id(model))
    if hit is not None and hit[0] is model:
        return hit[1]
    import casadi as ca
    fns = getattr(model, "functions", None) or {}
    energy = fns.get("energy") if hasattr(fns, "get") else None
    if energy is None:
        raise FjmValueError(f"interface joint_torque: model {getattr(model, 'name', '?')!r} has no energy function "
                            "to compute the gravity the robot adds")
    n, nx = int(model.n), int(model.nx)
    x, p, q = ca.SX.sym("x", nx), ca.SX.sym("p", energy.size1_in(1)), ca.SX.sym("q", n)
    e_fn = energy.expand() if energy.is_a("MXFunction") else energy
    grad = ca.Function("dE", [x, p], [ca.gradient(e_fn(x, p), x)[0:n]])
    rest = ca.vertcat(q, ca.SX.zeros(n), q, ca.SX.zeros(nx - 3 * n))
    fn = ca.Function(f"fjm_gravity_{getattr(model, 'name', 'model')}", [q, p], [ca.cse(grad(rest, p))],
                     ["q", "p"], ["g"])
    _GRAVITY[id(model)] = (model, fn)
    return fn
