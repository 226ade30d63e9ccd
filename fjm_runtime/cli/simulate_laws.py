"""``fjm simulate`` with the impedance laws (:data:`~fjm_runtime.control.factory.FULL_SENSED_KINDS`).

* :func:`take_law_sensing`: they read the full measurement ``[q; dq; q_m; dq_m; tau_J; dtau_J]``, so the run's
  sensing is ``full`` for them (set when ``--sensing`` is not given; another one refused), and only for them.
* :func:`impedance_controller`: the law with its defaults, or a design's ``K_p``, ``K_d``, ``K_T``, ``K_i`` /
  ``K_q``, ``D_q``, ``K_i`` (the sliding-mode flags ``--lam``, ``--k-s``, ``--delta`` refused).
* :func:`check_run_interface`: the law on the command interface it is made for (``impedance``: motor torque,
  ``joint_impedance``: the joint-torque layer's ``tau_d``).
* :func:`check_set_point`: ``impedance`` regulating to a set point (``--reference constant`` or ``step``) where
  the nominal spring dominates gravity (:func:`~fjm_runtime.control.impedance.regulation_motor_position`).
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from ..control.factory import FULL_SENSED_KINDS, check_law_interface, make_controller
from ..control.impedance import regulation_motor_position
from ..validation import FjmValueError

__all__ = ["check_run_interface", "check_set_point", "impedance_controller", "take_law_sensing"]


def _kind(args, design) -> Optional[str]:
    return design.kind if design is not None else args.controller


def take_law_sensing(args, design) -> None:
    """Set ``args.sensing = 'full'`` for a full-sensed law (from ``--controller`` or the ``--gains`` design) left
    without ``--sensing``; refuse, in one line, ``--sensing`` other than ``full`` for it and ``full`` for any other."""
    kind = _kind(args, design)
    if kind in FULL_SENSED_KINDS:
        if args.sensing not in (None, "full"):
            raise FjmValueError(f"--sensing {args.sensing} with controller {kind}: {kind} reads q, dq, q_m, dq_m, "
                                "tau_J, dtau_J (expected --sensing full, or no --sensing)")
        args.sensing = "full"
    elif args.sensing == "full":
        raise FjmValueError(f"--sensing full with controller {kind or 'smc'}: the full measurement is read by "
                            f"{', '.join(FULL_SENSED_KINDS)} only (expected --sensing state or torque)")


def impedance_controller(m, args, nominal, kind: str, file_gains: dict):
    """The full-sensed law ``kind`` of the run: its default gains, the design's ``file_gains`` over them, the
    run's torque limit ``args.u_max`` unless the design sets ``u_max``.

    Raises
    ------
    FjmValueError
        A sliding-mode gain flag given (one line naming it), or a gain the law refuses.
    """
    given = [flag for flag, v in (("--lam", args.lam), ("--k-s", args.k_s), ("--delta", args.delta)) if v is not None]
    if given:
        raise FjmValueError(f"{', '.join(given)} with controller {kind}: gains of the sliding-mode laws (expected "
                            f"the {kind} law's defaults, or its gains in a --gains file)")
    try:
        return make_controller(kind, m, nominal, sensing="full", **{"u_max": args.u_max, **file_gains})
    except (TypeError, ValueError) as exc:
        raise FjmValueError(f"--gains {args.gains or 'shipped design'}: {str(exc).splitlines()[0]}") from None


def check_run_interface(kind: str, interface, args, design) -> None:
    """Refuse, in one line, a full-sensed law on an interface of another kind (naming where the interface
    came from: ``--interface``, the design, or the default)."""
    if getattr(args, "interface", None) is not None:
        where = "--interface"
    elif design is not None and design.interface is not None:
        where = f"{design.source}: interface"
    else:
        where = "the default interface"
    check_law_interface(kind, interface, where)


def check_set_point(kind: str, m, args, reference, nominal) -> None:
    """Refuse, in one line naming ``--q-d``, ``impedance`` regulating (``--reference constant`` or ``step``) to a
    set point where the fixed-point iteration of the motor-side gravity compensation does not contract."""
    if kind == "impedance" and args.reference in ("constant", "step"):
        q_final = np.asarray(reference(float(args.rise_time + args.duration)), dtype=float)[0]
        regulation_motor_position(m, q_final, nominal, where="--q-d")
