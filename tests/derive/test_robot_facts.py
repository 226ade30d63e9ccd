"""``[limits]`` and ``[task]`` of a model file: parsed in both forms, over the URDF's ``<limit>``, written into the
manifest, and every bad value rejected at its key and line."""

from __future__ import annotations

import json
import sys
import textwrap
import xml.etree.ElementTree as ET

import numpy as np
import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from derive.model_file import parse_model_text  # noqa: E402
from derive.model_file.schema import ModelFileError
from derive.registry import ROBOTS  # noqa: E402

from support.paths import REPO  # noqa: E402

ELBOW_URDF = ROBOTS / "elbow3" / "elbow3.urdf"
URDF_HEAD = f"""[model]
name = "arm"
urdf = "{ELBOW_URDF.as_posix()}"
base = "base_link"
tip = "tool0"
[joints.default]
K = 400.0
Jm = 0.05
"""
CHAIN_HEAD = """[model]
name = "arm2"
links = 2
"""


def urdf_limit(urdf, joint: str, attr: str):
    """``<limit attr>`` of ``joint`` as the URDF file states it (None when absent)."""
    for j in ET.parse(urdf).getroot().iter("joint"):
        if j.get("name") == joint:
            lim = j.find("limit")
            return None if lim is None or lim.get(attr) is None else float(lim.get(attr))
    raise KeyError(joint)


def test_urdf_limits_are_the_default_and_a_table_overrides_by_joint():
    facts = parse_model_text(URDF_HEAD + "[limits]\neffort = { shoulder_pitch = 20.0 }\ntorque_rate = 500\n").facts
    joints = ("shoulder_yaw", "shoulder_pitch", "elbow")
    lim = facts["limits"]
    expected = [urdf_limit(ELBOW_URDF, j, "effort") for j in joints]
    expected[1] = 20.0
    assert lim["effort"]["values"] == expected and lim["effort"]["unit"] == "N m"
    assert lim["effort"]["from"] == ["urdf" if expected[0] is not None else None, "model file",
                                     None if expected[2] is None else "urdf"]
    assert lim["velocity"]["values"] == [urdf_limit(ELBOW_URDF, j, "velocity") for j in joints]
    assert lim["torque_rate"] == {"unit": "N m/s", "values": [500.0] * 3, "from": ["model file"] * 3}
    assert lim["position"]["lower"] == [urdf_limit(ELBOW_URDF, j, "lower") for j in joints]
    assert "task" not in facts


def test_chain_form_limits_and_task_forms():
    text = CHAIN_HEAD + textwrap.dedent("""
        [limits]
        effort = [30.0, 10.0]
        velocity = { default = 2.0, "2" = 3.0 }
        [task]
        kind = "sines"
        amplitude = 0.2
        omega = [1.0, 2.0]
        """)
    facts = parse_model_text(text).facts
    assert facts["limits"]["effort"]["values"] == [30.0, 10.0]
    assert facts["limits"]["velocity"]["values"] == [2.0, 3.0]
    assert facts["limits"]["torque_rate"]["values"] == [None, None] and "position" not in facts["limits"]
    task = facts["task"]
    assert (task["offset"], task["amplitude"], task["omega"], task["phase"]) == ([0.0] * 2, [0.2] * 2, [1.0, 2.0],
                                                                                  [0.0] * 2)
    assert task["start"] == "rest" and task["unit"]["omega"] == "rad/s"
    assert parse_model_text(CHAIN_HEAD).facts == {}  # neither table, no URDF: nothing in the manifest


def test_poses_task():
    text = CHAIN_HEAD + '[task]\nkind = "poses"\nposes = [[0.0, 0.0], [0.5, -0.5], [1.0, 0.0]]\ndurations = [2, 1.5]\n'
    task = parse_model_text(text).facts["task"]
    assert task["poses"] == [[0.0, 0.0], [0.5, -0.5], [1.0, 0.0]] and task["durations"] == [2.0, 1.5]


@pytest.mark.parametrize("body,key,line,fragment", [
    ('[limits]\neffort = -1.0\n', "limits.effort", 2, "must be > 0"),
    ('[limits]\neffort = [1.0]\n', "limits.effort", 2, "expected 2 numbers in N m"),
    ('[limits]\nefort = 1.0\n', "limits.efort", 2, "did you mean 'effort'"),
    ('[limits]\nvelocity = { "3" = 1.0 }\n', "limits.velocity.3", 2, "no joint '3'"),
    ('[limits]\ntorque_rate = "fast"\n', "limits.torque_rate", 2, "expected a number in N m/s"),
    ('\n[task]\nkind = "circle"\n', "task.kind", 3, "expected kind = one of 'sines', 'poses'"),
    ('[task]\nkind = "sines"\nomega = 1.0\n', "task.amplitude", 1, "missing sine amplitude"),
    ('[task]\nkind = "sines"\namplitude = -0.1\nomega = 1.0\n', "task.amplitude", 3, "must be >= 0"),
    ('[task]\nkind = "sines"\namplitude = 0.1\nomega = 1.0\nposes = []\n', "task.poses", 5, "not a key of kind"),
    ('[task]\nkind = "sines"\namplitude = 0.1\nomega = 1.0\nstart = "home"\n', "task.start", 5, "expected one of"),
    ('[task]\nkind = "poses"\nposes = [[0.0, 0.0], [1.0]]\n', "task.poses", 1, "each an array of 2 angles"),
    ('[task]\nkind = "poses"\nposes = [[0.0, 0.0], [1.0, 1.0]]\ndurations = [0.0]\n', "task.durations", 4, "> 0"),
    ('[task]\nkind = "poses"\nposes = [[0.0, 0.0], [1.0, 1.0]]\n', "task.durations", 1, "expected an array of 1"),
])
def test_bad_facts_name_key_and_line(body, key, line, fragment):
    with pytest.raises(ModelFileError) as err:
        parse_model_text(CHAIN_HEAD + body, source="arm.toml")
    msg = str(err.value)
    assert err.value.key == key and err.value.line == len(CHAIN_HEAD.splitlines()) + line, msg
    assert fragment in msg and "\n" not in msg, msg


def test_builtin_manifests_carry_their_files_facts():
    """generated/<model>/manifest.json holds the limits (the TOML's [limits] over the URDF's) and [task]."""
    for name in ("panda", "panda_hd", "baxter"):
        manifest = json.loads((REPO / "generated" / name / "manifest.json").read_text())
        toml = tomllib.loads((ROBOTS / name / f"{name}.toml").read_text())
        src = manifest["source"]
        urdf = REPO / src["urdf"]
        effort = [urdf_limit(urdf, j, "effort") for j in src["joints"]]
        for joint, value in toml.get("limits", {}).get("effort", {}).items():
            effort[src["joints"].index(joint)] = value
        assert manifest["limits"]["effort"]["values"] == effort
        for key in ("offset", "amplitude", "omega"):
            assert manifest["task"][key] == toml["task"][key]
        assert manifest["task"]["phase"] == [toml["task"]["phase"]] * len(src["joints"])
        assert np.isclose(toml["task"]["phase"], -0.5 * np.pi, rtol=0, atol=1e-16)


def test_the_ur5e_example_block_parses_as_documented():
    """examples/ur5e.toml shows [limits] and [task] commented out: uncommented, they parse to what they say."""
    path = REPO / "examples" / "ur5e.toml"
    text = path.read_text()
    block = "\n".join(line[2:] for line in text.split("For example:\n#\n")[1].splitlines())
    stated = tomllib.loads(block)
    facts = parse_model_text(text + "\n" + block, base_dir=path.parent).facts
    assert facts["limits"]["torque_rate"]["values"] == [stated["limits"]["torque_rate"]] * 6
    assert facts["task"]["offset"] == stated["task"]["offset"]
    assert facts["task"]["amplitude"] == [stated["task"]["amplitude"]] * 6
    assert "task" not in parse_model_text(text, base_dir=path.parent).facts  # as shipped: the URDF's limits only
