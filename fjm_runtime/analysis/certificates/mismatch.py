"""``H = sup |alpha(x; p_nom) - alpha(x; p)|`` and the range of ``beta`` on a box, for Lemma 1.

The state the TRUE plant is in when its linearizing coordinates are ``y`` is ``x = T^{-1}(y; p)``;
``alpha_hat`` is evaluated there with the nominal parameters, as the controller does. Coordinates of
the box (:mod:`fjm_runtime.analysis.certificates.box`) along which the mismatch is affine take their
two vertices, the others a grid; :func:`mismatch_supremum` may then maximize locally.
:func:`fjm_runtime.analysis.certificates.lemma1.lemma1_on_box` turns the result into the gain.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .box import assemble, box_dims, box_maximize, classify_affine
from .evaluator import Evaluator, build_true_fn


def mismatch_evaluator(model, p_nom) -> Evaluator:
    """``(Y (N, 4n), P (N, npar)) -> [alpha(x; p_nom) - alpha(x; p), vec beta(x; p)]`` at ``x = T^{-1}(y; p)``.

    The state the TRUE plant is in when its linearizing coordinates are ``y``;
    ``alpha_hat`` is evaluated there with the nominal parameters, as the controller does.
    """
    return Evaluator(model, build_true_fn(model, np.asarray(p_nom, dtype=float)))


@dataclass
class Mismatch:
    """Result of :func:`mismatch_supremum`.

    Attributes
    ----------
    H : float
        ``sup |alpha(x; p_nom) - alpha(x; p)|`` found on the box (N m, the unit of ``alpha``).
    H_at : dict
        Where it is largest: ``'y'`` (list, 4n) and ``'params'`` (name -> value of the box's parameters).
    beta_min, beta_max : float
        Range of ``beta(x; p)`` over the grid points.
    """

    H: float
    H_at: dict
    beta_min: float
    beta_max: float


def _refine_supremum(ev, dims, pts, dA, p_nom, best, best_pt):
    """Local maximization of ``|alpha_hat - alpha|`` from the 8 largest grid points along the gridded coordinates."""
    free = [j for j, d in enumerate(dims) if not d.affine and d.lo < d.hi]
    if not free:
        return best, best_pt
    lo = np.array([dims[j].lo for j in free]); hi = np.array([dims[j].hi for j in free])
    for j0 in np.argsort(-dA)[:8]:
        base = pts[j0].copy()

        def obj(v, base=base, h=1e-7):
            vs = np.repeat(v[None, :], 2 * len(free) + 1, axis=0)
            for a in range(len(free)):
                vs[1 + 2 * a, a] = min(v[a] + h, 1.0)
                vs[2 + 2 * a, a] = max(v[a] - h, 0.0)
            pt = np.repeat(base[None, :], vs.shape[0], axis=0)
            pt[:, free] = lo + vs * (hi - lo)
            Yv, Pv = assemble(dims, pt, 1, p_nom)
            val = np.abs(ev(Yv, Pv)[:, 0])
            grad = np.array([(val[1 + 2 * a] - val[2 + 2 * a]) / max(vs[1 + 2 * a, a] - vs[2 + 2 * a, a], 1e-300)
                             for a in range(len(free))])
            return float(val[0]), grad

        vb = box_maximize(obj, (base[free] - lo) / (hi - lo), maxiter=300, tol=1e-14)
        val, _ = obj(vb)
        if val > best:
            best = val
            best_pt = base.copy(); best_pt[free] = lo + vb * (hi - lo)
    return best, best_pt


def mismatch_supremum(model, p_nom, box, y_box, points, *, refine: bool = False, seed: int = 0) -> Mismatch:
    """``H = sup |alpha(x; p_nom) - alpha(x; p)|`` and the range of ``beta`` over a y-box and a parameter box.

    ``x = T^{-1}(y; p)`` (:func:`mismatch_evaluator`). Coordinates along which the mismatch is
    affine take their two vertices, the others a grid; ``refine`` then maximizes locally.

    Parameters
    ----------
    model : Model
        One joint.
    p_nom : ndarray, shape (npar,)
        Nominal parameters (``alpha_hat``).
    box : dict name -> (lo, hi)
        Validated parameter intervals with ``lo < hi`` (:func:`~fjm_runtime.analysis.certificates.box.check_box`).
    y_box : ndarray, shape (4, 1)
        Half-widths of ``|y_k| <= Y_k``.
    points : callable
        ``Dim -> int``: grid points along a coordinate that is not affine.
    refine : bool
        Local maximization from the largest grid points; off, the grid supremum.
    seed : int
        Seed of the affinity test's sample points.

    Returns
    -------
    Mismatch
    """
    ev = mismatch_evaluator(model, p_nom)
    dims = box_dims(model, y_box, p_nom, box)
    classify_affine(dims, lambda Y, P: ev(Y, P)[:, :1], 1, p_nom, np.random.default_rng(seed))
    for d in dims:
        if not d.affine:
            d.points = points(d)
    pts = np.stack(np.meshgrid(*[d.values() for d in dims], indexing="ij"), axis=-1).reshape(-1, len(dims))
    Y, P = assemble(dims, pts, 1, p_nom)
    V = ev(Y, P)
    dA = np.abs(V[:, 0])
    best, best_pt = float(np.max(dA)), pts[int(np.argmax(dA))]
    if refine:
        best, best_pt = _refine_supremum(ev, dims, pts, dA, p_nom, best, best_pt)
    Yb, _ = assemble(dims, best_pt[None, :], 1, p_nom)
    at = {"y": Yb[0].tolist(), "params": {d.name: float(best_pt[j]) for j, d in enumerate(dims) if d.kind == "p"}}
    return Mismatch(best, at, float(np.min(V[:, 1])), float(np.max(V[:, 1])))
