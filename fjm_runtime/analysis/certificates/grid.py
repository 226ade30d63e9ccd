"""The reaching condition ``Phi`` on a grid of the box: supremum, curvature margin, refinement, gain.

For the formulas (``F0``, ``G``, ``W``, ``Phi_i``) see :mod:`fjm_runtime.analysis.certificates.certify`.
:class:`BoxAnalysis` samples the box once for one model and setting; :func:`solve_gain`
is the fixed point ``k_i = sup (drift + eta_i + cross coupling) / G_ii``.
"""
from __future__ import annotations

from itertools import product

import numpy as np

from .box import assemble, box_dims, box_maximize, check_box, classify_affine, per_joint, surface_coefficients
from .evaluator import Evaluator, build_nominal_fn


def nominal_setup(model, nominal_params, param_box, reference_bounds, error_bounds, lam, c, integral,
                   beta_hat):
    """Validated inputs of a synthesis on the box.

    Returns
    -------
    p_nom : ndarray, shape (npar,)
    box : dict name -> (lo, hi)
    cc : ndarray, shape (3,) or (4,)
        Surface coefficients, lowest first.
    R : ndarray, shape (5, n)
    E : ndarray, shape (4, n)
    Ybox : ndarray, shape (4, n)
        Half-widths ``R[:4] + E`` of ``|y_hat_k|``.
    W : ndarray, shape (n,)
        Bound of ``|w|``.
    bh : ndarray, shape (n, n), or None
        Constant ``beta_hat``.
    """
    n = int(model.n)
    p_nom = np.asarray(model.params_array(nominal_params or {}, arg="nominal_params"), dtype=float)
    box = check_box(model, p_nom, param_box)
    cc = surface_coefficients(lam, c, integral)
    R = per_joint(reference_bounds, 5, n, "reference_bounds")
    E = per_joint(error_bounds, 4, n, "error_bounds")
    Ybox = R[:4] + E
    ce = np.concatenate([[0.0], cc]) if not integral else cc       # coefficient of e1 .. e4 in `linear`
    W = R[4] + ce[0] * E[0] + ce[1] * E[1] + ce[2] * E[2] + ce[3] * E[3] if integral else \
        R[4] + cc[0] * E[1] + cc[1] * E[2] + cc[2] * E[3]
    bh = None
    if beta_hat is not None:
        bh = np.asarray(beta_hat, dtype=float)
        bh = bh * np.eye(n) if bh.ndim == 0 else bh
        if bh.shape != (n, n):
            raise ValueError(f"beta_hat with shape {bh.shape}: expected a scalar or ({n}, {n})")
    return p_nom, box, cc, R, E, Ybox, np.asarray(W, dtype=float), bh


class BoxAnalysis:
    """Grid of the box and the values ``F0``, ``G``, ``alpha_hat``, ``B`` on it (one model, one setting)."""

    def __init__(self, model, p_nom, box, cc, Ybox, W, beta_hat, budget: int, seed: int, n_grid=None,
                 D=None, evaluator=None):
        self.model, self.n = model, int(model.n)
        self.D = np.zeros(self.n) if D is None else np.asarray(D, dtype=float)
        self.p_nom, self.W, self.Ybox = p_nom, W, Ybox
        if evaluator is None:       # the state-feedback law; else evaluator(model, p_nom, c_last, beta_hat)
            self.fn = build_nominal_fn(model, p_nom, cc[-3:], beta_hat)
            self.ev = Evaluator(model, self.fn, p_inverse=p_nom)
        else:
            self.ev = evaluator(model, p_nom, cc[-3:], beta_hat)
            self.fn = self.ev.fn
        self.rng = np.random.default_rng(seed)
        self.dims = box_dims(model, Ybox, p_nom, box)
        n = self.n
        relevant = np.r_[0:n + n * n, 2 * n + 2 * n * n:2 * n + 3 * n * n]      # F0, G, C J g
        classify_affine(self.dims, self.ev, self.n, p_nom, self.rng, relevant=relevant)
        nl = [d for d in self.dims if not d.affine and d.lo < d.hi]
        n_vert = int(np.prod([len(d.values()) for d in self.dims if d.affine or d.lo == d.hi]))
        self.random = False
        if n_grid is None:
            per = int(np.floor((budget / max(n_vert, 1)) ** (1.0 / max(len(nl), 1)) + 1e-9))
            n_grid = max(3, per)
            self.random = n_vert * float(n_grid) ** len(nl) > 4 * budget
        for d in nl:
            d.points = int(n_grid)
        if self.random:
            # too many coordinates for a grid: uniform samples, affine coordinates at random vertices
            N = int(budget)
            mesh = np.empty((N, len(self.dims)))
            for j, d in enumerate(self.dims):
                v = d.values()
                if d.affine or d.lo == d.hi:
                    mesh[:, j] = v[self.rng.integers(0, len(v), N)]
                else:
                    mesh[:, j] = self.rng.uniform(d.lo, d.hi, N)
            self.shape = None
        else:
            axes = [d.values() for d in self.dims]
            self.shape = tuple(len(a) for a in axes)
            mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(self.dims))
        self.pts = mesh
        Y, P = assemble(self.dims, mesh, self.n, p_nom)
        V = self.ev(Y, P)
        self._unpack(V)

    def split(self, V):
        """V (N, outputs) -> ``(|F0| + |C J g| D, G)`` from raw values: the drift bound including the matched disturbance."""
        n = self.n
        F0 = np.abs(V[:, :n])
        if np.any(self.D > 0):
            CJg = V[:, 2 * n + 2 * n * n:2 * n + 3 * n * n].reshape(-1, n, n, order="F")
            F0 = F0 + np.abs(CJg) @ self.D
        return F0, V[:, n:n + n * n].reshape(-1, n, n, order="F")

    def _unpack(self, V):
        n = self.n
        self.F0, self.G = self.split(V)
        self.ah = V[:, n + n * n:2 * n + n * n]
        self.B = V[:, 2 * n + n * n:2 * n + 2 * n * n].reshape(-1, n, n, order="F")

    def u_bound(self, k, top: int = 200) -> np.ndarray:
        """``sup |u_i| = |alpha_hat_i| + sum_j |B_ij| (W_j + k_j)`` on the grid; coordinates collapsed
        as irrelevant for ``Phi`` (but affine) are put back at their vertices around the worst points."""
        n = self.n
        U = np.abs(self.ah) + np.abs(self.B) @ (self.W + k)
        collapsed = [d for d, dim in enumerate(self.dims) if dim.constant and dim.lo < dim.hi]
        best = np.max(U, axis=0)
        if not collapsed:
            return best
        idx = np.unique(np.concatenate([np.argsort(-U[:, i])[:top] for i in range(n)]))
        combos = np.array(list(product(*[(self.dims[d].lo, self.dims[d].hi) for d in collapsed])))
        pts = np.repeat(self.pts[idx], len(combos), axis=0)
        pts[:, collapsed] = np.tile(combos, (len(idx), 1))
        Y, P = assemble(self.dims, pts, n, self.p_nom)
        V = self.ev(Y, P)
        ah = V[:, n + n * n:2 * n + n * n]
        B = V[:, 2 * n + n * n:2 * n + 2 * n * n].reshape(-1, n, n, order="F")
        return np.maximum(best, np.max(np.abs(ah) + np.abs(B) @ (self.W + k), axis=0))

    # Phi on a set of values
    @staticmethod
    def phi(F0, G, W, k) -> np.ndarray:
        """``Phi`` (N, n) from ``F0`` (N, n), ``G`` (N, n, n), ``W`` (n,) and the gain ``k`` (n,)."""
        n = F0.shape[1]
        I = np.eye(n)
        drift = np.abs(F0) + np.abs(G - I) @ W
        absG = np.abs(G)
        diag = np.einsum("nii->ni", G)
        cross = absG @ k - np.einsum("nii->ni", absG) * k
        return drift + cross - diag * k

    def phi_at(self, pts, k):
        """``(Phi (N, n), raw values (N, outputs))`` at box points ``pts`` (N, len(dims))."""
        Y, P = assemble(self.dims, pts, self.n, self.p_nom)
        V = self.ev(Y, P)
        F0, G = self.split(V)
        return self.phi(F0, G, self.W, k), V

    def margin(self, Phi: np.ndarray, kind: str = "curvature") -> np.ndarray:
        """Grid margin per joint: how much ``Phi`` may exceed its grid maximum between grid points.

        ``kind='curvature'``: ``sum_d M_d h_d^2 / 8`` with ``M_d`` the largest NEGATIVE
        curvature along coordinate ``d`` seen in the grid's second differences
        (``Phi <= multilinear interpolant + sum_d M_d h_d^2 / 8`` when ``Phi'' >= -M_d``;
        convex kinks such as ``|F0|`` do not count). ``kind='lipschitz'``:
        ``sum_d L_d h_d / 2`` with ``L_d`` the largest neighbour slope (much coarser).
        Both use slopes/curvatures sampled on the grid: numerical, not proven.
        """
        n = self.n
        if self.shape is None:            # random sampling: no grid, no margin
            return np.zeros(n)
        A = Phi.reshape(self.shape + (n,))
        m = np.zeros(n)
        rest = tuple(range(A.ndim - 1))
        for d, dim in enumerate(self.dims):
            if dim.affine or dim.lo == dim.hi or len(dim.values()) < 2:
                continue
            h = (dim.hi - dim.lo) / (dim.points - 1)
            if kind == "lipschitz":
                m += 0.5 * h * np.max(np.abs(np.diff(A, axis=d)), axis=rest) / h
            else:
                curv = np.max(-np.diff(A, n=2, axis=d), axis=rest) / h ** 2
                m += np.maximum(curv, 0.0) * h ** 2 / 8.0
        return m

    def refine(self, Phi, k, n_starts: int = 4, maxiter: int = 80):
        """Local maximization of ``Phi_i`` from the worst grid points; returns extra points and values."""
        n = self.n
        free = [d for d, dim in enumerate(self.dims) if not dim.affine and dim.lo < dim.hi]
        if not free:
            return np.zeros((0, len(self.dims))), np.zeros((0, n))
        lo = np.array([self.dims[d].lo for d in free]); hi = np.array([self.dims[d].hi for d in free])
        span = hi - lo
        extra = []
        for i in range(n):
            order = np.argsort(-Phi[:, i])[:n_starts]
            for j in order:
                base = self.pts[j].copy()

                def obj(v, base=base, i=i):
                    h = 1e-6
                    V = np.repeat(base[None, :], 2 * len(free) + 1, axis=0)
                    V[0, free] = lo + v * span
                    for a in range(len(free)):
                        V[1 + 2 * a] = V[0]; V[2 + 2 * a] = V[0]
                        V[1 + 2 * a, free[a]] = lo[a] + np.clip(v[a] + h, 0, 1) * span[a]
                        V[2 + 2 * a, free[a]] = lo[a] + np.clip(v[a] - h, 0, 1) * span[a]
                    ph, _ = self.phi_at(V, k)
                    val = ph[:, i]
                    grad = np.empty(len(free))
                    for a in range(len(free)):
                        dv = np.clip(v[a] + h, 0, 1) - np.clip(v[a] - h, 0, 1)
                        grad[a] = (val[1 + 2 * a] - val[2 + 2 * a]) / dv if dv > 0 else 0.0
                    return val[0], grad

                v0 = (base[free] - lo) / span
                vbest = box_maximize(obj, v0, maxiter=maxiter)
                pt = base.copy()
                pt[free] = lo + vbest * span
                extra.append(pt)
        extra = np.array(extra)
        ph, _ = self.phi_at(extra, k)
        return extra, ph


def solve_gain(F0, G, W, eta, max_iter: int = 500):
    """Smallest ``k`` with ``max Phi_i <= -eta_i`` (fixed-point iteration).

    Parameters
    ----------
    F0 : ndarray, shape (N, n)
    G : ndarray, shape (N, n, n)
    W : ndarray, shape (n,)
    eta : ndarray, shape (n,)

    Returns
    -------
    k : ndarray, shape (n,)
        NaN when infeasible.
    reason : str
        Empty when a gain exists, else why not.
    """
    n = F0.shape[1]
    diag = np.einsum("nii->ni", G)
    if np.any(diag <= 0):
        j = int(np.argmin(np.min(diag, axis=1)))
        i = int(np.argmin(diag[j]))
        return np.full(n, np.nan), (f"joint {i + 1}: the input gain G_ii of s_i' is {diag[j, i]:.3g} <= 0 at a "
                                    "point of the box: the switching term does not act on s_i there")
    drift = np.abs(F0) + np.abs(G - np.eye(n)) @ W
    absG = np.abs(G)
    off = absG - np.einsum("nij,ij->nij", absG, np.eye(n))
    k = np.max((drift + eta) / diag, axis=0)
    for _ in range(max_iter):
        k_new = np.max((drift + eta + off @ k) / diag, axis=0)
        if np.all(np.abs(k_new - k) <= 1e-12 * (1 + np.abs(k_new))):
            return k_new, ""
        if not np.all(np.isfinite(k_new)) or np.max(k_new) > 1e15:
            break
        k = k_new
    return np.full(n, np.nan), ("the input gains couple the joints too strongly (G is not diagonally "
                                "dominant on the box): no per-joint constant gain dominates the coupling")


def witness_point(an: "BoxAnalysis", pt: np.ndarray, i: int, k) -> dict:
    """Where joint ``i``'s certificate is attained: ``y_hat`` (4, n), parameters, worst ``w``, sign of ``s``."""
    n = an.n
    Y, P = assemble(an.dims, pt[None, :], n, an.p_nom)
    V = an.ev(Y, P)
    F0 = V[0, :n]
    G = V[0, n:n + n * n].reshape(n, n, order="F")
    sgn = 1.0 if F0[i] >= 0 else -1.0
    w = sgn * np.sign(G[i] - np.eye(n)[i]) * an.W
    CJg = V[0, 2 * n + 2 * n * n:2 * n + 3 * n * n].reshape(n, n, order="F")
    d = sgn * np.sign(CJg[i]) * an.D
    params = {d_.name: float(pt[j]) for j, d_ in enumerate(an.dims) if d_.kind == "p"}
    return {"joint": i + 1, "y_hat": Y[0].reshape(4, n).tolist(), "params": params,
            "w": w.tolist(), "sign_s": sgn, "F0": float(F0[i]), "G_row": G[i].tolist(),
            "disturbance": d.tolist()}

