"""Rotors of the complete elastic model: gear-ratio parameters, carried inertias, spin coupling.

The complete model (docs/complete-model.md) mounts rotor ``i`` on body ``i-1``
(the base for ``i = 1``) at joint ``i``'s origin, spinning about joint ``i``'s
axis ``a_i`` with angle ``N_i q_m,i``. Its polar inertia is
``I_a,i = J_m,i / N_i^2``; its mass ``m_r,i`` and transverse inertia ``I_t,i``
are baked numbers. This module holds the per-joint data (:class:`Rotors`), the
gear-ratio parameters (:func:`gear_params`) and the pieces that
:func:`derive.spatial.spatial.make_spatial` adds to the CRBA/RNEA programmes of a
spatial chain:

* :func:`carry_rotors` -- the rotor's mass, transverse inertia and polar
  inertia (for the carried rotation) join body ``i-1``;
* :func:`spin_moments` -- the gyroscopic moment ``(J_m,i / N_i) dq_m,i
  (w_{i-1} x a_i)`` that body ``i-1`` must supply (added to the RNEA forward
  pass's moments, so the backward pass carries it to the joints ``j < i``);
* :func:`coupling_matrix` -- ``S_ji = (J_m,i / N_i) z_j . z_i`` (``j < i``) by
  carrying ``a_i`` down the chain as CRBA carries a force;
* :func:`motor_bias` -- ``(J_m,i / N_i) a_i . dw_{i-1}`` with the angular
  acceleration of the forward pass (``ddq = 0``), the ``(dS/dt)^T dq`` term.

Vectors are in body frames (``B_k``: z = joint ``k``'s axis; ``a_i`` is the
constant third column of ``R0_i`` in ``B_{i-1}``). Pure math: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, List, Optional, Sequence, Tuple

import sympy as sp

from .model_base import Param

__all__ = ["Rotors", "gear_params", "carry_rotors", "spin_moments", "coupling_matrix", "motor_bias",
           "planar_carried"]


@dataclass(frozen=True)
class Rotors:
    """Per-joint rotor data of a complete model, in q order.

    Attributes
    ----------
    gear_ratio : tuple of float
        Defaults of the runtime parameters ``N1..Nn`` (> 0).
    mass : tuple of float
        Rotor masses ``m_r`` (kg, >= 0), baked.
    transverse_inertia : tuple of float
        ``I_t`` (kg m^2, >= 0) about axes through the rotor centre perpendicular
        to its spin axis, baked. :meth:`resolve` fills ``None`` with ``I_a / 2``.
    """

    gear_ratio: Tuple[float, ...]
    mass: Tuple[float, ...]
    transverse_inertia: Tuple[Optional[float], ...]

    def resolve(self, jm: Sequence[float]) -> "Rotors":
        """``I_t = I_a / 2 = J_m / (2 N^2)`` (default ``J_m`` and ``N``) where it is ``None``.

        Parameters
        ----------
        jm : sequence of float, length n
            Default reflected rotor inertias ``J_m``.
        """
        it = tuple(float(jm[i]) / (2.0 * float(self.gear_ratio[i]) ** 2) if v is None else float(v)
                   for i, v in enumerate(self.transverse_inertia))
        return Rotors(tuple(float(v) for v in self.gear_ratio), tuple(float(v) for v in self.mass), it)


def gear_params(ratios: Sequence[float]) -> Tuple[Param, ...]:
    """Parameters ``N1..Nn``: gear ratios (rotor angle = ``N_i q_m,i``), appended after the reduced model's."""
    return tuple(Param(f"N{i + 1}", float(v), f"gear ratio of joint {i + 1} (rotor angle / reflected motor "
                       "angle; > 0)", "1") for i, v in enumerate(ratios))


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _num(v: float) -> sp.Expr:
    v = float(v)
    return sp.Integer(int(v)) if v == int(v) and abs(v) < 2 ** 31 else sp.Float(v)


def _axis(R0) -> List[sp.Expr]:
    return [_num(R0[r, 2]) for r in range(3)]


def carry_rotors(d: Callable, bodies, rotors: Rotors, ia: Sequence[sp.Expr], mass: list, hmom: list,
                 Io: list) -> None:
    """Add rotor ``i``'s mass, ``I_t (1 - a a^T) + I_a a a^T`` and parallel-axis terms to body ``i-1`` (in place).

    Parameters
    ----------
    d : callable (label, expr) -> expr
        Names intermediates in the model's program.
    bodies : sequence of BodyNumerics
        ``bodies[i].p`` is joint ``i + 1``'s origin in body ``i``'s frame, ``bodies[i].R0[:, 2]`` its axis.
    ia : sequence of sympy.Expr, length n
        Polar inertias ``J_m,i / N_i^2``.
    mass, hmom, Io : lists (n) of mass, first moment (3), inertia about the origin (3 x 3)
        Body inertias, updated for bodies ``0..n-2``; rotor 1 rides on the base and changes nothing.
    """
    for i in range(1, len(bodies)):
        b, a, p = i - 1, _axis(bodies[i].R0), [_num(v) for v in bodies[i].p]
        mr, it = _num(rotors.mass[i]), _num(rotors.transverse_inertia[i])
        pp = sum(float(v) ** 2 for v in bodies[i].p)
        for r in range(3):
            for k in range(r, 3):
                aa = a[r] * a[k]
                extra = ia[i] * aa + it * ((1 if r == k else 0) - aa) + mr * ((_num(pp) if r == k else 0) - p[r] * p[k])
                if extra != 0:
                    Io[b][r][k] = Io[b][k][r] = d(f"Ior{i + 1}_{r + 1}{k + 1}", Io[b][r][k] + extra)
        if mr != 0:
            mass[b] = d(f"mr{i + 1}", mass[b] + mr)
            hmom[b] = [d(f"hr{i + 1}{'xyz'[r]}", hmom[b][r] + mr * p[r]) for r in range(3)]


def spin_moments(d: Callable, bodies, coef: Sequence[sp.Expr], dqm, rates, moments: list) -> None:
    """Add ``coef_i dq_m,i (w_{i-1} x a_i)`` to body ``i-1``'s RNEA moment (in place; ``coef_i = J_m,i / N_i``).

    ``rates[b] = (w_b, dw_b)`` are the forward pass's body rates in body frames.
    """
    for i in range(1, len(bodies)):
        b, a = i - 1, _axis(bodies[i].R0)
        wxa = _cross(rates[b][0], a)
        moments[b] = [d(f"Mr{i + 1}{'xyz'[k]}", moments[b][k] + coef[i] * dqm[i] * wxa[k]) for k in range(3)]


def coupling_matrix(d: Callable, bodies, R, coef: Sequence[sp.Expr]) -> sp.Matrix:
    """``S_ji = coef_i (a_i expressed in B_j)_z`` for ``j < i``, zero elsewhere (shape (n, n)).

    ``R[k]`` maps body-``k`` coordinates to body-``k-1`` coordinates.
    """
    n = len(bodies)
    S = sp.zeros(n, n)
    for i in range(1, n):
        v = _axis(bodies[i].R0)  # in B_{i-1}
        for j in reversed(range(i)):
            if j < i - 1:  # carry v from B_{j+1} to B_j
                w = [sp.Add(*[R[j + 1][r][k] * v[k] for k in range(3)]) for r in range(3)]
                v = [d(f"za{i + 1}_{j + 1}{'xyz'[r]}", w[r]) for r in range(3)]
            S[j, i] = d(f"S{j + 1}_{i + 1}", coef[i] * v[2])
    return S


def motor_bias(d: Callable, bodies, coef: Sequence[sp.Expr], rates) -> sp.Matrix:
    """``c_m,i = coef_i a_i . dw_{i-1}`` (``ddq = 0``; zero for ``i = 1``), shape (n, 1)."""
    n = len(bodies)
    c = sp.zeros(n, 1)
    for i in range(1, n):
        a, dw = _axis(bodies[i].R0), rates[i - 1][1]
        c[i] = d(f"cm{i + 1}", coef[i] * sp.Add(*[a[k] * dw[k] for k in range(3)]))
    return c


def planar_carried(m, l, r, inertia, ia, rotors: Rotors, d: Callable):
    """Effective ``m, r, I`` of planar links carrying the rotors (rotor ``i`` at the far end of link ``i-1``).

    The rotor's mass sits at distance ``l_{i-1}`` along link ``i-1``; its polar
    inertia ``ia[i]`` adds to ``I_{i-1}`` (the transverse inertia does not enter
    planar motion). Returns new lists ``(m, r, I)``.
    """
    m, r, inertia = list(m), list(r), list(inertia)
    for i in range(1, len(m)):
        b, mr = i - 1, _num(rotors.mass[i])
        if mr == 0:
            inertia[b] = d(f"Ir{b + 1}", inertia[b] + ia[i])
            continue
        mt = d(f"mr{b + 1}", m[b] + mr)
        rt = d(f"rr{b + 1}", (m[b] * r[b] + mr * l[b]) / mt)
        inertia[b] = d(f"Ir{b + 1}", inertia[b] + m[b] * r[b] ** 2 + mr * l[b] ** 2 + ia[i] - mt * rt ** 2)
        m[b], r[b] = mt, rt
    return m, r, inertia
