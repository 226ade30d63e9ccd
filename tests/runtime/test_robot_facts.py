"""``Model.limits`` and ``Model.task``: the manifest's ``limits`` (a model file's ``[limits]`` over its URDF's) and
``task``, a manifest without them falling back to the URDF; ``PoseSequence``, the reference of a poses task."""

from __future__ import annotations

import json
import shutil
import textwrap

import numpy as np
import pytest

import fjm_runtime
from derive.__main__ import main as derive_main  # noqa: E402
from fjm_runtime.control.references import PoseSequence
from fjm_runtime.model import Model


@pytest.mark.parametrize("name", ("elbow3", "panda", "panda_complete", "panda_hd", "baxter"))
def test_limits_are_the_urdfs_where_the_file_states_none(name):
    m = fjm_runtime.load(name)
    lim = m.limits
    from_file = np.array([o == "model file" for o in lim.origin["effort"]])
    np.testing.assert_array_equal(lim.effort[~from_file], m.effort_limits[~from_file])
    np.testing.assert_array_equal(lim.velocity, m.velocity_limits)
    np.testing.assert_array_equal(lim.position, m.position_limits)
    assert np.all(np.isinf(lim.torque_rate)) and lim.effort.shape == (m.n,) and lim.position.shape == (m.n, 2)
    with pytest.raises(ValueError):
        lim.effort[0] = 1.0  # read-only: the cached limits cannot be changed by a caller


def test_baxters_head_effort_comes_from_its_file_not_the_urdf_placeholder():
    m = fjm_runtime.load("baxter")
    assert m.limits.origin["effort"] == ("model file",) + ("urdf",) * 14
    assert m.effort_limits[0] == 50000.0 and m.limits.effort[0] == m.manifest["limits"]["effort"]["values"][0]
    assert m.limits.effort[0] < m.effort_limits[0]


@pytest.mark.parametrize("name", ("link1", "planar3", "arm1_hd"))
def test_models_without_limits_have_none(name):
    m = fjm_runtime.load(name)
    assert np.all(np.isinf(m.limits.effort)) and np.all(np.isinf(m.limits.torque_rate))
    assert np.all(m.limits.position[:, 0] == -np.inf) and np.all(m.limits.position[:, 1] == np.inf)
    assert m.task is None


def test_a_manifest_without_limits_falls_back_to_the_urdf(tmp_path):
    shutil.copytree(fjm_runtime.load("panda").directory, tmp_path / "panda")
    path = tmp_path / "panda" / "manifest.json"
    manifest = json.loads(path.read_text())
    del manifest["limits"], manifest["task"]
    path.write_text(json.dumps(manifest))
    old, new = Model(tmp_path / "panda"), fjm_runtime.load("panda")
    for key in ("effort", "velocity", "torque_rate", "position"):
        np.testing.assert_array_equal(getattr(old.limits, key), getattr(new.limits, key))
    assert old.limits.origin["effort"] == ("urdf",) * 7 and old.task is None


@pytest.mark.parametrize("name", ("panda", "panda_hd", "baxter"))
def test_task_reference_is_the_manifests_sines(name):
    m = fjm_runtime.load(name)
    entry = m.manifest["task"]
    ref = m.task.reference()
    off, amp, om, ph = (np.array(entry[k]) for k in ("offset", "amplitude", "omega", "phase"))
    for t in (0.0, 0.37, 2.5, 9.0):
        r = ref(t)
        np.testing.assert_allclose(r[0], off + amp * np.sin(om * t + ph), rtol=0, atol=1e-15)
        np.testing.assert_allclose(r[1], amp * om * np.cos(om * t + ph), rtol=0, atol=1e-14)
    # phase -pi/2: at rest at offset - amplitude
    np.testing.assert_allclose(m.task.start_pose(), off - amp, rtol=0, atol=1e-15)
    np.testing.assert_allclose(ref(0.0)[1], 0.0, atol=1e-15)
    rec = m.task.record()
    assert rec["kind"] == entry["description"] and rec["phase"] == entry["phase"][0]
    assert rec["offset"] == entry["offset"] and "holding gravity" in rec["start"]


def test_pose_sequence_moves_smoothly_through_the_poses():
    poses = np.array([[0.0, 0.2], [0.5, -0.3], [1.0, -0.3]])
    ref = PoseSequence(poses, [2.0, 1.5])
    np.testing.assert_array_equal(ref(0.0)[0], poses[0])
    np.testing.assert_allclose(ref(2.0)[0], poses[1], atol=1e-15)
    np.testing.assert_allclose(ref(3.5)[0], poses[2], atol=1e-15)
    np.testing.assert_allclose(ref(10.0)[0], poses[2], atol=1e-15)
    for t in (0.0, 2.0, 3.5):  # at rest at every pose
        np.testing.assert_allclose(ref(t)[1:], 0.0, atol=1e-12)
    h = 1e-6
    for t in (0.7, 1.3, 2.4, 3.1):  # each row the derivative of the previous (central differences)
        d = (ref(t + h) - ref(t - h)) / (2 * h)
        np.testing.assert_allclose(d[:4], ref(t)[1:], rtol=1e-6, atol=1e-5)
    bounds = ref.derivative_bounds()
    samples = ref.sample(np.linspace(0.0, 4.0, 801))
    assert np.all(np.abs(samples).max(axis=0) <= bounds + 1e-9)


def test_a_model_files_limits_and_poses_reach_the_runtime(tmp_path):
    text = textwrap.dedent("""
        [model]
        name = "arm2"
        links = 2
        [limits]
        effort = [30.0, 10.0]
        torque_rate = 400.0
        [task]
        kind = "poses"
        description = "two poses"
        poses = [[0.0, 0.0], [0.8, -0.4]]
        durations = [3.0]
        """)
    (tmp_path / "arm2.toml").write_text(text)
    assert derive_main(["--model-file", str(tmp_path / "arm2.toml"), "--out", str(tmp_path / "out")]) == 0
    m = Model(tmp_path / "out" / "arm2")
    np.testing.assert_array_equal(m.limits.effort, [30.0, 10.0])
    np.testing.assert_array_equal(m.limits.torque_rate, [400.0, 400.0])
    assert np.all(np.isinf(m.limits.velocity)) and m.effort_limits is None  # no URDF
    assert m.task.kind == "poses" and m.task.record()["kind"] == "two poses"
    np.testing.assert_allclose(m.task.reference()(3.0)[0], [0.8, -0.4], atol=1e-15)
    np.testing.assert_array_equal(m.task.start_pose(), [0.0, 0.0])
