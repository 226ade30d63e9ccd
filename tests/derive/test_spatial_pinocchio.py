"""Spatial arms from URDF against Pinocchio on the very same URDF files.

Pinocchio parses the URDF itself (urdfdom-style) and runs its own rigid-body
algorithms (crba, rnea, aba); fixed joints, including the Panda's (fixed)
fingers, are merged into their parent body by Pinocchio too. Gravity is set
to ``g0`` along ``-z``. At >= 50 random states per model:

* ``inertia(x, p)`` == ``crba(q)`` (Pinocchio fills the upper triangle);
* ``h = -D ddq - K (q - q_m)`` from the link rows of ``f`` == ``rnea(q, dq, 0)``;
* the link accelerations of ``f`` == ``aba(q, dq, K (q_m - q))``;

each to a relative error <= 1e-10.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import fjm_runtime

from support.paths import REPO  # noqa: E402
SPATIAL = ("elbow3", "panda")
RTOL = 1e-10
SAMPLES = 60


def pinocchio_model(name):
    """Pinocchio model of the URDF recorded in the manifest, and a q -> q_pin map."""
    m = fjm_runtime.load(name)
    src = m.manifest["source"]
    urdf = REPO / src["urdf"]
    model = pin.buildModelFromUrdf(str(urdf))
    model.gravity.linear[:] = [0.0, 0.0, -float(m.default_params["g0"])]
    names = [model.names[j] for j in range(1, model.njoints)]
    assert names == src["joints"], (names, src["joints"])
    nqs = [model.joints[j].nq for j in range(1, model.njoints)]

    def q_pin(q):  # continuous joints are (cos, sin) in Pinocchio
        out = []
        for qi, nq in zip(q, nqs):
            out += [np.cos(qi), np.sin(qi)] if nq == 2 else [qi]
        return np.array(out)

    fid = model.getFrameId(src["tip"])
    tip = model.frames[fid].placement  # tip link frame in the last joint's frame
    return m, model, model.createData(), q_pin, tip


def states(m, rng, count):
    n = m.n
    for _ in range(count):
        q = rng.uniform(-np.pi, np.pi, n)
        dq = rng.uniform(-2, 2, n)
        qm = q + rng.uniform(-0.05, 0.05, n)
        dqm = dq + rng.uniform(-0.5, 0.5, n)
        yield np.concatenate([q, dq, qm, dqm])


def rel(a, b):
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / max(1e-300, np.max(np.abs(b))))


@pytest.mark.parametrize("name", SPATIAL)
def test_inertia_bias_and_forward_dynamics_match_pinocchio(name):
    m, model, data, q_pin, tip = pinocchio_model(name)
    n = m.n
    body = model.inertias[n].copy()
    rng = np.random.default_rng(sum(map(ord, name)))
    worst = {"crba": 0.0, "rnea": 0.0, "aba": 0.0}
    for k, x in enumerate(states(m, rng, SAMPLES)):
        p = dict(m.default_params)
        if k % 2:  # other stiffnesses, motor inertias, damping and gravity too
            for key in p:
                p[key] = p[key] * rng.uniform(0.5, 2.0) if not key.startswith("Bm") else rng.uniform(0, 1)
        if "m_load" in p:  # a point payload fixed to the tip link: added to the last body in Pinocchio
            p["m_load"] = rng.uniform(0, 3) if k % 3 else 0.0
            com = rng.uniform(-0.15, 0.15, 3)
            p.update(x_load=com[0], y_load=com[1], z_load=com[2])
            model.inertias[n] = body + pin.Inertia(p["m_load"], tip.act(com), np.zeros((3, 3)))
        K = np.array([p[f"K{i + 1}"] for i in range(n)])
        model.gravity.linear[:] = [0.0, 0.0, -p["g0"]]
        q, dq, qm = x[:n], x[n:2 * n], x[2 * n:3 * n]
        qp = q_pin(q)
        M = pin.crba(model, data, qp)
        M = np.triu(M) + np.triu(M, 1).T
        D = m.inertia(x, p)
        worst["crba"] = max(worst["crba"], rel(D, M))
        ddq = m.f(x, p)[n:2 * n]
        b = pin.rnea(model, data, qp, dq, np.zeros(n))
        h = -D @ ddq - K * (q - qm)
        # h is a difference of terms of size |D ddq| ~ |K (q - q_m)|: relative to the largest
        worst["rnea"] = max(worst["rnea"], float(np.max(np.abs(h - b)))
                            / max(np.max(np.abs(b)), np.max(np.abs(K * (q - qm)))))
        a = pin.aba(model, data, qp, dq, K * (qm - q))
        worst["aba"] = max(worst["aba"], rel(ddq, a))
    print(name, {k: f"{v:.1e}" for k, v in worst.items()})
    assert max(worst.values()) <= RTOL, (name, worst)


@pytest.mark.parametrize("name", SPATIAL)
def test_energy_matches_pinocchio(name):
    """Kinetic + potential energy of the links == Pinocchio's (plus motors and springs)."""
    m, model, data, q_pin, _ = pinocchio_model(name)
    n = m.n
    rng = np.random.default_rng(3)
    p = m.default_params
    K = np.array([p[f"K{i + 1}"] for i in range(n)])
    Jm = np.array([p[f"Jm{i + 1}"] for i in range(n)])
    for x in states(m, rng, 10):
        q, dq, qm, dqm = (x[k * n:(k + 1) * n] for k in range(4))
        qp = q_pin(q)
        kin = pin.computeKineticEnergy(model, data, qp, dq)
        pot = pin.computePotentialEnergy(model, data, qp)
        # Pinocchio's potential is -sum m g . c (zero at the base origin), like ours
        expected = kin + pot + 0.5 * Jm @ dqm ** 2 + 0.5 * K @ (q - qm) ** 2
        assert abs(m.energy(x, p) - expected) <= 1e-10 * max(1.0, abs(expected)), (m.energy(x, p), expected)


@pytest.mark.parametrize("name", SPATIAL)
def test_manifest_records_the_urdf_source(name):
    import hashlib
    m = fjm_runtime.load(name)
    src = json.loads((m.directory / "manifest.json").read_text())["source"]
    assert set(src) >= {"urdf", "sha256", "base", "tip", "joints"}
    urdf = REPO / src["urdf"]
    assert hashlib.sha256(urdf.read_bytes()).hexdigest() == src["sha256"]
    assert len(src["joints"]) == m.n
    elastic = tuple(f"{g}{i}" for g in ("K", "Jm", "Bm") for i in range(1, m.n + 1)) + ("g0",)
    assert m.param_names in (elastic, elastic + ("m_load", "x_load", "y_load", "z_load"))
