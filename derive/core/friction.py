"""Motor friction: Coulomb and Stribeck, regularized so that the plant stays smooth for RK4.

On the motor side (link-side velocity ``v = dq_m``), beside the viscous ``B_m dq_m`` of every model::

    J_m ddq_m + B_m dq_m + F(dq_m) + tau_J = u,
    F(v) = (F_c + (F_s - F_c) exp(-(v / v_s)^2)) tanh(v / v_c)

``F_c`` is the Coulomb level (N m), ``F_s`` the static (breakaway) level that the Stribeck hump
reaches near rest (``F_s = F_c``: no hump), ``v_s`` the Stribeck velocity and ``v_c`` the
regularization velocity (rad/s): ``tanh(v / v_c)`` replaces ``sign(v)``, so ``F`` is smooth and
the classical RK4 of the plant keeps its order as long as the substep resolves the time constant
``J_m v_c / F_c`` (docs/real-drives.md). It is the friction :mod:`fjm_runtime.ident.identify` fits.

Friction enters only the motor equation, beside ``u``: with ``y = q`` of relative degree 4 it
appears once, in ``L_f y4``, never differentiated. The linearizing law therefore adds the NOMINAL
``F(dq_m)`` to the torque (a feedforward of the nominal friction); a controller built on nominal
``F_c = F_s = 0`` does without it, and the sliding mode covers what the feedforward misses.

The derivation carries ``F`` as abstract SymPy functions (:func:`friction_functions`, each one's
derivative the next, as the spring's ``psi``) and substitutes the law at the end
(:meth:`MotorFriction.substitute`): the paper's involutivity determinants stay small (with the
law written out they took a minute). Pure math: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, Tuple

import sympy as sp

from .abstract import derivative_chain, law_derivative, substitute_chain

__all__ = ["MotorFriction", "FrictionError", "check_friction", "friction_functions", "FRICTION_PARAMETERS"]

#: Highest derivative of F the derivation may ask for (the brackets differentiate F up to third order).
_ORDERS = 5


def friction_functions(joint: int) -> Tuple[type, ...]:
    """``(F, F', F'', ...)`` of joint ``joint``'s motor friction as SymPy function classes (cached)."""
    return derivative_chain("F", joint, _ORDERS, "friction")


class FrictionError(ValueError):
    """Friction coefficients that are not a friction (one line, names the joint, the value, the unit)."""


@dataclass(frozen=True)
class MotorFriction:
    """``F(v) = (F_c + (F_s - F_c) exp(-(v / v_s)^2)) tanh(v / v_c)`` of one motor (N m, v in rad/s).

    Attributes
    ----------
    joint : int
        Joint number, 1-based.
    F_c, F_s, v_s, v_c : sympy.Symbol
        Coulomb and static levels (N m, >= 0), Stribeck and regularization velocities (rad/s, > 0):
        runtime parameters.
    """

    joint: int
    F_c: sp.Symbol
    F_s: sp.Symbol
    v_s: sp.Symbol
    v_c: sp.Symbol

    def law(self, v: sp.Expr) -> sp.Expr:
        """``F(v)``, the friction torque that opposes the motor velocity ``v``."""
        return (self.F_c + (self.F_s - self.F_c) * sp.exp(-(v / self.v_s) ** 2)) * sp.tanh(v / self.v_c)

    def derivative(self, k: int, v: sp.Expr) -> sp.Expr:
        """``F^(k)(v)``, the k-th derivative of the law."""
        return law_derivative(self.law, k, v)

    def substitute(self, e):
        """``e`` with every abstract ``F_k(.)`` of this joint replaced by the law's k-th derivative."""
        return substitute_chain(e, friction_functions(self.joint), self.derivative)

    def describe(self) -> str:
        return (f"F(v) = ({self.F_c} + ({self.F_s} - {self.F_c}) exp(-(v/{self.v_s})^2)) tanh(v/{self.v_c})")


#: Runtime parameters of the friction, in argument order: (name, meaning, unit).
FRICTION_PARAMETERS: Tuple[Tuple[str, str, str], ...] = (
    ("F_c", "motor Coulomb friction (link side)", "N m"),
    ("F_s", "motor static friction, the Stribeck level at rest (F_s = F_c: no hump)", "N m"),
    ("v_s", "Stribeck velocity of the motor friction (link side)", "rad/s"),
    ("v_c", "regularization velocity of the friction: tanh(v / v_c) for sign(v)", "rad/s"),
)

#: What each coefficient must be: (test, expectation, unit).
_RULES = {"F_c": (lambda v: v >= 0, ">= 0", "N m"), "F_s": (lambda v: v >= 0, ">= 0", "N m"),
          "v_s": (lambda v: v > 0, "> 0", "rad/s"), "v_c": (lambda v: v > 0, "> 0", "rad/s")}


def check_friction(model: str, friction: MotorFriction, values: Dict[str, float]) -> None:
    """Raise :class:`FrictionError` unless every coefficient is finite and physical.

    ``F_c, F_s >= 0`` (a negative level would push the motor along its motion: a source of
    energy), ``v_s, v_c > 0`` (they divide).
    """
    for role in ("F_c", "F_s", "v_s", "v_c"):
        name = str(getattr(friction, role))
        v = float(values[name])
        ok, expected, unit = _RULES[role]
        if not (math.isfinite(v) and ok(v)):
            raise FrictionError(f"{model} joint {friction.joint}: motor friction {name} = {v!r} {unit}; "
                                f"expected a finite number {expected}")
