"""A gains file (a ``fjm design`` output, or ``{"kind", "gains"}`` by hand) checked for one model.

:func:`check_gains_spec` refuses, in one line and before any work, a file whose per-joint gains are for
another arm or whose gains are not finite numbers of the right sign, or that lacks what its law reads.
Used by ``fjm simulate``, ``fjm analyze`` and ``fjm export controller``.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from ..validation import FjmValueError

__all__ = ["check_gains_spec", "is_real"]

# gains a file may set: (sign rule, unit); per-joint unless noted in _SCALAR
_GAIN_RULES = {"lam": ("> 0", "1/s"), "k_s": (">= 0", "rad/s^4"), "delta": ("> 0", "rad/s^3"),
               "k_lin": (">= 0", "1/s"), "u_max": ("> 0", "N m")}
_SCALAR = ("lam",)
# keys the law of each kind reads from a design (one of the tuple's names)
_REQUIRED = {"smc": (("lam", "c"), ("k_s",), ("delta",)), "ismc": (("lam", "c"), ("k_s",), ("delta",)),
             "adaptive": (("lam", "c"), ("k_s",), ("delta",)), "sign": (("lam", "c"), ("k_s",)),
             "fl": (("lam", "c"),)}


def _joints_of(spec: dict) -> Optional[int]:
    """How many joints a design is for: its task's length, or (when it names its model) its per-joint
    gains' length; else None (a hand-written file: each gain's length is checked on its own)."""
    gains = spec.get("gains", {})
    task = spec.get("reference") if isinstance(spec.get("reference"), dict) else {}
    named = [gains.get(k) for k in _GAIN_RULES if k not in _SCALAR] if spec.get("model") else []
    for v in [task.get("amplitude")] + named:
        if isinstance(v, list) and len(v) > 1 and not isinstance(v[0], list):
            return len(v)
    return None


def is_real(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def check_gains_spec(spec: dict, where: str, model) -> None:
    """Refuse a gains file that is not for ``model`` or holds a gain that is not a usable number.

    Parameters
    ----------
    spec : dict
        ``{"kind", "gains": {...}, ...}`` (a ``--gains`` file or a shipped design).
    where : str
        How the error names it, e.g. ``"--gains g.json"``.
    model : Model
        The run's model (``name``, ``n``).

    Raises
    ------
    FjmValueError
        One line: the model mismatch (the design's model and joints vs this one), or the key,
        the value and what was expected, or the missing key.
    """
    n, name = int(model.n), str(model.name)
    designed_for = spec.get("model")
    joints = _joints_of(spec)
    if joints is not None and joints != n:
        what = f"model {designed_for!r} with {joints} joints" if designed_for else f"{joints} joints"
        raise FjmValueError(f"{where}: the gains are for {what}; {name} has {n} joint{'s' * (n != 1)} "
                            f"(expected gains designed for {name}, e.g. from `fjm design {name}`)")
    gains = spec["gains"]
    for key, (rule, unit) in _GAIN_RULES.items():
        if key not in gains:
            continue
        v = gains[key]
        shape = "a finite number" if key in _SCALAR else f"a finite number or a list of {n}"
        expected = f"expected {shape} {rule} ({unit})"
        vals = v if (isinstance(v, list) and key not in _SCALAR) else [v]
        if not all(is_real(x) for x in vals) or not vals:
            raise FjmValueError(f"{where}: gains.{key} = {v!r}; {expected}")
        if isinstance(v, list) and len(v) not in (1, n):
            raise FjmValueError(f"{where}: gains.{key} has {len(v)} entries; {expected} for {name}")
        arr = np.asarray(vals, dtype=float)
        if not np.all(np.isfinite(arr)) or not np.all(arr > 0 if rule == "> 0" else arr >= 0):
            raise FjmValueError(f"{where}: gains.{key} = {v!r}; {expected}")
    for options in _REQUIRED.get(spec["kind"], ()):
        if not any(k in gains for k in options):
            raise FjmValueError(f"{where}: gains.{options[0]} is missing; expected the {spec['kind']} law's "
                                f"gains {', '.join(o[0] for o in _REQUIRED[spec['kind']])} (docs/simulation.md)")
