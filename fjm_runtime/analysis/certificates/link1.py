"""The paper's single link (``link1``) through its generated functions: parameters, ``T^{-1}``, ``alpha``.

Nothing here restates the model's formulas: ``alpha`` and ``T`` are the generated
CasADi functions of ``fjm_runtime.load('link1')``, and ``T^{-1}`` is computed from
``T`` by Newton (:func:`fjm_runtime.analysis.certificates.evaluator.inverse_T`; the motor half
of ``T`` is affine in ``(q_m, dq_m)`` for link1, so it converges in one step).
"""
from __future__ import annotations

from typing import Dict, Tuple

import numpy as np

from ...model import load
from .evaluator import inverse_T

POSITIVE = ("J_l", "J_m", "K")
"""Parameters of link1 that must be > 0 (they divide in ``T``, ``alpha`` and ``beta``)."""


def link1_model():
    """The generated ``link1`` model (``fjm_runtime.load('link1')``, cached by the loader)."""
    return load("link1")


def link1_params(p) -> Dict[str, float]:
    """Complete, validated link1 parameters as a dict (defaults for missing names).

    Parameters
    ----------
    p : dict or array_like, shape (7,)
        Names of ``link1_model().param_names`` (a subset, as a dict) or a full vector in that order.

    Returns
    -------
    dict name -> float
        ``J_l``, ``J_m``, ``K`` finite and > 0; ``ValueError`` naming the field otherwise.
    """
    m = link1_model()
    names = tuple(m.param_names)
    if isinstance(p, dict):
        unknown = sorted(set(p) - set(names))
        if unknown:
            raise ValueError(f"params: unknown names {unknown}; expected a subset of {names}")
        d = dict(m.default_params)
        d.update({k: float(v) for k, v in p.items()})
    else:
        a = np.asarray(p, dtype=float).ravel()
        if a.shape != (len(names),):
            raise ValueError(f"params with shape {a.shape}: expected ({len(names)},) in order {names}")
        d = dict(zip(names, a.tolist()))
    for k in POSITIVE:
        if not (np.isfinite(d[k]) and d[k] > 0):
            raise ValueError(f"{k} = {d[k]!r}: expected a finite value > 0")
    return d


def link1_bounds(nominal: Dict[str, float], bounds) -> Dict[str, Tuple[float, float]]:
    """Intervals of every link1 parameter: ``bounds`` where given, ``(nominal, nominal)`` elsewhere.

    Parameters
    ----------
    nominal : dict name -> float
        Complete parameters (:func:`link1_params`).
    bounds : dict name -> (lo, hi) or None

    Returns
    -------
    dict name -> (float, float)
    """
    names = tuple(link1_model().param_names)
    out = {}
    for k, v in (bounds or {}).items():
        if k not in names:
            raise ValueError(f"bounds: unknown parameter {k!r}; expected one of {names}")
        lo, hi = (float(b) for b in v)
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            raise ValueError(f"bounds[{k!r}] = {v!r}: expected finite (lo, hi) with lo <= hi")
        if k in POSITIVE and lo <= 0:
            raise ValueError(f"bounds[{k!r}] = {v!r}: expected lo > 0")
        out[k] = (lo, hi)
    for k in names:
        out.setdefault(k, (nominal[k], nominal[k]))
    return out


def _vector(p) -> np.ndarray:
    d = link1_params(p)
    return np.array([d[k] for k in link1_model().param_names])


def link1_T_inverse(y, p) -> np.ndarray:
    """``x = T^{-1}(y; p)`` for link1 from the generated ``T`` (broadcasts over leading axes).

    Parameters
    ----------
    y : array_like, shape (..., 4)
    p : dict or array_like

    Returns
    -------
    ndarray, shape (..., 4)
    """
    return inverse_T(link1_model(), y, _vector(p))


def link1_alpha(x, p) -> np.ndarray:
    """``alpha(x; p) = -beta a`` of the generated link1 model (broadcasts over leading axes).

    Parameters
    ----------
    x : array_like, shape (..., 4)
    p : dict or array_like

    Returns
    -------
    ndarray, shape ``x.shape[:-1]``
    """
    m = link1_model()
    x = np.asarray(x, dtype=float)
    if x.shape[-1:] != (4,):
        raise ValueError(f"x with shape {x.shape}: expected (..., 4)")
    X = x.reshape(-1, 4)
    if X.shape[0] == 0:
        return np.zeros(x.shape[:-1])
    out = m.functions["alpha"].map(X.shape[0])(X.T, _vector(p))
    return np.asarray(out, dtype=float).reshape(x.shape[:-1])


def link1_equilibrium(q: float, p) -> np.ndarray:
    """Rest state of link1 holding the link at ``q``: ``[q, 0, q + M g0 L sin(q) / K, 0]``, shape (4,).

    ``T^{-1}`` of ``y = [q, 0, 0, 0]``: at rest ``y3 = y4 = 0``.
    """
    return link1_T_inverse(np.array([q, 0.0, 0.0, 0.0]), p)
