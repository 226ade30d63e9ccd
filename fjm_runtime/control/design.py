"""A design: the gains of one controller and the conditions they were found for, as one typed object.

A design is what ``fjm design`` writes (docs/design-command.md), a shipped design
(``fjm_runtime/control/designed/<model>_<kind>[_tau]_<rate>hz_d<delay>.json``; ``_tau``: torque
sensing) or a hand-written ``{"kind", "gains"}`` file. :class:`Design` reads and writes the same JSON
(every key kept, so older readers still read a saved file), checks it against a model in one line
per error, and gives its task as a reference, the state the task starts from and the controller.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Tuple

import numpy as np

from ..model import command_name
from ..validation import FjmValueError
from .factory import CONTROLLER_KINDS, FULL_SENSED_KINDS, make_controller
from .sensing import SENSING_KINDS

__all__ = ["CONDITION_KEYS", "Design", "design_file_name", "is_real", "task_start"]

#: The conditions a design holds for (a run under others is not the design's).
CONDITION_KEYS = ("model", "kind", "sensing", "rate", "delay", "predict")

# gains a file may set: (sign rule, unit); per-joint unless noted in _SCALAR
_GAIN_RULES = {"lam": ("> 0", "1/s"), "k_s": (">= 0", "rad/s^4"), "delta": ("> 0", "rad/s^3"),
               "k_lin": (">= 0", "1/s"), "u_max": ("> 0", "N m"),
               # the impedance laws' (fjm_runtime.control.impedance): motor PD, torque feedback, link integral
               "K_p": (">= 0", "N m/rad"), "K_d": (">= 0", "N m s/rad"), "K_T": ("> -1", "1"),
               "K_i": (">= 0", "N m/(rad s)"), "K_q": (">= 0", "N m/rad"), "D_q": (">= 0", "N m s/rad")}
# the sign rules: what each allows
_RULE_HOLDS = {"> 0": lambda a: a > 0, ">= 0": lambda a: a >= 0, "> -1": lambda a: a > -1}
_SCALAR = ("lam",)
# keys the law of each kind reads from a design (one of the tuple's names)
_REQUIRED = {"smc": (("lam", "c"), ("k_s",), ("delta",)), "ismc": (("lam", "c"), ("k_s",), ("delta",)),
             "adaptive": (("lam", "c"), ("k_s",), ("delta",)), "sign": (("lam", "c"), ("k_s",)),
             "fl": (("lam", "c"),)}
# the only gains the impedance laws take (their keywords); any other key is refused by name
_ONLY = {"impedance": ("K_p", "K_d", "K_T", "K_i", "u_max", "anti_windup"),
         "joint_impedance": ("K_q", "D_q", "K_i", "u_max", "anti_windup")}
# JSON keys held by typed fields (the field name where it differs from the key)
_FIELD_OF_KEY = {"reference": "task"}
_TYPED_KEYS = ("model", "kind", "sensing", "rate", "delay", "predict", "predict_substeps", "sensor", "noise",
               "interface", "reference", "gains", "params", "meets")
_SHIPPED = "fjm_runtime/control/designed"


def is_real(x) -> bool:
    """A Python int or float, not a bool."""
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def design_file_name(model: str, kind: str, sensing: str, rate: float, delay: int) -> str:
    """The package-data file name of a shipped design (``panda_ismc_tau_1000hz_d1.json``)."""
    return f"{model}_{kind}{'_tau' if sensing == 'torque' else ''}_{int(round(rate))}hz_d{int(delay)}.json"


def task_start(model, reference, start: str, p=None) -> np.ndarray:
    """The state a task starts from: at rest on the reference's first sample ``q_d(0)``, holding gravity
    (motors at ``q + K^-1 G(q)`` for the parameters ``p``) when ``start`` says "holding gravity".

    Parameters
    ----------
    model : Model
    reference : Reference
        The task's reference (``reference(0.0)[0]`` is ``q_d(0)``, shape (n,), rad).
    start : str
        The task's ``start`` entry.
    p : dict or array_like or None
        The NOMINAL parameters the controller holds gravity with (``None``: the model's defaults).

    Returns
    -------
    ndarray, shape (4n,)
        ``[q; 0; q_m; 0]``.
    """
    from ..sim.rest import rest_state
    n = int(model.n)
    q0 = np.asarray(reference(0.0), dtype=float)[0]
    if "holding gravity" in str(start):
        return rest_state(model, q0, model.default_params if p is None else p)
    return np.concatenate([q0, np.zeros(n), q0, np.zeros(n)])


def _check_conditions(d: dict, where: str) -> None:
    """The recorded conditions' types: one line naming the key and the expected range."""
    rate = d.get("rate")
    if rate is not None and not (is_real(rate) and math.isfinite(rate) and rate > 0):
        raise FjmValueError(f"{where}: rate = {rate!r}; expected a control rate > 0 Hz")
    delay = d.get("delay")
    if delay is not None and (isinstance(delay, bool) or not isinstance(delay, int) or delay < 0):
        raise FjmValueError(f"{where}: delay = {delay!r}; expected an integer >= 0 (samples)")
    subs = d.get("predict_substeps")
    if subs is not None and (isinstance(subs, bool) or not isinstance(subs, int) or subs < 1):
        raise FjmValueError(f"{where}: predict_substeps = {subs!r}; expected an integer >= 1 (RK4 substeps per "
                            "sample of the predictor)")
    if d.get("sensing") is not None and d["sensing"] not in SENSING_KINDS:
        raise FjmValueError(f"{where}: sensing = {d['sensing']!r}; expected one of {', '.join(SENSING_KINDS)}")
    for key in ("reference", "params", "sensor"):
        if d.get(key) is not None and not isinstance(d[key], dict):
            raise FjmValueError(f"{where}: {key} = {d[key]!r}; expected a table")


@dataclass(frozen=True)
class Design:
    """The gains of one controller and the conditions they were designed for.

    Attributes
    ----------
    kind : str
        Law, one of :data:`~fjm_runtime.control.factory.CONTROLLER_KINDS` or
        :data:`~fjm_runtime.control.factory.FULL_SENSED_KINDS`.
    gains : dict
        ``lam`` (1/s) or ``c``, ``k_s`` (rad/s^4), ``delta`` (rad/s^3), ``k_lin`` (1/s), ``u_max``
        (N m): scalars or per-joint lists (n,). The impedance laws': ``K_p``, ``K_d``, ``K_T``, ``K_i``
        (``impedance``) or ``K_q``, ``D_q``, ``K_i`` (``joint_impedance``), each optional (the law's default).
    model, sensing, rate, delay, predict : optional
        The conditions (model name; ``'state'``/``'torque'``; control rate, Hz; computation delay,
        samples; delay compensation). ``None``: not recorded (a hand-written file).
    predict_substeps : int, optional
        RK4 substeps per sample of the predictor, chosen by accuracy (:mod:`fjm_runtime.sim.predictor`);
        ``None`` (a file from before the choice): the plant's substeps rule.
    sensor : dict, optional
        The sensor model's fields (:class:`~fjm_runtime.sim.sensor.SensorModel`); ``noise``: its preset name.
    interface : str, optional
        The command interface (``None``: not recorded).
    task : dict, optional
        The task the gains were searched on (JSON key ``reference``): per-joint sines ``offset +
        amplitude sin(omega t + phase)`` (rad, rad, rad/s, rad) and its ``start``.
    params : dict, optional
        The parameter file of the search: ``nominal`` (the controller's nominal values), spreads.
    meets : bool, optional
        The search's verdict: the gains meet every threshold.
    report : dict
        The file's other keys (worst case, margins, draws, ...), kept as read.
    source : str
        How errors name the design (``--gains g.json``, ``shipped design FILE``).
    file : str, optional
        The shipped file it came from.
    """

    kind: str
    gains: Mapping[str, Any]
    model: Optional[str] = None
    sensing: Optional[str] = None
    rate: Optional[float] = None
    delay: Optional[int] = None
    predict: Optional[bool] = None
    predict_substeps: Optional[int] = None
    sensor: Optional[Mapping[str, Any]] = None
    noise: Optional[str] = None
    interface: Optional[str] = None
    task: Optional[Mapping[str, Any]] = None
    params: Optional[Mapping[str, Any]] = None
    meets: Optional[bool] = None
    report: Mapping[str, Any] = field(default_factory=dict)
    source: str = field(default="gains file", compare=False)
    file: Optional[str] = field(default=None, compare=False)
    key_order: Tuple[str, ...] = field(default=(), compare=False, repr=False)

    # -- reading and writing -------------------------------------------------------------------------

    @classmethod
    def from_dict(cls, d, where: str = "gains file") -> "Design":
        """A design from its JSON object; one-line :class:`FjmValueError` naming ``where`` and the key."""
        kinds = CONTROLLER_KINDS + FULL_SENSED_KINDS
        if not isinstance(d, dict) or not isinstance(d.get("gains"), dict) or d.get("kind") not in kinds:
            raise FjmValueError(f"{where}: expected {{\"kind\": one of {', '.join(kinds)}, \"gains\": {{...}}}}")
        _check_conditions(d, where)
        typed = {_FIELD_OF_KEY.get(k, k): d[k] for k in _TYPED_KEYS if k in d}
        report = {k: v for k, v in d.items() if k not in _TYPED_KEYS and k != "file"}
        return cls(**typed, report=report, source=where, file=d.get("file"), key_order=tuple(d))

    @classmethod
    def load(cls, path, where: Optional[str] = None) -> "Design":
        """Read a gains file (``where``: how errors name it, default ``--gains PATH``)."""
        where = where or f"--gains {path}"
        try:
            d = json.loads(Path(path).read_text())
        except (OSError, ValueError) as exc:
            raise FjmValueError(f"{where}: cannot read a JSON object ({exc})") from None
        return cls.from_dict(d, where)

    def as_dict(self) -> Dict[str, Any]:
        """The JSON object (the keys in the order read, new ones after; an unrecorded condition left out
        unless the file it was read from held it as null)."""
        out = {k: getattr(self, _FIELD_OF_KEY.get(k, k)) for k in _TYPED_KEYS}
        out = {k: v for k, v in out.items() if v is not None or k in self.key_order}
        out.update(self.report)
        order = [k for k in self.key_order if k in out] + [k for k in out if k not in self.key_order]
        return {k: out[k] for k in order}

    def save(self, path) -> None:
        """Write the JSON object (indented, as ``fjm design --out``)."""
        Path(path).write_text(json.dumps(self.as_dict(), indent=2, allow_nan=False) + "\n")

    # -- the shipped designs -------------------------------------------------------------------------

    @classmethod
    def shipped(cls, model: str, kind: Optional[str], sensing: str, rate: float, delay: int) -> Optional["Design"]:
        """The shipped design for ``model`` at this rate, delay and sensing, or ``None``.

        ``kind`` None: any controller kind (the first by name when several are shipped); else only
        that kind. The rate must round to the file's integer rate in Hz (``1000.4`` is ``1000``).
        """
        if not (is_real(rate) and math.isfinite(rate) and rate > 0):
            return None
        folder = resources.files(__package__).joinpath("designed")
        # The kinds shipped for the model are read from the files, not parsed from their names: a kind
        # may hold an underscore (joint_impedance), a model name may prefix another's (panda, panda_hd).
        kinds = [kind] if kind is not None else sorted(
            {json.loads(p.read_text(encoding="utf-8")).get("kind") for p in folder.iterdir()
             if p.name.endswith(".json") and p.name.startswith(model + "_")} - {None})
        for k in kinds:
            name = design_file_name(model, k, sensing, rate, delay)
            path = folder.joinpath(name)
            if path.is_file():
                d = json.loads(path.read_text(encoding="utf-8"))
                d["file"] = f"{_SHIPPED}/{name}"
                return cls.from_dict(d, f"shipped design {_SHIPPED}/{name}")
        return None

    @classmethod
    def shipped_for_sensor(cls, model: str, sensor, rate: Optional[float] = None, delay: Optional[int] = None,
                           interface=None) -> Optional["Design"]:
        """The shipped design for ``model`` made with ``sensor`` (a SensorModel; its fields compared, seed and
        name aside), at ``rate`` (Hz) and ``delay`` (samples) when given, for ``interface`` (a CommandInterface:
        its fields compared; None: any of kind ``motor``); of several, the highest rate, then the shortest
        delay, then the first file by name. ``None`` when none is shipped."""
        from ..sim.interface import interface_from_record
        folder = resources.files(__package__).joinpath("designed")
        found = []
        for path in sorted(folder.iterdir(), key=lambda p: p.name):
            if not (path.name.endswith(".json") and path.name.startswith(model + "_")):
                continue
            d = json.loads(path.read_text(encoding="utf-8"))
            if d.get("model") != model or d.get("rate") is None or d.get("delay") is None:
                continue
            d["file"] = f"{_SHIPPED}/{path.name}"
            design = cls.from_dict(d, f"shipped design {_SHIPPED}/{path.name}")
            if rate is not None and not math.isclose(float(design.rate), float(rate), rel_tol=1e-9):
                continue
            if (delay is not None and int(design.delay) != int(delay)) or not design.same_sensor(sensor)[0]:
                continue
            made_for = interface_from_record({"interface": design.interface, "sensor": design.sensor}, design.source)
            if made_for.kind != "motor" if interface is None else made_for.as_dict() != interface.as_dict():
                continue
            found.append(design)
        found.sort(key=lambda dsg: (-float(dsg.rate), int(dsg.delay)))
        return found[0] if found else None

    # -- checks --------------------------------------------------------------------------------------

    def joints(self) -> Optional[int]:
        """How many joints the design is for: its task's length, or (when it names its model) its per-joint
        gains' length; else None (a hand-written file: each gain's length is checked on its own)."""
        task = self.task if isinstance(self.task, dict) else {}
        named = [self.gains.get(k) for k in _GAIN_RULES if k not in _SCALAR] if self.model else []
        for v in [task.get("amplitude")] + named:
            if isinstance(v, list) and len(v) > 1 and not isinstance(v[0], list):
                return len(v)
        return None

    def check(self, model) -> "Design":
        """Refuse, in one line, a design for another arm, a gain that is not a usable number of the right
        sign, or a missing gain of its law; returns the design.

        Raises
        ------
        FjmValueError
            The model mismatch (the design's model and joints vs this one), or the key, the value and
            what was expected, or the missing key.
        """
        n, name, where = int(model.n), str(model.name), self.source
        joints = self.joints()
        if joints is not None and joints != n:
            what = f"model {self.model!r} with {joints} joints" if self.model else f"{joints} joints"
            raise FjmValueError(f"{where}: the gains are for {what}; {name} has {n} joint{'s' * (n != 1)} "
                                f"(expected gains designed for {name}, e.g. from `fjm design {command_name(model)}`)")
        unknown = [k for k in self.gains if k not in _ONLY.get(self.kind, self.gains)]
        if unknown:
            raise FjmValueError(f"{where}: gains.{unknown[0]} is not a gain of the {self.kind} law; expected "
                                f"{', '.join(_ONLY[self.kind])}")
        for key, (rule, unit) in _GAIN_RULES.items():
            if key in self.gains:
                _check_gain(where, key, self.gains[key], rule, unit, n, name)
        for options in _REQUIRED.get(self.kind, ()):
            if not any(k in self.gains for k in options):
                raise FjmValueError(f"{where}: gains.{options[0]} is missing; expected the {self.kind} law's "
                                    f"gains {', '.join(o[0] for o in _REQUIRED[self.kind])} (docs/simulation.md)")
        return self

    def mismatches(self, conditions: Mapping[str, Any]) -> List[str]:
        """Why the design does NOT hold for a run: one short reason per differing condition.

        Parameters
        ----------
        conditions : dict
            The run's ``model``, ``kind``, ``sensing``, ``rate`` (Hz), ``delay``, ``predict``, ``sensor``
            (the run's SensorModel) and, optionally, ``interface`` (the run's CommandInterface).

        Returns
        -------
        list of str
            Empty when the design was made for exactly these conditions; else one reason per condition
            it does not record (a hand-written file) or records otherwise.
        """
        out = [r for r in (_mismatch(k, getattr(self, k), conditions.get(k)) for k in CONDITION_KEYS) if r]
        same, name = self.same_sensor(conditions["sensor"])
        if not same:
            out.append(f"designed with the sensor {name!r}, run with {conditions['sensor'].name!r}")
        if conditions.get("interface") is not None:
            out += self._interface_mismatch(conditions["interface"])
        return out

    def _interface_mismatch(self, interface) -> List[str]:
        """``[reason]`` when ``interface`` (a CommandInterface) is not the one the design was made for (its
        record, or for an older record the ``motor`` interface with the rate limit its sensor states)."""
        from ..sim.interface import interface_from_record
        try:
            design = interface_from_record({"interface": self.interface, "sensor": self.sensor}, self.source)
        except FjmValueError:
            return [f"the design's interface record {self.interface!r} is not readable"]
        a, b = design.as_dict(), interface.as_dict()
        if {k: v for k, v in a.items() if k != "name"} == {k: v for k, v in b.items() if k != "name"}:
            return []
        return [f"designed for the command interface {design.name!r}, run with {interface.name!r}"]

    def same_sensor(self, sensor) -> Tuple[bool, str]:
        """Whether ``sensor`` (a SensorModel) is the design's, and the design's sensor name.

        The recorded ``sensor`` fields are compared (seed and name aside); a design without them is
        compared by its ``noise`` preset name (former names resolved).
        """
        from ..sim.sensor import SensorModel, sensor_from_spec
        label = str(self.noise if self.noise is not None else "?")
        try:
            if isinstance(self.sensor, dict):
                design = SensorModel.from_dict(dict(self.sensor), where="design sensor")
            elif self.noise is not None:
                design = sensor_from_spec(self.noise)
            else:
                return False, "unrecorded"
        except FjmValueError:
            return False, label
        ignore = ("seed", "name")
        a = {k: v for k, v in design.as_dict().items() if k not in ignore}
        b = {k: v for k, v in sensor.as_dict().items() if k not in ignore}
        name = sensor_from_spec(label).name if label in ("panda", "none", "ideal", "panda_white", "franka_like") \
            else label
        return a == b, name

    # -- what the design holds for -------------------------------------------------------------------

    def sensor_model(self):
        """The recorded sensor model (its fields, else its ``noise`` preset; default ideal)."""
        from ..sim.sensor import SensorModel, sensor_from_spec
        if isinstance(self.sensor, dict):
            return SensorModel.from_dict(dict(self.sensor), where=f"{self.source}: sensor")
        return sensor_from_spec(self.noise if self.noise is not None else "ideal", what=f"{self.source}: noise")

    def nominal(self, model) -> Dict[str, float]:
        """The nominal values the design was made for (its ``params.nominal``, from ``fjm design --params``).

        The gains hold for the controller's nominal model they were searched with. Unknown names or
        non-finite values are refused in one line.
        """
        nominal = (self.params or {}).get("nominal") if isinstance(self.params, dict) else None
        out: Dict[str, float] = {}
        for k, v in dict(nominal or {}).items():
            if k not in model.param_names:
                raise FjmValueError(f"gains file params.nominal.{k}: not a parameter of {model.name}; expected one "
                                    f"of {', '.join(model.param_names)}")
            try:
                val = float(v)
            except (TypeError, ValueError):
                val = float("nan")
            if not math.isfinite(val):
                raise FjmValueError(f"gains file params.nominal.{k} = {v!r}: expected a finite number")
            out[k] = val
        return out

    def reference(self, model):
        """The task as a :class:`~fjm_runtime.control.references.Sinusoid` (per-joint sines), or ``None``
        when the design records no task."""
        from .references import Sinusoid
        task = self.task
        if not isinstance(task, dict) or not all(k in task for k in ("offset", "amplitude", "omega")):
            return None
        return Sinusoid(list(task["amplitude"]), list(task["omega"]), n=int(model.n), offset=list(task["offset"]),
                        phase=float(task.get("phase", 0.0)))

    def start_state(self, model, p=None) -> Optional[np.ndarray]:
        """The state the task starts from (:func:`task_start`; ``p``: the nominal parameters, default the
        design's over the model's defaults), or ``None`` when the design records no task.

        Returns
        -------
        ndarray, shape (4n,), or None
        """
        ref = self.reference(model)
        if ref is None:
            return None
        p = model.params_array(self.nominal(model)) if p is None else p
        start = str(self.task.get("start", ""))
        try:
            return task_start(model, ref, start, p)
        except ValueError as exc:  # e.g. a complete model (sim/rest.py assumes the reduced one's K)
            raise FjmValueError(f"{self.source}: the design's start ({start}) cannot be computed for {model.name} "
                                f"({str(exc).splitlines()[0][:80]}); expected a reduced model or another "
                                "reference (sine, step, constant)") from None

    def law_gains(self) -> Dict[str, Any]:
        """The law's gains without ``u_max`` (a caller sets the arm's own limits)."""
        return {k: v for k, v in self.gains.items() if k != "u_max"}

    def controller(self, model, nominal=None, **overrides):
        """The design's controller for ``model`` (its kind, sensing and gains; ``overrides`` replace gains).

        Parameters
        ----------
        model : Model
        nominal : dict, optional
            Nominal parameters (default: the design's ``params.nominal`` over the model's defaults).

        Raises
        ------
        FjmValueError
            One line naming the design when the law refuses its gains.
        """
        self.check(model)
        nominal = self.nominal(model) if nominal is None else nominal
        try:
            return make_controller(self.kind, model, nominal, sensing=self.sensing or "state",
                                   **{**self.gains, **overrides})
        except (TypeError, ValueError) as exc:
            raise FjmValueError(f"{self.source}: {str(exc).splitlines()[0]}") from None


def _check_gain(where: str, key: str, v, rule: str, unit: str, n: int, name: str) -> None:
    """One gain: real numbers, one or ``n`` of them (scalars only for ``lam``), finite, of the rule's sign."""
    shape = "a finite number" if key in _SCALAR else f"a finite number or a list of {n}"
    expected = f"expected {shape} {rule} ({unit})"
    vals = v if (isinstance(v, list) and key not in _SCALAR) else [v]
    if not all(is_real(x) for x in vals) or not vals:
        raise FjmValueError(f"{where}: gains.{key} = {v!r}; {expected}")
    if isinstance(v, list) and len(v) not in (1, n):
        raise FjmValueError(f"{where}: gains.{key} has {len(v)} entries; {expected} for {name}")
    arr = np.asarray(vals, dtype=float)
    if not np.all(np.isfinite(arr)) or not np.all(_RULE_HOLDS[rule](arr)):
        raise FjmValueError(f"{where}: gains.{key} = {v!r}; {expected}")


def _mismatch(key: str, want, got) -> Optional[str]:
    """Why one recorded condition differs from the run's (None: it does not)."""
    if want is None:
        return f"the design records no {key}"
    if key == "rate" and not math.isclose(float(want), float(got), rel_tol=1e-9):
        return f"designed at {float(want):g} Hz, run at {float(got):g} Hz"
    if key == "delay" and int(want) != int(got):
        return f"designed for a delay of {int(want)} sample(s), run with {int(got)}"
    if key == "predict" and bool(want) != bool(got):
        return f"designed {'with' if want else 'without'} prediction, run {'with' if got else 'without'}"
    if key in ("model", "kind", "sensing") and str(want) != str(got):
        return f"designed for {key} {want!r}, run with {got!r}"
    return None

