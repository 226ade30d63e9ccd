"""URDF import (derive/spatial/urdf.py) and the URDF form of model files: one test per bad case.

Every error must name the file, the line, the element and what was expected.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from support.paths import REPO  # noqa: E402
sys.path.insert(0, str(REPO))

from derive.model_file import load_model_file  # noqa: E402
from derive.model_file.schema import ModelFileError
from derive.spatial.urdf import UrdfError, load_urdf  # noqa: E402

INERTIAL = """<inertial><origin xyz="0 0 0.1"/><mass value="{mass}"/>
      <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>"""


LIMIT = '<limit effort="10" lower="-3" upper="3" velocity="2"/>'  # urdfdom (Pinocchio) requires it


def arm(j2_type="revolute", mass2="1.0", ixx2="0.01", link2_inertial=True, extra="", j2_extra=""):
    """A 2-joint arm base -> l1 -> l2 -> tool (fixed), with hooks for the bad cases."""
    l2 = INERTIAL.format(mass=mass2, ixx=ixx2) if link2_inertial else ""
    return f"""<?xml version="1.0"?>
<robot name="two">
  <link name="base"/>
  <link name="l1">
    {INERTIAL.format(mass=1.0, ixx=0.01)}
  </link>
  <link name="l2">
    {l2}
  </link>
  <link name="tool"/>
  <joint name="j1" type="revolute">
    <origin xyz="0 0 0.1" rpy="0 0 0"/>
    <parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>{LIMIT}
  </joint>
  <joint name="j2" type="{j2_type}">
    <origin xyz="0 0 0.3" rpy="0 0 0"/>
    <parent link="l1"/><child link="l2"/><axis xyz="0 1 0"/>{LIMIT}{j2_extra}
  </joint>
  <joint name="tool_joint" type="fixed">
    <origin xyz="0 0 0.3"/>
    <parent link="l2"/><child link="tool"/>
  </joint>
{extra}
</robot>
"""


def write(tmp_path, text, name="arm.urdf"):
    path = tmp_path / name
    path.write_text(text)
    return path


def line_of(text, needle):
    return next(i for i, ln in enumerate(text.splitlines(), 1) if needle in ln)


def expect_error(tmp_path, text, base="base", tip="tool", *, element, expected, line_needle=None):
    path = write(tmp_path, text)
    with pytest.raises(UrdfError) as info:
        load_urdf(path, base, tip)
    msg = str(info.value)
    assert msg.startswith(f"{path}:"), msg
    if line_needle is not None:
        assert f"{path}:{line_of(text, line_needle)}:" in msg, msg
    assert element in msg, msg
    assert re.search(expected, msg), msg
    return msg


def test_good_arm_parses_and_merges_the_fixed_tool(tmp_path):
    chain = load_urdf(write(tmp_path, arm()), "base", "tool")
    assert chain.joints == ("j1", "j2")
    assert [j.kind for j in chain.description.joints] == ["revolute", "revolute", "fixed"]


def test_malformed_xml(tmp_path):
    text = arm().replace('<child link="l1"/>', '<child link="l1">')
    expect_error(tmp_path, text, element="malformed XML", expected=r"mismatched tag.*expected a well-formed")


def test_entities_are_refused(tmp_path):
    text = ('<?xml version="1.0"?>\n<!DOCTYPE r [<!ENTITY a "aaaa">]>\n' + arm().split("\n", 1)[1])
    expect_error(tmp_path, text, element="malformed XML", expected="entity declarations are not allowed")


def test_root_must_be_robot(tmp_path):
    expect_error(tmp_path, "<model name='x'/>", element="root element is <model>", expected="expected <robot>")


@pytest.mark.parametrize("role", ["base", "tip"])
def test_missing_base_or_tip_link(tmp_path, role):
    kw = {"base": "nowhere"} if role == "base" else {"tip": "nowhere"}
    expect_error(tmp_path, arm(), **kw, element='<robot name="two">',
                 expected=rf"{role} link 'nowhere' not found; expected one of the <link> names \(base, l1, l2, tool\)",
                 line_needle="<robot")


def test_tip_not_below_base(tmp_path):
    expect_error(tmp_path, arm(), base="l2", tip="l1", element='<link name="l1">',
                 expected="not a descendant of base link 'l2'", line_needle='<link name="l1">')


def test_closed_loop(tmp_path):
    extra = """  <joint name="loop" type="revolute">
    <parent link="l1"/><child link="tool"/><axis xyz="0 0 1"/>
  </joint>"""
    expect_error(tmp_path, arm(extra=extra), element='<joint name="loop">',
                 expected="already the child of <joint name=\"tool_joint\">.*closed kinematic loop",
                 line_needle='<joint name="loop"')


def test_cycle(tmp_path):
    text = """<robot name="c">
  <link name="base"/><link name="a"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="b"/>
  <joint name="ab" type="revolute"><parent link="a"/><child link="b"/></joint>
  <joint name="ba" type="revolute"><parent link="b"/><child link="a"/></joint>
</robot>"""
    expect_error(tmp_path, text, tip="a", element="<joint name=", expected="cycle through link .*expected a tree")


@pytest.mark.parametrize("kind", ["prismatic", "planar", "floating"])
def test_non_revolute_joint_on_the_chain(tmp_path, kind):
    expect_error(tmp_path, arm(j2_type=kind), element='<joint name="j2">',
                 expected=f'type "{kind}" on the chain base -> tool; expected revolute, continuous or fixed',
                 line_needle='<joint name="j2"')


def test_unknown_joint_type(tmp_path):
    expect_error(tmp_path, arm(j2_type="hinge"), element='<joint name="j2">',
                 expected="type='hinge'; expected one of revolute, continuous")


def test_mimic_on_the_chain(tmp_path):
    expect_error(tmp_path, arm(j2_extra='<mimic joint="j1"/>'), element='<joint name="j2">',
                 expected="<mimic> on the chain; expected independent joints")


def test_link_without_inertial_on_the_chain(tmp_path):
    text = arm(link2_inertial=False)
    expect_error(tmp_path, text, element='<link name="l2">',
                 expected="no <inertial>.*needs <inertial> with <mass> > 0", line_needle='<link name="l2">')


@pytest.mark.parametrize("mass", ["0", "-1.5"])
def test_mass_not_positive(tmp_path, mass):
    text = arm(mass2=mass)
    expect_error(tmp_path, text, element='<link name="l2"> <mass>', expected=f"mass {float(mass)!r} kg; expected > 0",
                 line_needle=f'<mass value="{mass}"/>')


def test_inertia_not_positive_definite(tmp_path):
    text = arm(ixx2="-0.01")
    expect_error(tmp_path, text, element='<link name="l2"> <inertia>',
                 expected=r"not positive definite \(eigenvalues -0.01, .*expected a symmetric positive definite",
                 line_needle='ixx="-0.01"')


def test_bad_number(tmp_path):
    text = arm().replace('<origin xyz="0 0 0.3" rpy="0 0 0"/>', '<origin xyz="0 0 3e" rpy="0 0 0"/>')
    expect_error(tmp_path, text, element='<joint name="j2"> <origin>',
                 expected='xyz="0 0 3e"; expected 3 finite number\\(s\\)')


def test_zero_axis(tmp_path):
    text = arm().replace('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>')
    expect_error(tmp_path, text, element='<joint name="j2">', expected="is zero; expected a non-zero axis")


def test_undefined_link_in_a_joint(tmp_path):
    text = arm().replace('<parent link="l2"/>', '<parent link="l9"/>')
    expect_error(tmp_path, text, element='<joint name="tool_joint"> <parent>',
                 expected="link 'l9' is not defined")


def test_branch_with_mass_is_refused(tmp_path):
    extra = f"""  <link name="side">{INERTIAL.format(mass=0.5, ixx=0.01)}</link>
  <joint name="side_joint" type="prismatic">
    <parent link="l1"/><child link="side"/><axis xyz="1 0 0"/>
  </joint>"""
    expect_error(tmp_path, arm(extra=extra), element='<joint name="side_joint">',
                 expected=r"a prismatic joint leaves the chain base -> tool and carries mass \(link\(s\) side\)",
                 line_needle='<joint name="side_joint"')


def test_massless_branch_is_ignored_and_named(tmp_path):
    extra = """  <link name="sensor"/>
  <joint name="sensor_joint" type="revolute">
    <parent link="l1"/><child link="sensor"/><axis xyz="1 0 0"/>
  </joint>"""
    chain = load_urdf(write(tmp_path, arm(extra=extra)), "base", "tool")
    assert chain.ignored == ("sensor",)
    assert chain.joints == ("j1", "j2")


def test_fixed_branch_is_merged(tmp_path):
    """A fixed side mass changes D exactly as Pinocchio's merge does."""
    import pinocchio as pin
    from derive.spatial.chain import chain_numerics
    extra = f"""  <link name="side">{INERTIAL.format(mass=0.5, ixx=0.02)}</link>
  <joint name="side_joint" type="fixed">
    <origin xyz="0.1 0.2 0" rpy="0.3 0.2 0.1"/>
    <parent link="l1"/><child link="side"/>
  </joint>"""
    path = write(tmp_path, arm(extra=extra))
    num = chain_numerics(load_urdf(path, "base", "tool").description)
    model = pin.buildModelFromUrdf(str(path))
    for i, body in enumerate(num.bodies, 1):
        assert abs(body.mass - model.inertias[i].mass) < 1e-14
    ref, body = model.inertias[1], num.bodies[0]  # l1 carries the side mass; its axis is z: same frame
    assert body.mass == pytest.approx(1.5, abs=1e-14)
    c = ref.lever
    np.testing.assert_allclose(body.first_moment, ref.mass * c, atol=1e-14)
    np.testing.assert_allclose(body.inertia_origin, ref.inertia + ref.mass * (c @ c * np.eye(3) - np.outer(c, c)),
                               atol=1e-14)


# ---- the URDF form of model files ------------------------------------------------------------

TOML = """[model]
name = "two"
urdf = "arm.urdf"
base = "base"
tip = "tool"

[joints.default]
K = 500.0
Jm = 0.1

[joints.j2]
K = 200.0
Bm = 0.2
"""


def test_model_file_urdf_form(tmp_path):
    write(tmp_path, arm())
    spec = load_model_file(write(tmp_path, TOML, "two.toml"))
    assert (spec.K, spec.Jm, spec.Bm, spec.g0) == ((500.0, 200.0), (0.1, 0.1), (0.0, 0.2), 9.81)
    m = spec.build()
    assert m.param_names == ("K1", "K2", "Jm1", "Jm2", "Bm1", "Bm2", "g0")
    assert m.source["joints"] == ["j1", "j2"] and m.source["base"] == "base" and m.source["tip"] == "tool"
    assert m.source["urdf"] == "arm.urdf"  # outside the repository: the file name only


@pytest.mark.parametrize("edit, key, expected", [
    (lambda t: t.replace('urdf = "arm.urdf"', 'urdf = "missing.urdf"'), "model.urdf",
     "URDF file 'missing.urdf' not found"),
    (lambda t: t.replace('tip = "tool"', 'tip = "hand"'), "model.urdf",
     "cannot use the URDF: .*tip link 'hand' not found"),
    (lambda t: t.replace("[joints.j2]", "[joints.j3]"), "joints.j3",
     "no revolute joint 'j3' on the chain base -> tool; expected 'default' or one of j1, j2"),
    (lambda t: t.replace("K = 200.0", "K = -1.0"), "joints.j2.K",
     "-1.0 N m/rad is not physical: joint stiffness must be > 0"),
    (lambda t: t.replace("Jm = 0.1\n", ""), "joints.j1.Jm",
     "missing reflected motor inertia of joint 'j1'"),
    (lambda t: t.replace("Bm = 0.2", "Kx = 0.2"), "joints.j2.Kx", "unknown key; a joint table allows K, Jm, Bm"),
    (lambda t: t + "\n[parameters]\nm1 = 2.0\n", "parameters.m1", "takes g0 only"),
    (lambda t: t.replace('base = "base"\n', ""), "model.base", "missing required key: base"),
    (lambda t: t + "\n[payload]\nmass = -1.0\ncom = [0, 0, 0]\n", "payload.mass",
     "-1.0 kg is not physical: payload mass must be >= 0"),
    (lambda t: t + "\n[payload]\nmass = 1.0\ncom = [0, 0]\n", "payload.com", "expected an array of 3 numbers"),
])
def test_model_file_urdf_form_errors(tmp_path, edit, key, expected):
    write(tmp_path, arm())
    text = edit(TOML)
    path = write(tmp_path, text, "two.toml")
    with pytest.raises(ModelFileError) as info:
        load_model_file(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}:"), msg
    assert f": {key}: " in msg, msg
    assert re.search(expected, msg), msg


def test_model_file_payload_parameters(tmp_path):
    write(tmp_path, arm())
    spec = load_model_file(write(tmp_path, TOML + "\n[payload]\nmass = 0.5\ncom = [0.0, 0.1, 0.2]\n", "two.toml"))
    m = spec.build()
    assert m.param_names[-5:] == ("g0", "m_load", "x_load", "y_load", "z_load")
    assert [p.default for p in m.params[-4:]] == [0.5, 0.0, 0.1, 0.2]


def test_urdf_model_file_name_may_not_shadow_a_builtin(tmp_path):
    write(tmp_path, arm())
    path = write(tmp_path, TOML.replace('name = "two"', 'name = "panda"'), "two.toml")
    with pytest.raises(ModelFileError, match="model.name: .*is a built-in model name"):
        load_model_file(path)


def test_example_urdf_model_file_derives(tmp_path):
    """examples/elbow_arm.toml (URDF form) through the CLI, loaded by the runtime."""
    import fjm_runtime
    from derive.__main__ import main as derive_main
    example = REPO / "examples" / "elbow_arm.toml"
    assert derive_main(["--model-file", str(example), "--out", str(tmp_path / "out")]) == 0
    m = fjm_runtime.model.Model(tmp_path / "out" / "elbow_arm")
    ref = fjm_runtime.load("elbow3")
    assert m.manifest["source"]["urdf"] == "derive/robots/elbow3/elbow3.urdf"
    x = np.linspace(-0.5, 0.7, 12)
    # same URDF, same inertials: D equal; only K/Jm defaults differ
    np.testing.assert_allclose(m.inertia(x, None), ref.inertia(x, None), rtol=1e-14, atol=1e-14)


def test_symbolic_inertials_equal_a_urdf_with_those_numbers(tmp_path):
    """`symbolic = ["l2", "tool"]`: the inertials become parameters m_l2, cx_l2, ..., izz_tool
    (URDF values as defaults); at other values the model equals the baked model of a URDF
    carrying those values."""
    from derive.emit.functions import build_functions
    from derive.core.linearize import linearize
    tool = '<inertial><origin xyz="0.01 0 0.02" rpy="0.3 0.1 0"/><mass value="0.2"/>' \
           '<inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.0015"/></inertial>'
    base_text = arm().replace('<link name="tool"/>', f'<link name="tool">{tool}</link>')
    write(tmp_path, base_text)
    toml = TOML.replace('tip = "tool"', 'tip = "tool"\nsymbolic = ["l2", "tool"]')
    spec = load_model_file(write(tmp_path, toml, "two.toml"))
    m = spec.build()
    names = m.param_names
    assert names[:7] == ("K1", "K2", "Jm1", "Jm2", "Bm1", "Bm2", "g0")
    assert names[7:10] == ("m_l2", "cx_l2", "cy_l2") and names[-1] == "izz_tool" and len(names) == 27
    defaults = dict(zip(names, (p.default for p in m.params)))
    assert defaults["m_l2"] == 1.0 and defaults["cz_l2"] == 0.1 and defaults["iyy_tool"] == 0.002
    sym_fs = build_functions(linearize(m))
    new = {"m_l2": 1.7, "cx_l2": 0.02, "cy_l2": -0.03, "cz_l2": 0.15, "ixx_l2": 0.03, "ixy_l2": 0.001,
           "ixz_l2": -0.002, "iyy_l2": 0.02, "iyz_l2": 0.0005, "izz_l2": 0.015,
           "m_tool": 0.4, "cx_tool": 0.0, "cy_tool": 0.05, "cz_tool": 0.03, "ixx_tool": 0.002,
           "ixy_tool": 0.0001, "ixz_tool": 0.0, "iyy_tool": 0.003, "iyz_tool": 0.0, "izz_tool": 0.0025}
    baked_text = arm(mass2="1.7").replace(
        '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>\n  </link>\n  <link name="tool"/>',
        '<inertia ixx="0.03" ixy="0.001" ixz="-0.002" iyy="0.02" iyz="0.0005" izz="0.015"/></inertial>\n  </link>\n'
        '  <link name="tool"><inertial><origin xyz="0.0 0.05 0.03" rpy="0.3 0.1 0"/><mass value="0.4"/>'
        '<inertia ixx="0.002" ixy="0.0001" ixz="0" iyy="0.003" iyz="0" izz="0.0025"/></inertial></link>')
    baked_text = baked_text.replace('<origin xyz="0 0 0.1"/><mass value="1.7"/>',
                                    '<origin xyz="0.02 -0.03 0.15"/><mass value="1.7"/>')
    assert baked_text.count("0.02 -0.03 0.15") == 1 and 'izz="0.0025"' in baked_text
    (tmp_path / "baked").mkdir()
    write(tmp_path / "baked", baked_text)
    baked = load_model_file(write(tmp_path / "baked", TOML, "two.toml")).build()
    baked_fs = build_functions(linearize(baked))
    p_sym = np.array([defaults[k] for k in names[:7]] + [new[k] for k in names[7:]])
    p_baked = np.array([defaults[k] for k in names[:7]])
    rng = np.random.default_rng(5)
    for _ in range(5):
        x = rng.uniform(-2, 2, 8)
        for q in ("inertia", "f", "alpha", "energy", "ad"):
            a, b = np.array(sym_fs[q](x, p_sym)), np.array(baked_fs[q](x, p_baked))
            assert np.max(np.abs(a - b)) <= 1e-12 * max(1.0, np.max(np.abs(b))), q


def test_symbolic_inertial_of_an_unknown_link(tmp_path):
    write(tmp_path, arm())
    path = write(tmp_path, TOML.replace('tip = "tool"', 'tip = "tool"\nsymbolic = ["l7"]'), "two.toml")
    with pytest.raises(ModelFileError, match=r"model.symbolic: symbolic inertial of link\(s\) \['l7'\]: "
                                             r"not a link of the chain \(expected among \['l1', 'l2'\]\)"):
        load_model_file(path)
