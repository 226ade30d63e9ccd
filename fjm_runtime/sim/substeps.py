"""How finely the plant is integrated within one control sample: the substeps rule.

The controller runs at ``1/T``; the plant is integrated by ``substeps`` classical RK4 steps of
``T / substeps`` per sample with the torque held. The default comes from the model's fastest
elastic mode at the initial state, with the TRUE parameters::

    omega_i^2 = K_i (D^-1)_ii + K_i / J_mi          (link and motor inertia on one spring)
    omega_max = max_i omega_i
    substeps  = ceil(SAFETY * T * omega_max / STEP_PER_RADIAN)

``K_i (D^-1)_ii`` and ``K_i / J_mi`` are read off the model's drift: the link acceleration is
affine in ``q_m`` (its derivative is ``D^-1 K``) and the motor acceleration affine in ``q``
(derivative ``J_m^-1 K``), so one difference of ``f`` per joint gives them exactly up to
rounding. ``D^-1`` varies with ``q``: :data:`SAFETY` covers a fastest mode up to that factor
faster than at the initial configuration. :data:`STEP_PER_RADIAN` (``omega h`` per RK4 substep)
is chosen so that the substepped plant equals a 10x finer reference to 1e-8 rad over 10 s on
the Panda at 1 kHz and on link1 (docs/simulation.md; tests/runtime/sim/test_substeps.py).
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from ..validation import FjmValueError

__all__ = ["CoarseIntegrationWarning", "SAFETY", "STEP_PER_RADIAN", "default_substeps", "fastest_mode",
           "resolve_substeps"]

#: Margin on the initial-configuration ``omega_max`` for the variation of ``D^-1`` with ``q``.
SAFETY = 1.5

#: ``omega_max h`` allowed per RK4 substep (rad).
STEP_PER_RADIAN = 0.1


class CoarseIntegrationWarning(UserWarning):
    """``substeps`` forced below what the model's fastest mode needs (see :func:`default_substeps`)."""


def fastest_mode(model, x0, p_true) -> float:
    """``omega_max = max_i sqrt(K_i (D^-1)_ii + K_i / J_mi)`` at ``x0`` with the TRUE parameters, rad/s.

    Parameters
    ----------
    model : Model
    x0 : ndarray, shape (4n,)
    p_true : ndarray, shape (n_params,)
    """
    n, nx = int(model.n), int(model.nx)
    x0 = np.asarray(x0, dtype=float)
    f0 = np.asarray(model.f(x0, p_true), dtype=float).reshape(nx)
    w2 = np.zeros(n)
    for i in range(n):
        xm = x0.copy(); xm[2 * n + i] += 1.0            # q_m,i + 1: link accel changes by (D^-1 K)[:, i]
        xl = x0.copy(); xl[i] += 1.0                    # q_i + 1: motor accel changes by K_i / J_mi
        fm = np.asarray(model.f(xm, p_true), dtype=float).reshape(nx)
        fl = np.asarray(model.f(xl, p_true), dtype=float).reshape(nx)
        w2[i] = (fm[n + i] - f0[n + i]) + (fl[3 * n + i] - f0[3 * n + i])
    return float(np.sqrt(np.max(np.maximum(w2, 0.0))))


def default_substeps(T: float, omega_max: float) -> int:
    """``ceil(SAFETY * T * omega_max / STEP_PER_RADIAN)``, at least 1."""
    return max(1, int(math.ceil(SAFETY * T * omega_max / STEP_PER_RADIAN - 1e-12)))


def resolve_substeps(substeps, model, x0, p_true, T: float) -> int:
    """The substeps of a run: the default rule for ``None``; a forced value is checked and warned about.

    Raises
    ------
    FjmValueError
        ``substeps`` not an integer >= 1.

    Warns
    -----
    CoarseIntegrationWarning
        A forced value below the rule's.
    """
    omega = fastest_mode(model, x0, p_true)
    needed = default_substeps(T, omega)
    if substeps is None:
        return needed
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise FjmValueError(f"substeps = {substeps!r}: expected an integer >= 1 (RK4 steps per control sample)")
    if substeps < needed:
        warnings.warn(f"substeps = {int(substeps)} is coarser than the rule: omega_max = {omega:.4g} rad/s, "
                      f"step {T / substeps:.3g} s, rule ceil({SAFETY:g} T omega_max / {STEP_PER_RADIAN:g}) = "
                      f"{needed}", CoarseIntegrationWarning, stacklevel=3)
    return int(substeps)
