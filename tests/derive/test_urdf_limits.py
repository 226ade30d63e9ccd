"""URDF ``<limit>`` as data (derive/spatial/urdf.py): per moving joint in q order, as written, checked.

The limits do not enter the dynamics; they are read so that the manifest (and the runtime's
``Model.effort_limits``) carry what the URDF states. Bad limits are refused with file, line and
element, like every other URDF error.
"""

from __future__ import annotations

import pytest

from derive.spatial.urdf import JointLimit, UrdfError, parse_urdf  # noqa: E402

LINK = """<link name="{name}"><inertial><origin xyz="0 0 0.1"/><mass value="1.0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>"""


def urdf(limit_a: str, limit_b: str, kind_b: str = "revolute") -> str:
    """base -> (a, fixed) -> (j1) -> l1 -> (j2) -> l2; j2 first in the file, j1 first in q."""
    return f"""<?xml version="1.0"?>
<robot name="r">
  <link name="base"/>
  <link name="a"/>
  {LINK.format(name="l1")}
  {LINK.format(name="l2")}
  <joint name="j2" type="{kind_b}">
    <origin xyz="0 0 0.3"/><parent link="l1"/><child link="l2"/><axis xyz="0 1 0"/>
    {limit_b}
  </joint>
  <joint name="fix" type="fixed"><parent link="base"/><child link="a"/></joint>
  <joint name="j1" type="revolute">
    <origin xyz="0 0 0.1"/><parent link="a"/><child link="l1"/><axis xyz="0 0 1"/>
    {limit_a}
  </joint>
</robot>
"""


def test_limits_per_joint_in_q_order_as_written():
    chain = parse_urdf(urdf('<limit effort="87" velocity="2.175" lower="-2.9" upper="2.9"/>',
                            '<limit effort="12.5" velocity="2.61" lower="-0.0175" upper="3.7525"/>'), "base", "l2")
    assert chain.joints == ("j1", "j2")
    assert chain.limits == (JointLimit(87.0, 2.175, -2.9, 2.9), JointLimit(12.5, 2.61, -0.0175, 3.7525))


def test_missing_limit_or_attributes_are_none():
    chain = parse_urdf(urdf('<limit effort="50000" velocity="10000"/>', "", kind_b="continuous"), "base", "l2")
    assert chain.limits == (JointLimit(50000.0, 10000.0, None, None), JointLimit())  # placeholders kept


@pytest.mark.parametrize("limit, expected", [
    ('<limit effort="-1" velocity="2"/>', 'effort="-1"; expected a number >= 0'),
    ('<limit effort="1" velocity="-2"/>', 'velocity="-2"; expected a number >= 0'),
    ('<limit effort="1" velocity="2" lower="1" upper="-1"/>', 'lower="1" > upper="-1"; expected lower <= upper'),
    ('<limit effort="lots" velocity="2"/>', 'effort="lots"; expected 1 finite number'),
    ('<limit effort="inf" velocity="2"/>', 'effort="inf"; expected 1 finite number'),
])
def test_bad_limit_is_refused_with_line_and_element(limit, expected):
    text = urdf('<limit effort="1" velocity="1"/>', limit)
    line = text.splitlines().index(f"    {limit}") + 1
    with pytest.raises(UrdfError) as err:
        parse_urdf(text, "base", "l2", source="r.urdf")
    message = str(err.value)
    assert message.startswith(f"r.urdf:{line}: <joint name=\"j2\"> <limit>: ") and expected in message, message
