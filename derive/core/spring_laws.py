"""Spring laws ``tau_J = psi(phi)``, ``phi = q_m - q``, of one joint: linear, cubic, three-segment.

Every law is odd (``psi(-phi) = -psi(phi)``) with ``psi(0) = 0`` and offers the same small interface
(used by :mod:`derive.core.spring` and the emitter):

* ``law(phi)``, ``derivative(k, phi)`` (the k-th derivative), ``potential(phi)`` (``int_0^phi psi``);
* ``substitute(e)``: the abstract ``psi_k`` of the derivation replaced by the law's derivatives;
* ``start_stiffness``: the symbol of ``psi'(0)`` (the model's ``K``, the Newton inverse's start);
* ``parameters``: the runtime parameters of the law, ``kind`` (``"linear"``, ``"cubic"``,
  ``"three_segment"``), ``describe()``;
* ``check(model, values)``: :class:`SpringError` (one line: model, joint, value, unit, deflection)
  unless the coefficients are finite and ``psi' > 0`` on the declared range;
* ``stiffness_bounds(values)``: ``(min, max)`` of ``psi'`` over the declared range (exact).

The three-segment law is the curve harmonic-drive makers publish: stiffness ``K_1`` up to the torque
``T_1``, ``K_2`` up to ``T_2``, ``K_3`` beyond, i.e. deflection breakpoints
``phi_1 = T_1 / K_1`` and ``phi_2 = phi_1 + (T_2 - T_1) / K_2``. The stiffness steps are blended over a
stated width ``w`` (rad) centred on each breakpoint by the quintic smoothstep
``s(t) = 6 t^5 - 15 t^4 + 10 t^3``: ``psi'`` is then C2 (``psi`` C3), and because the blend is
symmetric the curve equals the datasheet's piecewise-linear curve exactly outside the blend windows.
Pure math: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, Tuple

import sympy as sp

from .abstract import derivative_chain, law_derivative, substitute_chain

__all__ = ["SpringError", "LinearSpring", "CubicSpring", "ThreeSegmentSpring", "spring_functions",
           "smooth_ramp", "SPRING_KINDS", "SPRING_PARAMETERS", "LAW_COEFFICIENTS", "TORQUE_SCALE_COEFFICIENTS"]

#: Highest derivative of psi the derivation may ask for (the involutivity brackets reach psi''').
_ORDERS = 5


class SpringError(ValueError):
    """A spring law that is not a spring on its declared range (one line, names joint and deflection)."""


def spring_functions(joint: int) -> Tuple[type, ...]:
    """``(psi, psi', psi'', ...)`` of joint ``joint`` as SymPy function classes (cached).

    ``psi_k(a).diff(a) = psi_{k+1}(a)``, so SymPy's chain rule carries them through any
    Jacobian; each law's :meth:`substitute` replaces them by the law.
    """
    return derivative_chain("psi", joint, _ORDERS, "spring")


def _finite(model: str, joint: int, name: str, value: float, unit: str) -> float:
    if not math.isfinite(value):
        raise SpringError(f"{model} joint {joint}: spring coefficient {name} = {value!r} {unit}; "
                          "expected a finite number")
    return value


def _check_range(model: str, joint: int, r: float) -> None:
    if not (math.isfinite(r) and r > 0):
        raise SpringError(f"{model} joint {joint}: deflection range {r!r} rad; expected a finite number > 0")


def _not_stiff(model: str, joint: int, stiffness: float, phi: float, r: float) -> SpringError:
    return SpringError(f"{model} joint {joint}: spring stiffness psi'(phi) = {stiffness:g} N m/rad <= 0 at "
                       f"deflection phi = {phi:g} rad (declared range |phi| <= {r:g} rad); "
                       "expected psi' > 0 over the range")


class _Law:
    """What every law shares: derivatives by differentiation, substitution of the abstract chain."""

    def derivative(self, k: int, phi: sp.Expr) -> sp.Expr:
        """``psi^(k)(phi)``, the k-th derivative of the law."""
        return law_derivative(self.law, k, phi)

    def substitute(self, e):
        """``e`` with every ``psi_k(.)`` of this joint replaced by the law's k-th derivative."""
        return substitute_chain(e, spring_functions(self.joint), self.derivative)

    def roles(self) -> Dict[str, sp.Symbol]:
        """The law's coefficients by role (field name), e.g. ``{"k1": k1, "k3": k3}`` (chain.json, MJCF)."""
        return {f: getattr(self, f) for f in self.__dataclass_fields__ if f not in ("joint", "deflection_range")}

    @property
    def parameters(self) -> Tuple[sp.Symbol, ...]:
        """The law's runtime parameters, in field order."""
        return tuple(self.roles().values())

    def _values(self, values: Dict[str, float]) -> Tuple[float, ...]:
        return tuple(float(values[str(s)]) for s in self.parameters)


@dataclass(frozen=True)
class LinearSpring(_Law):
    """``psi(phi) = K phi`` (N m): today's spring, for a model that also has motor friction."""

    joint: int
    K: sp.Symbol
    deflection_range: float
    kind = "linear"

    @property
    def start_stiffness(self) -> sp.Symbol:
        return self.K

    #: Newton steps of the emitted inverse (exact after one: psi is linear).
    newton_steps = 1

    def newton_start(self, tau: sp.Expr) -> sp.Expr:
        """Where the emitted Newton inverse ``psi^-1(tau)`` starts: ``tau / K`` (the root)."""
        return tau / self.K

    def law(self, phi: sp.Expr) -> sp.Expr:
        return self.K * phi

    def potential(self, phi: sp.Expr) -> sp.Expr:
        return self.K * phi ** 2 / 2

    def describe(self) -> str:
        return f"psi(phi) = {self.K} phi"

    def check(self, model: str, values: Dict[str, float]) -> None:
        (K,) = self._values(values)
        _finite(model, self.joint, str(self.K), K, "N m/rad")
        _check_range(model, self.joint, float(self.deflection_range))
        if not K > 0:
            raise _not_stiff(model, self.joint, K, 0.0, float(self.deflection_range))

    def stiffness_bounds(self, values: Dict[str, float]) -> Tuple[float, float]:
        (K,) = self._values(values)
        return K, K


@dataclass(frozen=True)
class CubicSpring(_Law):
    """``psi(phi) = k1 phi + k3 phi^3`` (N m), ``phi`` in rad, of one joint.

    Attributes
    ----------
    joint : int
        Joint number, 1-based (names the ``psi`` functions and the errors).
    k1, k3 : sympy.Symbol
        The coefficients (runtime parameters, N m/rad and N m/rad^3).
    deflection_range : float
        Declared range ``|phi| <= deflection_range`` (rad) on which ``psi' > 0`` must hold.
    """

    joint: int
    k1: sp.Symbol
    k3: sp.Symbol
    deflection_range: float
    kind = "cubic"

    @property
    def start_stiffness(self) -> sp.Symbol:
        return self.k1

    #: Newton steps of the emitted inverse from ``tau / k1`` (monotone: derive.core.spring.newton_inverse).
    newton_steps = 12

    def newton_start(self, tau: sp.Expr) -> sp.Expr:
        """Where the emitted Newton inverse ``psi^-1(tau)`` starts: ``tau / k1``."""
        return tau / self.k1

    def law(self, phi: sp.Expr) -> sp.Expr:
        """``psi(phi)``."""
        return self.k1 * phi + self.k3 * phi ** 3

    def potential(self, phi: sp.Expr) -> sp.Expr:
        """``integral_0^phi psi = k1 phi^2 / 2 + k3 phi^4 / 4`` (spring energy)."""
        return self.k1 * phi ** 2 / 2 + self.k3 * phi ** 4 / 4

    def describe(self) -> str:
        return f"psi(phi) = {self.k1} phi + {self.k3} phi^3"

    def check(self, model: str, values: Dict[str, float]) -> None:
        """``psi'(phi) = k1 + 3 k3 phi^2`` is even and monotone in ``|phi|``: its minimum over
        ``|phi| <= r`` is at ``phi = 0`` or ``|phi| = r``; both are checked (exact, no sampling)."""
        k1, k3 = (_finite(model, self.joint, str(s), v, u) for s, v, u in
                  zip(self.parameters, self._values(values), ("N m/rad", "N m/rad^3")))
        r = float(self.deflection_range)
        _check_range(model, self.joint, r)
        for phi in (0.0, r):
            stiffness = k1 + 3.0 * k3 * phi * phi
            if not stiffness > 0:
                raise _not_stiff(model, self.joint, stiffness, phi, r)

    def stiffness_bounds(self, values: Dict[str, float]) -> Tuple[float, float]:
        k1, k3 = self._values(values)
        r = float(self.deflection_range)
        ends = (k1, k1 + 3.0 * k3 * r * r)
        return min(ends), max(ends)


def _smoothstep_integrals(t):
    """``(S, Q)``: ``S(t) = int_0^t s``, ``Q(t) = int_0^t S`` of the quintic smoothstep ``s = 6t^5 - 15t^4 + 10t^3``."""
    return t ** 6 - 3 * t ** 5 + sp.Rational(5, 2) * t ** 4, t ** 7 / 7 - t ** 6 / 2 + t ** 5 / 2


def smooth_ramp(x: sp.Expr, w: sp.Expr, integral: bool = False) -> sp.Expr:
    """The ramp ``max(x, 0)`` with its kink blended over ``|x| < w / 2`` (C3), or its integral.

    ``R(x) = 0`` for ``x <= -w/2``, ``w S((x + w/2) / w)`` inside, ``x`` for ``x >= w/2``; ``R' `` is the
    quintic smoothstep, so the blend's area equals the kink's and ``R = max(x, 0)`` outside the window.
    ``integral=True``: ``P(x) = int_{-inf}^x R`` (``x^2 / 2 + w^2 / 56`` beyond the window).
    """
    t = (x + w / 2) / w
    S, Q = _smoothstep_integrals(t)
    if integral:
        return sp.Piecewise((0, x <= -w / 2), (w ** 2 * Q, x < w / 2), (x ** 2 / 2 + w ** 2 / 56, True))
    return sp.Piecewise((0, x <= -w / 2), (w * S, x < w / 2), (x, True))


@dataclass(frozen=True)
class ThreeSegmentSpring(_Law):
    """The datasheet curve: stiffness ``K_1`` to torque ``T_1``, ``K_2`` to ``T_2``, ``K_3`` beyond, C2-blended.

    ``psi(phi) = K_1 phi + sum_i (K_{i+1} - K_i) (R(phi - phi_i) - R(-phi - phi_i))`` with the
    smooth ramp ``R`` of :func:`smooth_ramp` of width ``w`` and the breakpoints
    ``phi_1 = T_1 / K_1``, ``phi_2 = phi_1 + (T_2 - T_1) / K_2`` (rad).

    Attributes
    ----------
    joint : int
    K_1, K_2, K_3 : sympy.Symbol
        Segment stiffnesses, N m/rad (``0 < K_1 <= K_2 <= K_3``: a harmonic drive stiffens).
    T_1, T_2 : sympy.Symbol
        Torque breakpoints, N m (``0 < T_1 < T_2``).
    width : sympy.Symbol
        Blend width ``w``, rad (``0 < w <= min(2 phi_1, phi_2 - phi_1)``: the windows neither reach
        ``phi = 0`` nor overlap).
    deflection_range : float
        Declared range, rad.
    """

    joint: int
    K_1: sp.Symbol
    K_2: sp.Symbol
    K_3: sp.Symbol
    T_1: sp.Symbol
    T_2: sp.Symbol
    width: sp.Symbol
    deflection_range: float
    kind = "three_segment"

    @property
    def start_stiffness(self) -> sp.Symbol:
        return self.K_1

    #: Newton steps of the emitted inverse from :meth:`newton_start` (3 reach 1e-17 rad on the built-ins; the
    #: tests check 4 on a dense grid over the range).
    newton_steps = 4

    def newton_start(self, tau: sp.Expr) -> sp.Expr:
        """Where the emitted Newton inverse ``psi^-1(tau)`` starts: the inverse of the datasheet's piecewise line.

        Exact outside the blends. Inside them the blended curve lies above the line on ``phi > 0`` (the smooth
        ramp is convex with asymptotes ``0`` and ``x``), so the start lies beyond the root of a convex function
        and Newton descends to it monotonically (odd symmetry for ``tau < 0``).
        """
        phi1, phi2 = self.breakpoints()
        return sp.Piecewise((-phi2 + (tau + self.T_2) / self.K_3, tau <= -self.T_2),
                            (-phi1 + (tau + self.T_1) / self.K_2, tau <= -self.T_1),
                            (tau / self.K_1, tau <= self.T_1),
                            (phi1 + (tau - self.T_1) / self.K_2, tau <= self.T_2),
                            (phi2 + (tau - self.T_2) / self.K_3, True))

    def breakpoints(self):
        """``(phi_1, phi_2)``, symbolic (rad)."""
        phi1 = self.T_1 / self.K_1
        return phi1, phi1 + (self.T_2 - self.T_1) / self.K_2

    def _steps(self):
        phi1, phi2 = self.breakpoints()
        return ((self.K_2 - self.K_1, phi1), (self.K_3 - self.K_2, phi2))

    def law(self, phi: sp.Expr) -> sp.Expr:
        return self.K_1 * phi + sum(dk * (smooth_ramp(phi - b, self.width) - smooth_ramp(-phi - b, self.width))
                                    for dk, b in self._steps())

    def potential(self, phi: sp.Expr) -> sp.Expr:
        """``int_0^phi psi``; ``P(-phi_i) = 0`` because the windows do not reach ``phi = 0`` (checked)."""
        P = lambda x: smooth_ramp(x, self.width, integral=True)  # noqa: E731
        return self.K_1 * phi ** 2 / 2 + sum(dk * (P(phi - b) + P(-phi - b)) for dk, b in self._steps())

    def describe(self) -> str:
        return (f"three-segment datasheet curve: stiffness {self.K_1} to torque {self.T_1}, {self.K_2} to "
                f"{self.T_2}, {self.K_3} beyond, blended over {self.width} rad")

    def check(self, model: str, values: Dict[str, float]) -> None:
        """Finite coefficients, ``psi' > 0``, breakpoints in order, windows apart (one-line errors).

        With ``0 < K_1 <= K_2 <= K_3`` the stiffness runs monotonically from ``K_1`` to ``K_3``
        (the smoothstep blends between neighbours), so ``psi' >= K_1 > 0`` everywhere; the order is
        also what makes the torque laws' Newton inverse start (``tau_J / K_1``) converge
        monotonically (``psi`` convex for ``phi > 0``).
        """
        j, r = self.joint, float(self.deflection_range)
        units = ("N m/rad",) * 3 + ("N m",) * 2 + ("rad",)
        K1, K2, K3, T1, T2, w = (_finite(model, j, str(s), v, u)
                                 for s, v, u in zip(self.parameters, self._values(values), units))
        _check_range(model, j, r)
        if not K1 > 0:
            raise _not_stiff(model, j, K1, 0.0, r)
        if not 0 < T1 < T2:
            raise SpringError(f"{model} joint {j}: torque breakpoints {self.T_1} = {T1:g}, {self.T_2} = {T2:g} N m; "
                              "expected 0 < T_1 < T_2")
        phi1 = T1 / K1
        for name, k, at in ((self.K_2, K2, phi1), (self.K_3, K3, None)):
            if not k > 0:
                at = phi1 + (T2 - T1) / K2 if at is None else at
                raise SpringError(f"{model} joint {j}: spring stiffness psi'(phi) = {name} = {k:g} N m/rad <= 0 "
                                  f"beyond deflection phi = {at:g} rad (declared range |phi| <= {r:g} rad); "
                                  "expected psi' > 0")
        if not K1 <= K2 <= K3:
            raise SpringError(f"{model} joint {j}: segment stiffnesses {K1:g}, {K2:g}, {K3:g} N m/rad; expected "
                              "K_1 <= K_2 <= K_3 (a harmonic drive stiffens; the torque laws' inverse of psi "
                              "converges monotonically for that)")
        phi2 = phi1 + (T2 - T1) / K2
        limit = min(2 * phi1, phi2 - phi1)
        if not 0 < w <= limit:
            raise SpringError(f"{model} joint {j}: blend width {self.width} = {w:g} rad; expected 0 < w <= "
                              f"{limit:.6g} rad (min(2 phi_1, phi_2 - phi_1) with breakpoints phi_1 = {phi1:.6g}, "
                              f"phi_2 = {phi2:.6g} rad: the blends must not reach phi = 0 nor overlap)")

    def stiffness_bounds(self, values: Dict[str, float]) -> Tuple[float, float]:
        """``(K_1, psi'(r))``: the stiffness is monotone in ``|phi|`` (checked order)."""
        a = sp.Symbol("a", real=True)
        subs = {s: float(values[str(s)]) for s in self.parameters}
        at_r = float(self.derivative(1, a).subs(subs).subs(a, float(self.deflection_range)))
        return float(values[str(self.K_1)]), at_r


#: Law name (as in model files and manifests) -> class.
SPRING_KINDS = {"linear": LinearSpring, "cubic": CubicSpring, "three_segment": ThreeSegmentSpring}

#: Runtime-parameter name -> (meaning, unit) of every law's coefficients (the linear law's ``K`` is the
#: model's own stiffness parameter and keeps its entry there).
SPRING_PARAMETERS: Dict[str, Tuple[str, str]] = {
    "k1": ("spring: linear coefficient psi'(0)", "N m/rad"), "k3": ("spring: cubic coefficient", "N m/rad^3"),
    "K_1": ("spring: stiffness of the first segment, psi'(0)", "N m/rad"),
    "K_2": ("spring: stiffness of the second segment", "N m/rad"),
    "K_3": ("spring: stiffness of the third segment", "N m/rad"),
    "T_1": ("spring: torque at the end of the first segment", "N m"),
    "T_2": ("spring: torque at the end of the second segment", "N m"),
    "w_blend": ("spring: blend width around each breakpoint", "rad"),
}

#: Law name -> the runtime-parameter names of its coefficients, in the law's field order.
LAW_COEFFICIENTS: Dict[str, Tuple[str, ...]] = {
    "linear": (), "cubic": ("k1", "k3"), "three_segment": ("K_1", "K_2", "K_3", "T_1", "T_2", "w_blend")}

#: Law name -> the coefficients that scale its torque together: multiplying them by ``g`` multiplies
#: ``psi`` by ``g`` exactly (``K`` of the linear law; the three-segment curve's breakpoints ``T / K`` and
#: blend width stay). The first is the small-deflection stiffness ``psi'(0)``.
TORQUE_SCALE_COEFFICIENTS: Dict[str, Tuple[str, ...]] = {
    "linear": ("K",), "cubic": ("k1", "k3"), "three_segment": ("K_1", "K_2", "K_3", "T_1", "T_2")}
