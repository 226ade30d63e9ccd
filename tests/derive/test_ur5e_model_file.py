"""A 6-joint arm the project was not built around, as a new user derives it: the UR5e from UR's own
description (examples/ur5e/ur5e.urdf) with the model file examples/ur5e.toml.

Derived into a temporary directory, loaded with the runtime and checked against Pinocchio built from
the same URDF by Pinocchio's own parser: ``D(q)`` == ``crba(q)``, gravity ``G(q)`` ==
``computeGeneralizedGravity(q)`` and the bias ``C(q, dq) dq + G(q)`` == ``rnea(q, dq, 0)``, each to
1e-10 relative at random states, with the default and with other gravity; the effort, velocity and
position limits the runtime exposes are the URDF's (Pinocchio's reading of them).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest

from derive.__main__ import main as derive_main  # noqa: E402
from fjm_runtime.model import Model  # noqa: E402

from support.paths import REPO  # noqa: E402

MODEL_FILE = REPO / "examples" / "ur5e.toml"
URDF = REPO / "examples" / "ur5e" / "ur5e.urdf"
JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint")
RTOL = 1e-10
SAMPLES = 40


@pytest.fixture(scope="module")
def ur5e(tmp_path_factory):
    out = tmp_path_factory.mktemp("user") / "models"
    assert derive_main(["--model-file", str(MODEL_FILE), "--out", str(out)]) == 0
    return Model(out / "ur5e")


@pytest.fixture(scope="module")
def reference():
    model = pin.buildModelFromUrdf(str(URDF))
    return model, model.createData()


def test_the_model_is_the_six_urdf_joints(ur5e, reference):
    model, _ = reference
    assert (ur5e.n, ur5e.nx) == (6, 24)
    assert tuple(ur5e.manifest["source"]["joints"]) == JOINTS
    assert tuple(model.names[j] for j in range(1, model.njoints)) == JOINTS and model.nq == 6  # all revolute
    assert ur5e.param_names == tuple(f"{g}{i}" for g in ("K", "Jm", "Bm") for i in range(1, 7)) + ("g0",)


def _rel(a, b):
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(b)))


def test_inertia_gravity_and_bias_match_pinocchio(ur5e, reference):
    model, data = reference
    n = ur5e.n
    rng = np.random.default_rng(5)
    worst = {"D": 0.0, "G": 0.0, "h": 0.0}
    for k in range(SAMPLES):
        p = dict(ur5e.default_params, g0=9.81 if k % 2 else rng.uniform(1.0, 20.0))
        model.gravity.linear[:] = [0.0, 0.0, -p["g0"]]
        q, dq = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2.0, 2.0, n)
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        # at q_m = q the spring is relaxed, so the link rows of f are -D^-1 (C dq + G)
        x_rest = np.concatenate([q, np.zeros(n), q, np.zeros(n)])
        x = np.concatenate([q, dq, q, rng.uniform(-2.0, 2.0, n)])
        D = ur5e.inertia(x, p)
        G = -D @ ur5e.f(x_rest, p)[n:2 * n]
        h = -D @ ur5e.f(x, p)[n:2 * n]
        worst["D"] = max(worst["D"], _rel(D, M))
        worst["G"] = max(worst["G"], _rel(G, pin.computeGeneralizedGravity(model, data, q)))
        worst["h"] = max(worst["h"], _rel(h, pin.rnea(model, data, q, dq, np.zeros(n))))
    print("ur5e vs Pinocchio, worst relative error:", {k: f"{v:.1e}" for k, v in worst.items()})
    assert max(worst.values()) <= RTOL, worst


def test_limits_are_the_urdfs(ur5e, reference):
    model, _ = reference
    effort = [float(j.find("limit").get("effort")) for name in JOINTS
              for j in ET.parse(URDF).getroot().iter("joint") if j.get("name") == name]
    assert effort == [150.0, 150.0, 150.0, 28.0, 28.0, 28.0]  # UR's published maximum joint torques
    np.testing.assert_array_equal(ur5e.effort_limits, effort)
    np.testing.assert_array_equal(ur5e.effort_limits, model.effortLimit)
    np.testing.assert_array_equal(ur5e.velocity_limits, model.velocityLimit)
    np.testing.assert_array_equal(ur5e.position_limits[:, 0], model.lowerPositionLimit)
    np.testing.assert_array_equal(ur5e.position_limits[:, 1], model.upperPositionLimit)
    assert ur5e.effort_limits.shape == (6,) and ur5e.position_limits.shape == (6, 2)


def test_model_file_states_what_is_assumed(ur5e):
    """The elastic defaults are the model file's, and their meaning says they are assumptions."""
    p = ur5e.default_params
    assert [p[f"K{i}"] for i in range(1, 7)] == [2e4, 2e4, 2e4, 4e3, 4e3, 4e3]
    assert [p[f"Jm{i}"] for i in range(1, 7)] == [0.3, 0.3, 0.3, 0.1, 0.1, 0.1]
    meaning = {e["name"]: e["meaning"] for e in ur5e.manifest["parameters"]}
    assert "assumed" in meaning["K1"] and "assumed" in meaning["Jm6"]
