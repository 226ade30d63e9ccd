"""The link equation's joint torque from a model's generated functions (no joint-torque sensor needed)."""
from __future__ import annotations

import numpy as np

__all__ = ["link_torque"]


def link_torque(model, q, dq, ddq, p) -> np.ndarray:
    """``tau_J = D(q) ddq + h(q, dq)`` per sample, shape (N, n).

    From the model's ``f`` and ``inertia`` at parameters ``p``: ``f``'s link rows at ``q_m = q`` (no
    spring torque) are ``-D^-1 h``, so ``tau_J = D (ddq - f_link(q, dq, q_m = q))``.

    Parameters
    ----------
    model : Model
    q, dq, ddq : ndarray, shape (N, n)
    p : ndarray, shape (n_par,)
    """
    q, dq, ddq = (np.asarray(v, dtype=float) for v in (q, dq, ddq))
    n, N = int(model.n), q.shape[0]
    X = np.concatenate([q, dq, q, np.zeros_like(dq)], axis=1).T
    P = np.repeat(np.asarray(p, dtype=float)[:, None], N, axis=1)
    a0 = np.asarray(model.functions["f"].map(N)(X, P))[n:2 * n].T
    D = np.asarray(model.functions["inertia"].map(N)(X, P)).reshape(n, N, n)   # [i, k, j] = D_k[i, j]
    return np.einsum("kij,kj->ki", np.transpose(D, (1, 0, 2)), ddq - a0)
