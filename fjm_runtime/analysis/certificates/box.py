"""The box of a reaching certificate: parameter and error boxes, coordinates, affinity tests, sampling.

A box is the product of the half-widths of the nominal linearizing coordinates
``|y_hat_k| <= R_{k-1} + E_k`` (per joint) and the intervals of the uncertain TRUE
parameters. :class:`Dim` is one coordinate of it; :func:`classify_affine` marks the
coordinates along which the analysed quantities are affine (enumerated at their two
vertices); :func:`box_maximize` refines a supremum inside the box.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np

from ...control.laws import coefficients_from_pole
from ...drives import linear_springs, linear_stiffness_indices, role_names

# ---------------------------------------------------------------------------------------------
# inputs
def surface_coefficients(lam: Optional[float] = None, c=None, integral: bool = False) -> np.ndarray:
    """Surface coefficients, lowest first (``[c1, c2, c3]`` or ``[c0, c1, c2, c3]``), from ``lam`` or ``c``."""
    order = 4 if integral else 3
    if (lam is None) == (c is None):
        raise ValueError("lam/c: give exactly one of lam (pole magnitude, 1/s) or c (coefficients)")
    if lam is not None:
        return coefficients_from_pole(lam, order)
    cc = np.asarray(c, dtype=float).ravel()
    if cc.shape != (order,) or not np.all(np.isfinite(cc)) or np.any(cc <= 0):
        raise ValueError(f"c = {np.asarray(c).tolist()}: expected {order} finite values > 0")
    return cc


def param_box_from_ranges(model, k_range=None, jm_range=None, bm_range=None, mass_range=None,
                          extra: Optional[Dict[str, Tuple[float, float]]] = None) -> Dict[str, Tuple[float, float]]:
    """Parameter box ``{name: (lo, hi)}`` from per-kind ranges applied to every joint.

    Parameters
    ----------
    model : Model
    k_range, jm_range, bm_range : (lo, hi), optional
        Absolute bounds for every joint stiffness (``K``/``K<i>``), motor inertia
        (``J_m``/``Jm<i>``) and motor damping (``B_m``/``Bm<i>``).
    mass_range : (lo, hi), optional
        Absolute bounds for every link mass (``M``/``m<i>``; link1's ``M`` is the tip mass).
    extra : dict, optional
        Further ``name: (lo, hi)`` entries (override the above).
    """
    info = model.parameter_info
    masses = [k for k in model.param_names if info[k].role is None and info[k].unit == "kg" and info[k].domain == ">0"]
    box: Dict[str, Tuple[float, float]] = {}
    for rng, what in ((k_range, "stiffness"), (jm_range, "rotor_inertia"), (bm_range, "damping"),
                      (mass_range, "link mass")):
        if rng is None:
            continue
        if what == "stiffness":
            lst = [model.param_names[i] for i in linear_stiffness_indices(model, "k_range")]
        else:
            lst = masses if what == "link mass" else role_names(model, what)
        if not lst:
            raise ValueError(f"model {model.name!r} has no {what.replace('_', ' ')} parameter; "
                             f"parameters: {list(model.param_names)}")
        for nm in lst:
            box[nm] = (float(rng[0]), float(rng[1]))
    box.update(extra or {})
    return box


def check_box(model, p_nom: np.ndarray, box) -> Dict[str, Tuple[float, float]]:
    """Validated parameter box: known names, finite ``lo <= hi``; degenerate intervals dropped.

    Parameters
    ----------
    model : Model
    p_nom : ndarray, shape (len(param_names),)
        Nominal parameters (kept for the signature of the callers).
    box : dict name -> (lo, hi) or None

    Returns
    -------
    dict name -> (float, float)
        Only the intervals with ``lo < hi``.
    """
    out = {}
    for name, rng in (box or {}).items():
        if name not in model.param_names:
            raise ValueError(f"param_box: unknown parameter {name!r}; expected one of {list(model.param_names)}")
        try:
            lo, hi = (float(v) for v in rng)
        except (TypeError, ValueError):
            raise ValueError(f"param_box[{name!r}] = {rng!r}: expected (lo, hi)") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            raise ValueError(f"param_box[{name!r}] = {rng!r}: expected finite lo <= hi")
        if lo < hi:
            out[name] = (lo, hi)
    return out


def per_joint(value, rows: int, n: int, field: str) -> np.ndarray:
    """Bounds per joint: ``value`` of shape ``(rows,)`` (same for every joint) or ``(rows, n)``.

    Returns
    -------
    ndarray, shape (rows, n)
        Finite values ``>= 0``; ``ValueError`` naming ``field`` otherwise.
    """
    a = np.asarray(value, dtype=float)
    if a.ndim == 1 and a.shape == (rows,):
        a = np.repeat(a[:, None], n, axis=1)
    if a.shape != (rows, n) or not np.all(np.isfinite(a)) or np.any(a < 0):
        raise ValueError(f"{field} with shape {np.shape(value)}: expected {rows} finite values >= 0 "
                         f"(shape ({rows},) or ({rows}, {n}))")
    return a


# ---------------------------------------------------------------------------------------------
# the box: coordinates, affinity classification, grid
@dataclass
class Dim:
    """One coordinate of the box: a nominal coordinate ``y_hat`` (kind ``'y'``) or a parameter (``'p'``).

    ``affine``: the analysed outputs are affine along it (two vertices suffice);
    ``constant``: they do not depend on it (one point); otherwise ``points`` grid points.
    """

    name: str
    kind: str          # 'y' or 'p'
    index: int         # index into y (4n) or into the parameter vector
    lo: float
    hi: float
    affine: bool = False
    points: int = 2
    constant: bool = False

    def values(self) -> np.ndarray:
        """Grid values along this coordinate, shape (1,), (2,) or (points,)."""
        if self.lo == self.hi or self.constant:
            return np.array([0.5 * (self.lo + self.hi)])
        return np.array([self.lo, self.hi]) if self.affine else np.linspace(self.lo, self.hi, self.points)


def box_dims(model, Ybox: np.ndarray, p_nom, box) -> List[Dim]:
    """Coordinates of the box: ``y_hat`` (block-major, shape of ``Ybox`` (4, n)) then the parameters of ``box``."""
    n = int(model.n)
    names = ("q", "dq", "ddq", "dddq")
    dims = []
    for k in range(4):
        for i in range(n):
            Y = float(Ybox[k, i])
            dims.append(Dim(f"y{k + 1}[{i + 1}] ({names[k]}{i + 1})", "y", k * n + i, -Y, Y))
    pn = list(model.param_names)
    for name, (lo, hi) in box.items():
        dims.append(Dim(name, "p", pn.index(name), lo, hi))
    return dims


def assemble(dims: List[Dim], pts: np.ndarray, n: int, p_nom: np.ndarray):
    """Points of the box (``pts`` (N, len(dims)), one column per dim) -> ``(Y (N, 4n), P (N, npar))``.

    Parameters not in ``dims`` keep their nominal value ``p_nom`` (npar,).
    """
    N = pts.shape[0]
    Y = np.zeros((N, 4 * n))
    P = np.repeat(p_nom[None, :], N, axis=0)
    for d, dim in enumerate(dims):
        (Y if dim.kind == "y" else P)[:, dim.index] = pts[:, d]
    return Y, P


def classify_affine(dims, evaluate, n, p_nom, rng, n_test: int = 48, tol: float = 1e-7, relevant=None) -> None:
    """Mark the coordinates along which the outputs are affine (numerical midpoint/third-point test).

    ``relevant``: indices of the outputs that enter ``Phi``; a coordinate that none of
    them depends on is marked ``constant`` (one grid point; the torque bound then
    handles it separately).
    """
    lo = np.array([d.lo for d in dims]); hi = np.array([d.hi for d in dims])
    base = lo + (hi - lo) * rng.random((n_test, len(dims)))
    for d, dim in enumerate(dims):
        if dim.lo == dim.hi:
            dim.affine = True
            continue
        fr = np.array([0.0, 1.0, 0.5, 1.0 / 3.0])
        pts = np.repeat(base, fr.size, axis=0)
        pts[:, d] = np.tile(dim.lo + fr * (dim.hi - dim.lo), n_test)
        Y, P = assemble(dims, pts, n, p_nom)
        V = evaluate(Y, P).reshape(n_test, fr.size, -1)
        a, b, m, t = V[:, 0], V[:, 1], V[:, 2], V[:, 3]
        scale = 1.0 + np.max(np.abs(V))
        err = max(np.max(np.abs(m - 0.5 * (a + b))), np.max(np.abs(t - (2 * a + b) / 3.0)))
        dim.affine = bool(err <= tol * scale)
        if relevant is not None:
            ra, rb, rm = a[:, relevant], b[:, relevant], m[:, relevant]
            rs = 1.0 + np.max(np.abs(V[:, :, relevant]))
            dim.constant = bool(dim.affine and np.max(np.abs(rb - ra)) <= tol * rs and
                                np.max(np.abs(rm - ra)) <= tol * rs)


def box_maximize(fg, v0: np.ndarray, maxiter: int = 60, tol: float = 1e-12) -> np.ndarray:
    """Projected gradient ascent on ``[0, 1]^d`` with an adaptive step (NumPy only, no SciPy).

    ``fg(v) -> (value, gradient)``. Accepts a step when the value increases
    (then grows the step 1.5x), halves it otherwise; stops when the step falls
    below ``tol`` or after ``maxiter`` accepted-or-rejected trials. Returns the best ``v``.
    """
    v = np.clip(np.asarray(v0, dtype=float), 0.0, 1.0)
    f, g = fg(v)
    step = 0.1
    for _ in range(maxiter):
        norm = float(np.linalg.norm(g))
        if norm == 0.0 or step < tol:
            break
        cand = np.clip(v + step * g / norm, 0.0, 1.0)
        if np.array_equal(cand, v):
            break
        fc, gc = fg(cand)
        if fc > f:
            v, f, g = cand, fc, gc
            step *= 1.5
        else:
            step *= 0.5
    return v


def stiffness_names(model) -> List[str]:
    """Names of the linear joint stiffnesses of ``model`` (``model.drives``): ``['K']`` (link1) or
    ``['K1', ..., 'Kn']``; empty for nonlinear springs."""
    return [model.param_names[i] for i in linear_springs(model)]



def default_stiffness_box(model, nominal_params=None) -> Dict[str, Tuple[float, float]]:
    """Every joint stiffness over ``[2/3, 4/3]`` of its nominal value (``100..200`` at ``K = 150``).

    Parameters
    ----------
    model : Model
    nominal_params : dict or array_like, optional

    Returns
    -------
    dict name -> (lo, hi)
    """
    p_nom = model.params_array(nominal_params or {}, arg="nominal_params")
    box = {}
    for name in stiffness_names(model):
        k0 = float(p_nom[model.param_names.index(name)])
        box[name] = (k0 * 2.0 / 3.0, k0 * 4.0 / 3.0)
    return box
