"""The state at rest holding gravity: where a sampled-data run on a gravity-loaded arm starts."""
from __future__ import annotations

import numpy as np

from ..drives import model_springs

__all__ = ["rest_state"]


def rest_state(model, q, p) -> np.ndarray:
    """State at rest at link angles ``q`` holding gravity: ``q_m = q + K^-1 G(q)`` (parameters ``p``), or
    ``q_m = q + psi^-1(G(q))`` for a nonlinear spring (the model's ``spring_inverse``).

    ``G(q) = -D(q) ddq`` with ``ddq`` the link acceleration of ``f`` at ``q_m = q``, ``dq = 0`` (for a
    complete model, the link rows of ``-M [ddq; ddq_m]`` with its coupled inertia ``M`` (2n, 2n)).

    Parameters
    ----------
    model : Model
    q : array_like, shape (n,)
        Link angles (rad).
    p : dict or array_like or None
        Parameters (``None``: the defaults); a controller's start uses the NOMINAL ones.

    Returns
    -------
    ndarray, shape (4n,)
        ``[q; 0; q + K^-1 G(q); 0]``.
    """
    n = int(model.n)
    q = np.asarray(q, dtype=float)
    x = np.concatenate([q, np.zeros(n), q, np.zeros(n)])
    f = np.asarray(model.f(x, p), dtype=float).ravel()
    M = np.atleast_2d(np.asarray(model.inertia(x, p), dtype=float))
    # the reduced model's inertia is the links' D (n, n); a complete model's couples links and motors (2n, 2n)
    acc = f[n:2 * n] if M.shape[0] == n else np.concatenate([f[n:2 * n], f[3 * n:4 * n]])
    G = -(M @ acc)[:n]
    # the deflection that carries G: psi^-1(G) of the model's spring law (G / K for a linear one)
    phi = model_springs(model)["spring_inverse"](G, np.asarray(model.params_array(p), dtype=float))
    x[2 * n:3 * n] = q + np.asarray(phi, dtype=float).ravel()
    return x
