"""Lemma 1 for a nonlinear spring: the stiffness interval ``psi' in [k_min, k_max]`` a certificate covers.

The paper states Lemma 1 for a linear spring with ``K in [K_min, K_max]``; everything it uses of
``K`` is the stiffness in ``beta = J_l J_m / K`` (and the bound on ``|alpha_hat - alpha|``). With a
spring ``tau_J = psi(phi)`` the same quantity is ``psi'(phi)`` at the deflection the state has:
``beta = J_m D / psi'(phi)``. So the certificate of ``fjm tune`` (which evaluates the law that runs,
``alpha`` and ``beta`` of the generated model at the states of its box, ``x = T^{-1}(y_hat; p_nom)``)
holds for the nonlinear spring exactly as for the linear one, with the paper's interval replaced by

    k_min = min psi'(phi; p),  k_max = max psi'(phi; p)

over the deflections ``phi = q_m - q`` of the box's states and the parameter box, and on one
condition the linear case does not have: every such deflection lies in the DECLARED range, where the
model guarantees ``psi' > 0`` (outside it the law may be singular). :func:`stiffness_interval`
computes both from the deflections the certificate visited; ``fjm tune`` reports them and refuses
(``feasible: false``) a box that leaves the declared range.
"""
from __future__ import annotations

from itertools import product
from typing import Dict, Optional, Tuple

import numpy as np

from ...drives import model_springs

__all__ = ["stiffness_interval"]


def _declared_ranges(model) -> Dict[int, float]:
    """Joint (1-based) -> declared deflection range (rad) of a nonlinear-spring model's manifest."""
    joints = (model.manifest.get("springs") or {}).get("joints") or []
    return {int(j["joint"]): float(j["deflection_range"][1]) for j in joints}


def stiffness_interval(model, box: Dict[str, Tuple[float, float]], p_nom: np.ndarray,
                       deflections: np.ndarray, points: int = 401) -> Optional[dict]:
    """``psi'`` over the visited deflections and the parameter box, and whether they stay declared.

    Parameters
    ----------
    model : Model
        A generated model; None is returned for a linear spring (no ``spring`` Function).
    box : dict name -> (lo, hi)
        The TRUE parameters' box of the certificate (names absent: the nominal value).
    p_nom : ndarray, shape (npar,)
        Nominal parameters.
    deflections : ndarray, shape (n, 2)
        ``[min, max]`` of ``q_m - q`` per joint over the certificate's states.
    points : int
        Deflections sampled per joint between the extremes (``psi'`` is smooth; the extremes of the
        cubic and of the stiffening three-segment curve are at the ends or at ``phi = 0``, included).

    Returns
    -------
    dict or None
        ``deflection`` ``[[lo, hi]]`` (rad), ``declared`` ``[r]`` (rad), ``k_min``, ``k_max`` (N m/rad)
        per joint, and ``outside``: a one-line reason when a deflection leaves the declared range or
        ``psi' <= 0`` somewhere on the box (empty otherwise).
    """
    drives = getattr(model, "drives", None)
    if drives is None or all(d.spring_law == "linear" for d in drives):  # a constant K: no interval to report
        return None
    spring = model_springs(model)["spring"]
    declared = _declared_ranges(model)
    names = list(model.param_names)
    spring_names = sorted({p for j in (model.manifest["springs"]["joints"]) for p in j["parameters"]})
    axes = [sorted({box.get(k, (p_nom[names.index(k)],) * 2)[0], box.get(k, (p_nom[names.index(k)],) * 2)[1]})
            for k in spring_names]
    k_min, k_max, outside = [], [], ""
    for i, (lo, hi) in enumerate(np.asarray(deflections, dtype=float)):
        r = declared.get(i + 1, np.inf)
        if not outside and max(abs(lo), abs(hi)) > r:
            outside = (f"joint {i + 1}: the box's states reach the deflection q_m - q = "
                       f"{lo if abs(lo) > abs(hi) else hi:.4g} rad, beyond the declared range |phi| <= {r:g} rad "
                       "where the model guarantees psi' > 0 (shrink the error box or the reference)")
        phis = np.unique(np.concatenate([np.linspace(lo, hi, points), [0.0] if lo < 0 < hi else []]))
        ks = []
        for vertex in product(*axes):
            p = np.array(p_nom, dtype=float)
            for k, v in zip(spring_names, vertex):
                p[names.index(k)] = v
            ks.append(np.asarray(spring.map(phis.size)(phis[None, :], np.tile(p[:, None], phis.size))[1]).ravel())
        ks = np.concatenate(ks)
        k_min.append(float(ks.min()))
        k_max.append(float(ks.max()))
        if not outside and not k_min[-1] > 0:
            outside = (f"joint {i + 1}: psi' = {k_min[-1]:.4g} N m/rad <= 0 on the box (parameter box and "
                       "deflections): the law is singular there")
    return {"deflection": np.asarray(deflections, dtype=float).tolist(),
            "declared": [declared.get(i + 1, float("inf")) for i in range(len(k_min))],
            "k_min": k_min, "k_max": k_max, "outside": outside}
