"""The complete elastic model against an independent Pinocchio build (rotor bodies as their own joints).

The reference (:mod:`support.complete_pinocchio`) takes the links from
Pinocchio's URDF parser (Panda) or its model-building API (planar2) and appends
one revolute rotor joint per link joint; fjm's emitted ``inertia`` (the whole
M), the bias forces and the forward dynamics ``f + g u`` must match it at
random states, torques and parameters to a relative 1e-10.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import fjm_runtime

from support.complete_pinocchio import CompleteReference
from support.independent_chain import pinocchio_chain
from support.paths import REPO

RTOL = 1e-10
SAMPLES = 20


def _rel(a, b):
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)


def _reference(name, p):
    m = fjm_runtime.load(name)
    n = m.n
    dflt = m.default_params
    get = lambda g, src: np.array([src[f"{g}{i}"] for i in range(1, n + 1)])
    if name == "panda_complete":
        links = pin.buildModelFromUrdf(str(REPO / m.manifest["source"]["urdf"]))
        links.gravity.linear[:] = [0.0, 0.0, -p["g0"]]
        # the definition: I_t = I_a / 2 at the default J_m and N (baked), no rotor mass
        It = get("Jm", dflt) / (2 * get("N", dflt) ** 2)
    else:
        links = pinocchio_chain(p, n)
        It = np.zeros(n)
    return m, CompleteReference(links, get("N", p), get("Jm", p) / get("N", p) ** 2, It, np.zeros(n)), get


@pytest.mark.parametrize("name", ["planar2_complete", "panda_complete"])
def test_complete_model_matches_pinocchio(name):
    rng = np.random.default_rng(7)
    m0 = fjm_runtime.load(name)
    for k in range(SAMPLES):
        p = dict(m0.default_params)
        for key in p:  # random elastic parameters and gear ratios (baked numbers stay)
            if key[:1] in ("K", "N") or key.startswith("Jm") or key.startswith("Bm"):
                p[key] = p[key] * rng.uniform(0.5, 2.0) + (rng.uniform(0, 1) if key.startswith("Bm") else 0)
        m, ref, get = _reference(name, p)
        n = m.n
        q, dq = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n)
        x = np.concatenate([q, dq, q + rng.uniform(-0.05, 0.05, n), rng.uniform(-50, 50, n)])
        u = rng.uniform(-20, 20, n)
        M = m.inertia(x, p)
        assert _rel(M, ref.inertia(q)) < RTOL
        xd = m.xdot(x, u, p)
        assert _rel(xd, ref.xdot(x, u, get("K", p), get("Bm", p))) < RTOL
        # bias: M [ddq; ddq_m] + b = [K (q_m - q); K (q - q_m) - B_m dq_m + u]
        qm, dqm = x[2 * n:3 * n], x[3 * n:]
        Kv = get("K", p)
        tau = np.concatenate([Kv * (qm - q), Kv * (q - qm) - get("Bm", p) * dqm + u])
        b = tau - M @ np.concatenate([xd[n:2 * n], xd[3 * n:]])
        assert _rel(b, ref.bias(q, dq, dqm)) < RTOL, k
