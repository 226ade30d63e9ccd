"""The design's torque limits and the demo's task come from each robot's own files, for every built-in model:
``default_efforts`` is the URDF's ``<limit effort>`` with the model file's ``[limits]`` over it, and
``demo_task`` is the model file's ``[task]`` (its sines, their start at rest holding gravity, and the record
the gains file keeps), both read here from the TOML and URDF themselves."""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

import fjm_runtime
from derive.registry import ROBOTS  # noqa: E402
from fjm_runtime.analysis.search.search import default_efforts
from fjm_runtime.cli.design import demo_task
from fjm_runtime.model import available_models, generated_root
from fjm_runtime.sim.rest import rest_state

from support.paths import REPO  # noqa: E402

BUILTIN = [name for name in available_models(generated_root())]


def robot_file(name: str):
    """The model's TOML as parsed, or None for the closed-form models."""
    path = ROBOTS / name / f"{name}.toml"
    return tomllib.loads(path.read_text()) if path.is_file() else None


def stated_efforts(m, toml):
    """The URDF's <limit effort> per joint (q order), the TOML's [limits] effort over it; None without a URDF."""
    src = m.manifest.get("source")
    if src is None:
        return None
    limits = {j.get("name"): j.find("limit") for j in ET.parse(REPO / src["urdf"]).getroot().iter("joint")}
    effort = [None if limits[j] is None or limits[j].get("effort") is None else float(limits[j].get("effort"))
              for j in src["joints"]]
    stated = ((toml or {}).get("limits") or {}).get("effort")
    if isinstance(stated, dict):
        effort = [stated.get(j, stated.get("default", e)) for j, e in zip(src["joints"], effort)]
    elif stated is not None:
        effort = list(stated) if isinstance(stated, list) else [stated] * m.n
    return effort


@pytest.mark.parametrize("name", BUILTIN)
def test_design_efforts_are_the_robots_stated_ones(name):
    m = fjm_runtime.load(name)
    effort = stated_efforts(m, robot_file(name))
    if effort is None or any(e is None for e in effort):
        assert default_efforts(m) is None  # no limit: the design saturates nothing
    else:
        assert default_efforts(m) == tuple(effort)
    if name == "baxter":  # the file's 50 N m replaces the URDF's 50000 placeholder on the head
        assert default_efforts(m)[0] == robot_file(name)["limits"]["effort"]["head_pan"] < m.effort_limits[0]


@pytest.mark.parametrize("name", BUILTIN)
def test_demo_task_is_the_robots_stated_task(name):
    m = fjm_runtime.load(name)
    stated = (robot_file(name) or {}).get("task")
    out = demo_task(m)
    if stated is None:
        assert out == {}
        return
    assert set(out) == {"reference", "x0", "task"}
    assert out["task"] == {"kind": stated["description"], "offset": stated["offset"],
                           "amplitude": stated["amplitude"], "omega": stated["omega"], "phase": stated["phase"],
                           "start": "at rest holding gravity (nominal parameters)"}
    off, amp, om = (np.asarray(stated[k], dtype=float) for k in ("offset", "amplitude", "omega"))
    for t in (0.0, 0.37, 2.5, 9.0):
        np.testing.assert_array_equal(out["reference"](t)[0], off + amp * np.sin(om * t + stated["phase"]))
    q0 = out["reference"](0.0)[0]
    np.testing.assert_allclose(q0, off - amp, rtol=0, atol=1e-15)  # phase -pi/2: at rest at offset - amplitude
    np.testing.assert_array_equal(out["x0"], rest_state(m, q0, m.default_params))
    nominal = dict(m.default_params, g0=0.0)  # the start holds the NOMINAL parameters' gravity
    x0 = demo_task(m, nominal)["x0"]
    np.testing.assert_array_equal(x0[2 * m.n:3 * m.n], q0)  # no gravity: motors at the links
    assert not np.array_equal(x0, out["x0"])
