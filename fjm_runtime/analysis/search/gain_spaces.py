"""Each law's gain space for the search of ``fjm design``: its gains, their ranges, its starting grid.

:data:`GAIN_SPACES` maps a law (a :func:`~fjm_runtime.control.factory.make_controller` kind) to a
:class:`GainSpace`: the measurement the law reads, its scalar gains (one value shared by the joints) and
per-joint gains, the range each may take, and the starting candidates the grid stage simulates, computed
from the NOMINAL model. The search (:mod:`fjm_runtime.analysis.search.search`) is the same for every
law: grid, pattern search (each coordinate times and divided by a factor), final check, active set,
re-check on fresh draws.

* ``ismc`` (torque sensing): ``lam`` (scalar, the surface's quadruple pole, 1/s) and per joint ``k_lin``
  (1/s), ``k_s`` (rad/s^4), ``delta`` (rad/s^3). Grid: ``lam`` in 20..160 1/s x ``k_s`` in 200..20000 x
  two boundary-layer slopes, ``k_lin = 5 lam``; every move keeps ``k_lin >= 1.25 lam``.
* ``fl`` (torque sensing): ``lam`` (scalar) and per joint ``k_lin``. Grid: ``lam`` in 10..160 1/s x
  ``k_lin / lam`` in {1, 5}.
* ``impedance`` (full sensing ``[q; dq; q_m; dq_m; tau_J; dtau_J]``): per joint ``K_p`` (N m/rad),
  ``K_d`` (N m s/rad), ``K_T`` (1, in [-0.8, 0]), ``K_i`` (N m/(rad s)). With the link held still the motor
  is ``J_m s^2 + K_d s + K_p + (1 + K_T) K``: it behaves ``1 / (1 + K_T)`` times heavier and its natural
  frequency is ``omega_m = sqrt((K_p + (1 + K_T) K) / J_m)``. Grid: ``K_T`` in {-0.7, -0.35, 0} x ``K_p = c
  (1 + K_T) K`` with ``c`` in {1/6, 1/3, 2/3} x ``K_d = 2 zeta sqrt(J_m (K_p + (1 + K_T) K))`` with ``zeta`` in
  {0.5, 0.7, 1} (damping of that mode), ``K_i = K_p omega_i`` with ``omega_i = 2 pi`` rad/s (a slow link
  integral, 1 Hz: well below the link's bandwidth). ``K_T`` moves act on ``1 + K_T`` (the share of the
  spring torque the motor feels), kept in [0.2, 1].
* ``joint_impedance`` (the joint-torque interface): per joint ``K_q`` (N m/rad), ``D_q`` (N m s/rad), ``K_i``
  (N m/(rad s)). Grid: ``K_q`` in {1/12, 1/6, 1/3} ``K`` x ``D_q`` for damping {0.5, 0.7, 1} of ``D_ii(0)``, ``K_i = 3
  K_q``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Mapping, Optional, Tuple

import numpy as np

from ...drives import drive_indices
from ...validation import FjmValueError

__all__ = ["GAIN_SPACES", "LAYER_SLOPES", "LIN_FLOOR", "LIN_RATIO", "GainSpace", "combine_moves", "gain_space",
           "move_gain"]

#: ``k_lin / lam`` of the ismc grid stage.
LIN_RATIO = 5.0
#: Floor of ``k_lin_j / lam`` (ismc): the sliding variable's own pole no slower than 1.25 x the surface's.
#: Without it the search (2 s screening runs) drove one Panda joint's k_lin to 6 (1/s), and 7 of 200
#: final 10 s runs diverged after 2 s (slow limit cycles through the delay and the boundary layer);
#: on those draws plus the screening ones (22 runs, 10 s), floors of 25 / 50 / 100 left 8 / 1 / 0 diverged.
LIN_FLOOR = 1.25
#: Boundary-layer slopes ``k_s / delta`` of the ismc grid stage (N m per unit of ``s``). The former grid had 200
#: only: on the Panda with velocities differentiated from the encoders (``franka_like``) every such
#: candidate diverged (the layer's slope through the velocity filter's lag); ``lam 40, k_lin 200`` at 25
#: held every joint but the wrist's (4 s, one draw) and the linear analysis puts it at radius 0.983.
LAYER_SLOPES = (25.0, 200.0)


@dataclass(frozen=True)
class GainSpace:
    """One law's gains as the search moves them.

    Attributes
    ----------
    law : str
        The law's name (:func:`~fjm_runtime.control.factory.make_controller` kind).
    sensing : str or None
        The measurement the law reads (``'full'``); None: the search's ``sensing`` setting (state or torque).
    scalar : tuple of str
        Gains shared by every joint (a coordinate is the name).
    per_joint : tuple of str
        Gains with one value per joint (a coordinate is ``(name, joint)``).
    ranges : dict str -> (float, float)
        Bounds of the moved quantity (``gain + offset``); absent: any value > 0.
    offsets : dict str -> float
        A move multiplies ``gain + offset`` (``K_T``: 1, the share ``1 + K_T``).
    grid : callable ``(model, nominal_params (n_params,)) -> list of dict``
        The starting candidates, per-joint gains as lists of length n.
    floor : callable ``(gains) -> gains``, optional
        A coupling kept after every move (ismc: ``k_lin >= LIN_FLOOR lam``).
    """

    law: str
    sensing: Optional[str]
    scalar: Tuple[str, ...]
    per_joint: Tuple[str, ...]
    grid: Callable[..., List[dict]]
    ranges: Mapping[str, Tuple[float, float]] = field(default_factory=dict)
    offsets: Mapping[str, float] = field(default_factory=dict)
    floor: Optional[Callable[[dict], dict]] = None

    def coords(self, n: int) -> list:
        """Every coordinate of the pattern search: the scalar names, then ``(name, joint)`` by name."""
        return list(self.scalar) + [(key, j) for key in self.per_joint for j in range(int(n))]

    def move(self, gains: dict, coord, factor: float) -> dict:
        """``gains`` with ``coord`` moved: ``gain + offset`` multiplied by ``factor`` and clipped to its range."""
        out = {k: (list(v) if isinstance(v, list) else v) for k, v in gains.items()}
        name = coord if isinstance(coord, str) else coord[0]
        off = self.offsets.get(name, 0.0)
        lo, hi = self.ranges.get(name, (0.0, math.inf))
        old = out[name] if isinstance(coord, str) else out[name][coord[1]]
        new = min(max((old + off) * factor, lo), hi) - off
        if isinstance(coord, str):
            out[name] = new
        else:
            out[name][coord[1]] = new
        return self.floor(out) if self.floor is not None else out


def _ismc_floor(g: dict) -> dict:
    g["k_lin"] = [max(v, LIN_FLOOR * g["lam"]) for v in g["k_lin"]]
    return g


def _ismc_grid(model, p_nom) -> List[dict]:
    """The same gains on every joint: ``lam`` x ``k_s`` x the layer's slope, ``k_lin = LIN_RATIO lam``."""
    n = int(model.n)
    return [{"lam": float(lam), "k_lin": [LIN_RATIO * float(lam)] * n, "k_s": [float(ks)] * n,
             "delta": [float(ks) / float(slope)] * n}
            for slope in LAYER_SLOPES for lam in np.geomspace(20.0, 160.0, 4) for ks in np.geomspace(200.0, 20000.0, 5)]


def _fl_grid(model, p_nom) -> List[dict]:
    n = int(model.n)
    return [{"lam": float(lam), "k_lin": [ratio * float(lam)] * n}
            for ratio in (1.0, LIN_RATIO) for lam in np.geomspace(10.0, 160.0, 5)]


#: The impedance grid: torque feedback, ``K_p`` as a share of the spring the motor feels, damping of the motor mode.
IMPEDANCE_K_T = (-0.7, -0.35, 0.0)
IMPEDANCE_SHARES = (1.0 / 6.0, 1.0 / 3.0, 2.0 / 3.0)
IMPEDANCE_DAMPING = (0.5, 0.7, 1.0)
#: Corner of the link integral of the grid, rad/s (``K_i = K_p omega_i``).
IMPEDANCE_OMEGA_I = 2 * math.pi


def _impedance_grid(model, p_nom) -> List[dict]:
    K = p_nom[drive_indices(model, "stiffness")]
    Jm = p_nom[drive_indices(model, "rotor_inertia")]
    out = []
    for k_t in IMPEDANCE_K_T:
        for c in IMPEDANCE_SHARES:
            for zeta in IMPEDANCE_DAMPING:
                K_p = c * (1 + k_t) * K
                K_d = 2 * zeta * np.sqrt(Jm * (K_p + (1 + k_t) * K))
                out.append({"K_p": K_p.tolist(), "K_d": K_d.tolist(), "K_T": [k_t] * int(model.n),
                            "K_i": (IMPEDANCE_OMEGA_I * K_p).tolist()})
    return out


def _joint_impedance_grid(model, p_nom) -> List[dict]:
    K = p_nom[drive_indices(model, "stiffness")]
    inertia = np.diag(model.inertia(np.zeros(model.nx), p_nom))
    return [{"K_q": (share * K).tolist(), "D_q": (2 * zeta * np.sqrt(share * K * inertia)).tolist(),
             "K_i": (3.0 * share * K).tolist()} for share in (1 / 12, 1 / 6, 1 / 3) for zeta in (0.5, 0.7, 1.0)]


#: Every law the search covers.
GAIN_SPACES: Dict[str, GainSpace] = {
    "ismc": GainSpace("ismc", None, ("lam",), ("k_lin", "k_s", "delta"), _ismc_grid, floor=_ismc_floor),
    "fl": GainSpace("fl", None, ("lam",), ("k_lin",), _fl_grid),
    "impedance": GainSpace("impedance", "full", (), ("K_p", "K_d", "K_T", "K_i"), _impedance_grid,
                           ranges={"K_T": (0.2, 1.0)}, offsets={"K_T": 1.0}),
    "joint_impedance": GainSpace("joint_impedance", "full", (), ("K_q", "D_q", "K_i"), _joint_impedance_grid),
}


def gain_space(law: str) -> GainSpace:
    """The :class:`GainSpace` of ``law``; a one-line FjmValueError naming the laws the search covers."""
    if law not in GAIN_SPACES:
        raise FjmValueError(f"design: law {law!r}: the search covers {', '.join(GAIN_SPACES)}")
    return GAIN_SPACES[law]


def move_gain(gains: dict, coord, factor: float) -> dict:
    """ismc ``gains`` with one coordinate (``"lam"`` or ``(name, joint)``) multiplied by ``factor``."""
    return GAIN_SPACES["ismc"].move(gains, coord, factor)


def combine_moves(gains: dict, moves, space: Optional[GainSpace] = None) -> dict:
    """``gains`` with every ``(coord, factor)`` of ``moves`` applied (distinct coordinates; default ismc)."""
    space = GAIN_SPACES["ismc"] if space is None else space
    for coord, factor in moves:
        gains = space.move(gains, coord, factor)
    return gains
