"""The state at rest holding gravity: where a sampled-data run on a gravity-loaded arm starts."""
from __future__ import annotations

import numpy as np

__all__ = ["rest_state"]


def rest_state(model, q, p) -> np.ndarray:
    """State at rest at link angles ``q`` holding gravity: ``q_m = q + K^-1 G(q)`` (parameters ``p``).

    ``G(q) = -D(q) ddq`` with ``ddq`` the link acceleration of ``f`` at ``q_m = q``, ``dq = 0``.

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
    ddq = np.asarray(model.f(x, p), dtype=float).ravel()[n:2 * n]
    G = -np.asarray(model.inertia(x, p), dtype=float) @ ddq
    pv = model.params_array(p)
    K = pv[[list(model.param_names).index(f"K{i + 1}") for i in range(n)]]
    x[2 * n:3 * n] = q + G / K
    return x
