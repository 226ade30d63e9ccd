"""CasADi evaluation of the certificate's quantities on batches of box points.

``x = T^{-1}(y_hat; p)`` by batched Newton on the motor half of ``T`` (the link
half is the identity: ``y1 = q_l``, ``y2 = dq_l``), then one CasADi Function of
``(x, y, p)`` mapped over the batch. Everything comes from the generated model
functions (``T``, ``f``, ``g``, ``alpha``, ``beta``).
"""
from __future__ import annotations

import numpy as np

def build_inverse(model, p_const=None):
    """CasADi Function ``(x, y, p) -> (T_m(x; p) - y_m, dT_m/dx_m)`` for Newton on the motor half of ``T``.

    ``T`` keeps ``q_l`` and ``dq_l`` as they are (``y1 = q_l``, ``y2 = dq_l``), so
    ``x = T^{-1}(y)`` only needs ``q_m``, ``dq_m``. ``p_const``: a fixed parameter
    vector (the nominal one) instead of the argument ``p``.
    """
    import casadi as ca
    n, nx, npar = int(model.n), int(model.nx), len(model.param_names)
    x = ca.SX.sym("x", nx)
    y = ca.SX.sym("y", nx)
    p = ca.SX.sym("p", npar)
    pp = ca.DM(p_const) if p_const is not None else p
    Tm = model.functions["T"](x, pp)[2 * n:]
    return ca.Function("tune_newton", [x, y, p], [Tm - y[2 * n:], ca.jacobian(Tm, x[2 * n:])])


def build_nominal_fn(model, p_nom: np.ndarray, c_last: np.ndarray, beta_hat):
    """CasADi Function ``(x, y, p) -> [F0; vec G; alpha_hat; vec B; vec C J g]``.

    The quantities of :mod:`fjm_runtime.analysis.certificates.certify` (its module docstring): ``x`` (4n,),
    ``y`` = ``y_hat`` (4n,), ``p`` the TRUE parameters; output shape ``(2n + 3n^2, 1)``.
    """
    import casadi as ca
    n, nx, npar = int(model.n), int(model.nx), len(model.param_names)
    fns = model.functions
    x = ca.SX.sym("x", nx)
    y = ca.SX.sym("y", 4 * n)
    p = ca.SX.sym("p", npar)
    pn = ca.DM(p_nom)
    J = ca.jacobian(fns["T"](x, pn), x)
    C = ca.horzcat(*[float(c_last[k]) * ca.SX.eye(n) for k in range(3)], ca.SX.eye(n))
    f = fns["f"](x, p)
    g = ca.reshape(fns["g"](x, p), nx, n)
    a_hat = fns["alpha"](x, pn)
    B = ca.SX(ca.DM(beta_hat)) if beta_hat is not None else ca.reshape(fns["beta"](x, pn), n, n)
    CJ = ca.mtimes(C, J)
    lin = float(c_last[0]) * y[n:2 * n] + float(c_last[1]) * y[2 * n:3 * n] + float(c_last[2]) * y[3 * n:]
    F0 = ca.mtimes(CJ, f + ca.mtimes(g, a_hat)) - lin
    G = ca.mtimes(ca.mtimes(CJ, g), B)
    CJg = ca.mtimes(CJ, g)
    out = ca.vertcat(F0, ca.reshape(G, n * n, 1), a_hat, ca.reshape(B, n * n, 1), ca.reshape(CJg, n * n, 1))
    return ca.Function("tune_nominal", [x, y, p], [out])


def build_true_fn(model, p_nom: np.ndarray):
    """``(x, y, p) -> [alpha(x; p_nom) - alpha(x; p); beta(x; p)]`` (true coordinates, ``x = T^{-1}(y; p)``)."""
    import casadi as ca
    n, nx, npar = int(model.n), int(model.nx), len(model.param_names)
    fns = model.functions
    x = ca.SX.sym("x", nx)
    y = ca.SX.sym("y", nx)
    p = ca.SX.sym("p", npar)
    d_alpha = fns["alpha"](x, ca.DM(p_nom)) - fns["alpha"](x, p)
    beta = ca.reshape(fns["beta"](x, p), n * n, 1)
    return ca.Function("tune_true", [x, y, p], [ca.vertcat(d_alpha, beta)])


class Evaluator:
    """Batched ``(Y, P) -> values``: ``x = T^{-1}(y; p_inv)`` by batched Newton, then ``fn(x, y, p)``.

    Chunks of columns through cached ``Function.map``; the Newton residual of
    every point is checked (``ValueError`` when it does not converge).
    """

    #: Newton steps at most (a point that needs more is reported as not converged).
    MAX_ITERATIONS = 40

    def __init__(self, model, fn, p_inverse=None, chunk: int = 20000, iterations: int = 4):
        self.model, self.n, self.nx = model, int(model.n), int(model.nx)
        self.inv = build_inverse(model, p_inverse)
        self.fn, self.chunk, self.maps, self.iterations = fn, chunk, {}, iterations
        #: ``[min, max]`` of the deflection ``q_m - q`` per joint over every state evaluated, (n, 2)
        #: (a nonlinear spring's certificate holds on the stiffness there: analysis.certificates.spring_interval)
        self.deflection = np.tile([np.inf, -np.inf], (self.n, 1))

    def _map(self, fn, m):
        key = (fn.name(), m)
        fm = self.maps.get(key)
        if fm is None:
            fm = self.maps[key] = fn.map(m)
        return fm

    def __call__(self, Y: np.ndarray, P: np.ndarray) -> np.ndarray:
        """Values at the points ``Y`` (N, 4n) with parameters ``P`` (N, npar); shape (N, outputs)."""
        N, n = Y.shape[0], self.n
        out = []
        for a in range(0, N, self.chunk):
            b = min(N, a + self.chunk)
            m = b - a
            Yc, Pc = Y[a:b], P[a:b]
            X = np.concatenate([Yc[:, :2 * n], Yc[:, :2 * n]], axis=1)
            inv = self._map(self.inv, m)
            scale = 1.0 + np.max(np.abs(Yc), axis=1)
            # ``iterations`` steps always (a linear spring is exact after one); a nonlinear spring's
            # coordinates (psi, psi' of q_m - q) take a few more: continue while any point is off
            for k in range(self.MAX_ITERATIONS):
                r, J = inv(X.T, Yc.T, Pc.T)
                r = np.asarray(r).T
                if k >= self.iterations and np.all(np.max(np.abs(r), axis=1) <= 1e-12 * scale):
                    break  # r is the residual at the X the values are taken at
                J = np.asarray(J).reshape(2 * n, m, 2 * n).transpose(1, 0, 2)
                X[:, 2 * n:] -= np.linalg.solve(J, r[:, :, None])[:, :, 0]
            else:  # the last step's residual
                r = np.asarray(inv(X.T, Yc.T, Pc.T)[0]).T
            bad = ~(np.max(np.abs(r), axis=1) <= 1e-8 * scale)
            if np.any(bad):
                j = int(np.flatnonzero(bad)[0])
                raise ValueError(f"T^(-1): Newton did not converge at y = {np.round(Yc[j], 4).tolist()} "
                                 f"(residual {np.max(np.abs(r[j])):.3g}); the box may be too large for this model")
            phi = X[:, 2 * n:3 * n] - X[:, :n]
            self.deflection[:, 0] = np.minimum(self.deflection[:, 0], phi.min(axis=0))
            self.deflection[:, 1] = np.maximum(self.deflection[:, 1], phi.max(axis=0))
            out.append(np.asarray(self._map(self.fn, m)(X.T, Yc.T, Pc.T)).T)
        return np.concatenate(out, axis=0)



_STATE_EVALUATORS: dict = {}     # id(model) -> Evaluator of x itself (the inverse alone)


def inverse_T(model, y, p) -> np.ndarray:
    """``x = T^{-1}(y; p)`` from the model's ``T`` by Newton (broadcasts over leading axes of ``y``).

    Parameters
    ----------
    model : Model
    y : array_like, shape (..., 4n)
        Linearizing coordinates.
    p : dict or array_like
        Parameters (``model.params_array``), the same for every point.

    Returns
    -------
    ndarray, shape (..., 4n)
        ``ValueError`` when Newton does not converge at some point.
    """
    import casadi as ca
    y = np.asarray(y, dtype=float)
    nx = int(model.nx)
    if y.shape[-1:] != (nx,):
        raise ValueError(f"y with shape {y.shape}: expected (..., {nx})")
    pv = np.asarray(model.params_array(p), dtype=float)
    ev = _STATE_EVALUATORS.get(id(model))
    if ev is None or ev.model is not model:
        xs, ys, ps = ca.SX.sym("x", nx), ca.SX.sym("y", nx), ca.SX.sym("p", pv.size)
        ev = _STATE_EVALUATORS[id(model)] = Evaluator(model, ca.Function("state", [xs, ys, ps], [xs]))
    Y = y.reshape(-1, nx)
    if Y.shape[0] == 0:
        return np.zeros(y.shape)
    X = ev(Y, np.repeat(pv[None, :], Y.shape[0], axis=0))
    return X.reshape(y.shape)
