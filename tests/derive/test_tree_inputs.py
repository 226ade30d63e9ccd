"""Trees from the input side: ``tips`` in the URDF reader and the model file, q order, refusals.

The dynamics of trees are checked against Pinocchio in test_tree_pinocchio.py.
"""

from __future__ import annotations

import shutil
import textwrap

import pytest

from derive.spatial.chain import chain_numerics
from derive.model_file import load_model_file
from derive.model_file.schema import ModelFileError
from derive.core.rotors import Rotors
from derive.spatial.spatial import make_spatial
from derive.spatial.spatial_params import elastic_params
from derive.spatial.urdf import UrdfError, load_urdf
from support.paths import REPO

BAXTER = REPO / "derive" / "robots" / "baxter"
ARM = ("s0", "s1", "e0", "e1", "w0", "w1", "w2")


def test_q_order_is_depth_first_in_the_order_of_the_tips():
    urdf = BAXTER / "baxter.urdf"
    a = load_urdf(urdf, "base", ["head", "left_gripper", "right_gripper"])
    assert a.joints == ("head_pan",) + tuple(f"left_{j}" for j in ARM) + tuple(f"right_{j}" for j in ARM)
    b = load_urdf(urdf, "base", ["right_gripper", "head"])
    assert b.joints == tuple(f"right_{j}" for j in ARM) + ("head_pan",)
    num = chain_numerics(a.description)
    # parents: head pan and both shoulders hang on the (fixed) torso; each arm is a path
    assert num.parents == (-1, -1, 1, 2, 3, 4, 5, 6, -1, 8, 9, 10, 11, 12, 13)


def test_a_single_tip_is_a_path_and_equals_the_serial_reader():
    urdf = BAXTER / "baxter.urdf"
    one = load_urdf(urdf, "base", ["left_gripper"])
    path = load_urdf(urdf, "base", "left_gripper")
    assert one.description == path.description and one.description.tips == ()
    assert chain_numerics(path.description).parents == tuple(range(-1, 6))


def test_bad_tips_are_refused_with_the_link_named():
    urdf = BAXTER / "baxter.urdf"
    with pytest.raises(UrdfError, match="tip link 'nose' not found"):
        load_urdf(urdf, "base", ["head", "nose"])
    with pytest.raises(UrdfError, match="distinct link names"):
        load_urdf(urdf, "base", ["head", "head"])
    with pytest.raises(UrdfError, match="no revolute or continuous joint between base 'base' and tip 'pedestal'"):
        load_urdf(urdf, "base", ["head", "pedestal"])


def test_a_tree_refuses_rotors():
    desc = load_urdf(BAXTER / "baxter.urdf", "base", ["head", "left_gripper"]).description
    n = 8
    params = elastic_params(n, [500.0] * n, [0.1] * n, [0.0] * n, 9.81)
    with pytest.raises(ValueError, match="serial chains; the joints form a tree"):
        make_spatial(desc, "t", params, "t", rotors=Rotors((10.0,) * n, (0.0,) * n, (None,) * n))


def _model_file(tmp_path, model_lines, extra=""):
    shutil.copy(BAXTER / "baxter.urdf", tmp_path / "baxter.urdf")
    path = tmp_path / "tree.toml"
    path.write_text(textwrap.dedent(f"""\
        [model]
        name = "tree"
        urdf = "baxter.urdf"
        base = "base"
        {model_lines}
        [joints.default]
        K = 800.0
        Jm = 0.1
        """) + extra)
    return path


def test_model_file_tips_parse_and_name_the_tree(tmp_path):
    spec = load_model_file(_model_file(tmp_path, 'tips = ["head", "right_gripper"]\ntip = "head"'))
    assert spec.tips == ("head", "right_gripper") and spec.joints[0] == "head_pan" and len(spec.joints) == 8


@pytest.mark.parametrize("lines, extra, fragment", [
    ('tips = ["head", "head"]', "", "at least two distinct link names"),
    ('tips = ["head"]', "", "at least two distinct link names"),
    ('tips = ["head", "right_gripper"]\ntip = "left_gripper"', "", "not among tips"),
    ('tips = ["head", "right_gripper"]', "[payload]\nmass = 1.0\ncom = [0.0, 0.0, 0.0]\n", "[payload] is for a serial chain"),
    ('tips = ["head", "elbow"]', "", "tip link 'elbow' not found"),
])
def test_model_file_bad_tips(tmp_path, lines, extra, fragment):
    with pytest.raises(ModelFileError) as err:
        load_model_file(_model_file(tmp_path, lines, extra))
    assert fragment in str(err.value), str(err.value)
