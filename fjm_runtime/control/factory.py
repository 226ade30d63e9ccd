"""Controllers by name, and the default gains (:mod:`fjm_runtime.control.defaults`).

>>> import fjm_runtime
>>> from fjm_runtime.control.factory import make_controller, default_delta
>>> from fjm_runtime.control.defaults import DEFAULT_LAM
>>> m = fjm_runtime.load("link1")
>>> ctrl = make_controller("smc", m, {}, lam=DEFAULT_LAM, k_s=1000.0, delta=default_delta(1000.0))
>>> float(ctrl.delta[0])
5.0
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Dict, Mapping, Tuple

from .adaptive import make_adaptive
from .impedance import ImpedanceController, JointImpedanceController
from .laws import SlidingModeController
from .pdg import MotorPDGravityController
from .sensing import SENSING_KINDS
from ..validation import FjmValueError

__all__ = ["CONTROLLER_KINDS", "FULL_SENSED_KINDS", "INTERFACE_OF_LAW", "LAWS", "Law", "REGULATION_KINDS",
           "TORQUE_SENSED_KINDS", "check_law_interface", "make_controller"]


@dataclass(frozen=True)
class Law:
    """How :func:`make_controller` builds one law: ``build(model, nominal_params, **fixed, **defaults
    overridden by the caller's keywords)``, the caller's ``ignored`` keywords dropped first."""

    build: Callable[..., object]
    fixed: Mapping[str, object] = field(default_factory=dict)
    defaults: Mapping[str, object] = field(default_factory=dict)
    ignored: Tuple[str, ...] = ()

    def __call__(self, model, nominal_params, **kwargs):
        kw = {**self.defaults, **{k: v for k, v in kwargs.items() if k not in self.ignored}}
        return self.build(model, nominal_params, **self.fixed, **kw)


#: Every law by name: the tracking laws, then the regulation law ``pdg``.
LAWS: Dict[str, Law] = {
    "smc": Law(SlidingModeController, fixed={"mode": "sat"}),
    "ismc": Law(SlidingModeController, fixed={"integral": True}, defaults={"mode": "sat"}),
    "fl": Law(SlidingModeController, fixed={"mode": "fl"}, ignored=("k_s",)),    # no switching term
    "sign": Law(SlidingModeController, fixed={"mode": "sign"}),
    "adaptive": Law(make_adaptive),
    "pdg": Law(MotorPDGravityController),
    "impedance": Law(ImpedanceController),
    "joint_impedance": Law(JointImpedanceController),
}

#: Regulation laws (set point ``r[0]`` only), also accepted by :func:`make_controller`.
REGULATION_KINDS = ("pdg",)

#: Laws that read the full measurement ``[q; dq; q_m; dq_m; tau_J; dtau_J]`` (``sensing = 'full'``).
FULL_SENSED_KINDS = ("impedance", "joint_impedance")

#: The names :func:`make_controller` accepts for tracking with the sliding-mode family's gains (the command
#: line's ``--controller`` choices); ``make_controller`` also takes :data:`FULL_SENSED_KINDS`.
CONTROLLER_KINDS = tuple(k for k in LAWS if k not in REGULATION_KINDS + FULL_SENSED_KINDS)

#: The command-interface kind each full-sensed law is made for: ``impedance`` outputs the motor torque, ``joint_impedance``
#: the desired link torque without gravity that a joint-torque layer (libfranka's) takes.
INTERFACE_OF_LAW = {"impedance": "motor", "joint_impedance": "joint_torque"}

#: The kinds that accept ``sensing='torque'`` (emitted as ``control_<kind>_tau``).
TORQUE_SENSED_KINDS = ("smc", "ismc", "fl")


def check_law_interface(kind: str, interface, where: str = "--interface") -> None:
    """Refuse, in one line, a law of :data:`INTERFACE_OF_LAW` on a command interface of another kind.

    Parameters
    ----------
    kind : str
        The law (other laws pass).
    interface : CommandInterface
        Its ``kind`` (``'motor'`` or ``'joint_torque'``) and ``name`` are read.
    where : str
        How the error names the interface's origin.

    Raises
    ------
    FjmValueError
        Naming the law, the interface and the valid pairing.
    """
    want = INTERFACE_OF_LAW.get(kind)
    if want is not None and interface.kind != want:
        raise FjmValueError(f"{where} {interface.name} (a {interface.kind} interface) with controller {kind}: "
                            f"{kind} is made for a {want} interface (expected impedance on motor or ideal, "
                            "joint_impedance on joint_torque or franka, or an interface file of that kind)")


def make_controller(kind: str, model, nominal_params, sensing: str = "state", **kwargs) -> SlidingModeController:
    """Build a controller by name.

    Parameters
    ----------
    kind : {'smc', 'ismc', 'fl', 'sign', 'adaptive', 'pdg'}
        ``'smc'``: paper's surface with ``sat``; ``'sign'``: the paper's
        discontinuous law; ``'ismc'``: integral surface with ``sat``; ``'fl'``:
        plain feedback linearization (no switching term, quadruple pole);
        ``'adaptive'``: online stiffness estimate in ``T``, ``alpha``, ``beta``
        (:class:`fjm_runtime.control.adaptive.AdaptiveStiffnessController`; keywords
        ``K_bounds``, ``filter_rate``, ``ls_gain``, ``integral``); ``'pdg'``: motor PD +
        gravity compensation for regulation
        (:class:`fjm_runtime.control.pdg.MotorPDGravityController`; keywords ``k_p``,
        ``k_d``, ``u_max``); ``'impedance'``: motor-side impedance with torque feedback about the
        flatness feedforward, reading ``[q; dq; q_m; dq_m; tau_J; dtau_J]``
        (:class:`fjm_runtime.control.impedance.ImpedanceController`; keywords ``K_p``, ``K_d``, ``K_T``,
        ``K_i``, ``u_max``, ``anti_windup``; ``sensing`` must be left at its default or be ``'full'``);
        ``'joint_impedance'``: link-side joint impedance for a joint-torque interface, its output the
        desired link torque without gravity
        (:class:`fjm_runtime.control.impedance.JointImpedanceController`; keywords ``K_q``, ``D_q``,
        ``K_i``, ``u_max``, ``anti_windup``).
    model, nominal_params, **kwargs
        Passed to :class:`~fjm_runtime.control.laws.SlidingModeController`
        (gains not given take the defaults of :mod:`fjm_runtime.control.defaults`).
    sensing : {'state', 'torque', 'full'}
        ``'full'``: the impedance law's measurement (its only one; the default ``'state'`` means it too
        for that law). ``'state'``: the controller reads the plant state ``x`` (4n). ``'torque'`` (smc,
        ismc, fl): it reads the torque-sensed measurement ``m = [q; dq; tau_J; dtau_J; dq_m]``
        (5n, :func:`~fjm_runtime.control.sensing.torque_measurement`) and runs the emitted
        ``control_<kind>_tau``. Either way ``controller.sensing`` and
        ``controller.measurement_size`` say which, and every method takes that measurement.

    Returns
    -------
    SlidingModeController
    """
    if sensing not in SENSING_KINDS:
        raise ValueError(f"sensing = {sensing!r}: expected one of {', '.join(SENSING_KINDS)}")
    if (sensing == "full" and kind not in FULL_SENSED_KINDS) or (sensing == "torque" and kind in FULL_SENSED_KINDS):
        raise ValueError(f"controller = {kind!r} with sensing = {sensing!r}: sensing = 'full' (the measurement "
                         f"[q; dq; q_m; dq_m; tau_J; dtau_J]) is read by {', '.join(FULL_SENSED_KINDS)} and only by them")
    if sensing == "torque" and kind not in TORQUE_SENSED_KINDS:
        raise ValueError(f"controller = {kind!r} with sensing = 'torque': torque-sensed laws exist for "
                         f"{', '.join(TORQUE_SENSED_KINDS)} (use sensing = 'state')")
    law = LAWS.get(kind)
    if law is None:
        raise ValueError(f"controller = {kind!r}: expected one of "
                         f"{', '.join(CONTROLLER_KINDS + REGULATION_KINDS + FULL_SENSED_KINDS)}")
    if sensing == "torque":
        kwargs["sensing"] = "torque"
    return law(model, nominal_params, **kwargs)
