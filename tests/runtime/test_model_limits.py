"""``Model.effort_limits`` / ``velocity_limits`` / ``position_limits``: the URDF's ``<limit>`` of every
model derived from a URDF (built-ins and model files), as Pinocchio reads the same URDF; None for the
closed-form models, which have no URDF."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import fjm_runtime

from support.paths import REPO  # noqa: E402

URDF_MODELS = ("elbow3", "panda", "panda_complete", "baxter")


@pytest.mark.parametrize("name", URDF_MODELS)
def test_limits_are_what_pinocchio_reads_from_the_same_urdf(name):
    m = fjm_runtime.load(name)
    src = m.manifest["source"]
    model = pin.buildModelFromUrdf(str(REPO / src["urdf"]))
    idx = [model.joints[model.getJointId(j)].idx_v for j in src["joints"]]  # by name: a tree has other joints
    assert len(idx) == m.n and all(0 <= i < model.nv for i in idx)
    assert m.effort_limits.shape == (m.n,) and m.velocity_limits.shape == (m.n,)
    assert m.position_limits.shape == (m.n, 2)
    np.testing.assert_array_equal(m.effort_limits, model.effortLimit[idx])
    np.testing.assert_array_equal(m.velocity_limits, model.velocityLimit[idx])
    for i, j in enumerate(src["joints"]):
        joint = model.joints[model.getJointId(j)]
        if joint.nq == 1:
            lower, upper = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
        else:  # a continuous joint is (cos, sin) in Pinocchio: no angle limits
            lower, upper = -np.inf, np.inf
        assert m.position_limits[i].tolist() == [lower, upper], (j, m.position_limits[i], lower, upper)


def test_panda_effort_limits_are_frankas_and_baxters_placeholder_is_kept():
    np.testing.assert_array_equal(fjm_runtime.load("panda").effort_limits, [87.0] * 4 + [12.0] * 3)
    baxter = fjm_runtime.load("baxter")
    assert baxter.manifest["source"]["joints"][0] == "head_pan"
    # the URDF's head pan states 50000 N m and 10000 rad/s (placeholders): kept, the consumer decides
    assert baxter.effort_limits[0] == 50000.0 and baxter.velocity_limits[0] == 10000.0
    np.testing.assert_array_equal(baxter.effort_limits[1:], ([50.0] * 4 + [15.0] * 3) * 2)


@pytest.mark.parametrize("name", ("link1", "planar3", "link1_complete"))
def test_models_without_a_urdf_have_no_limits(name):
    m = fjm_runtime.load(name)
    assert m.effort_limits is None and m.velocity_limits is None and m.position_limits is None


def test_a_joint_without_a_stated_effort_is_unlimited(tmp_path):
    """inf where the manifest says null (a URDF joint without <limit effort>), and a wrong length is refused."""
    import json
    import shutil
    src_dir = fjm_runtime.load("elbow3").directory
    shutil.copytree(src_dir, tmp_path / "elbow3")
    path = tmp_path / "elbow3" / "manifest.json"
    manifest = json.loads(path.read_text())
    manifest["source"]["limits"]["effort"] = [None, 7.0, None]
    manifest["source"]["limits"]["lower"] = [None, None, None]
    path.write_text(json.dumps(manifest))
    m = fjm_runtime.Model(tmp_path / "elbow3")
    np.testing.assert_array_equal(m.effort_limits, [np.inf, 7.0, np.inf])
    assert m.position_limits[:, 0].tolist() == [-np.inf] * 3
    manifest["source"]["limits"]["effort"] = [1.0, 2.0]
    path.write_text(json.dumps(manifest))
    with pytest.raises(fjm_runtime.FjmValueError, match="source.limits.effort has 2 entries, expected n = 3"):
        fjm_runtime.Model(tmp_path / "elbow3").effort_limits
