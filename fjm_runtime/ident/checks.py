"""Plausibility warnings of an identification: a log's units and a result far from the model's nominal.

One line each, naming the joint (or parameter) and the factor. They warn, they do not refuse: a user
may know better (a prototype drive, a deliberately soft spring).
"""
from __future__ import annotations

from typing import List

import numpy as np

__all__ = ["gear_ratio_warnings", "nominal_warnings", "GEAR_LIKE", "NOMINAL_FACTOR"]

#: A motor angle moving this many times as far as its link angle (or more) looks like a rotor angle.
GEAR_LIKE = 3.0
#: An identified value this many times above or below the model's nominal one gets a warning.
NOMINAL_FACTOR = 10.0


def gear_ratio_warnings(q: np.ndarray, q_m: np.ndarray) -> List[str]:
    """A warning per joint whose logged ``q_m`` moves ``GEAR_LIKE`` times as far as ``q`` or more.

    On the link side ``q_m = q + tau_J / K`` moves with ``q`` (slope near 1); a rotor angle not divided by
    the gear ratio ``N`` moves ``N`` times as far (the stiffness then comes out about ``K / N^2``).

    Parameters
    ----------
    q, q_m : ndarray, shape (N, n)
        Link and motor angles, rad.
    """
    out = []
    dq, dqm = q - q.mean(axis=0), q_m - q_m.mean(axis=0)
    for i in range(q.shape[1]):
        var = float(dq[:, i] @ dq[:, i])
        if var <= 0.0:
            continue
        slope = float(dq[:, i] @ dqm[:, i]) / var
        if abs(slope) >= GEAR_LIKE:
            out.append(f"joint {i + 1}: q_m_{i + 1} moves {abs(slope):.3g} times as far as q_{i + 1} (a gear ratio?): "
                       "expected the motor angle on the link side, the rotor angle divided by the gear ratio "
                       "(q_m ~ q); the stiffness then comes out about K / N^2")
    return out


def nominal_warnings(values: dict, model) -> List[str]:
    """A warning per identified model parameter ``NOMINAL_FACTOR`` times or more from the model's nominal
    value (a nominal 0, e.g. an undamped model's ``B_m``, has no scale and is skipped)."""
    out = []
    for name, v in values.items():
        info = model.parameter_info.get(name)
        nominal = model.default_params.get(name)
        if info is None or not nominal or not np.isfinite(v):
            continue
        ratio = abs(float(v) / float(nominal))
        if ratio >= NOMINAL_FACTOR or ratio <= 1.0 / NOMINAL_FACTOR or v * nominal < 0:
            how = f"{ratio:.3g} times" if ratio >= 1 else f"1/{1 / ratio:.3g} of" if ratio > 0 else "0 times"
            sign = ", of the opposite sign" if v * nominal < 0 else ""
            out.append(f"{name} = {v:.4g} {info.unit} is {how} the model's nominal {nominal:.4g}{sign}: check the "
                       "log's units and gear ratio, or the model")
    return out
