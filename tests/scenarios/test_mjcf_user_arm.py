"""A user's URDF arm in a folder outside the repository: ``fjm derive --model-file`` writes its chain.json
(the URDF named as the model file gives it, with its sha256) and ``fjm export mjcf`` exports it.

The arm is the built-in elbow3 copied into a temporary folder under another name (the URDF in a
sub-folder): its chain.json bodies and its MJCF equal the built-in's, and MuJoCo's accelerations from
the exported file equal fjm's ``f + g u``.
"""
from __future__ import annotations

import hashlib
import json
import shutil

import numpy as np
import pytest

import mujoco  # noqa: F401  (the dev extra: no skip)

import fjm_runtime
from fjm_runtime.cli.main import main as fjm_main
from fjm_runtime.export.bridge import MujocoPlant

from support.paths import GENERATED, REPO


@pytest.mark.slow
def test_user_urdf_arm_outside_the_repository_exports_to_mjcf(tmp_path, capsys):
    arm = tmp_path / "my arm"                       # a user's folder, a space in its name
    (arm / "urdf").mkdir(parents=True)
    robot = REPO / "derive" / "robots" / "elbow3"
    shutil.copy(robot / "elbow3.urdf", arm / "urdf" / "my_arm.urdf")
    toml = (robot / "elbow3.toml").read_text()
    assert 'name = "elbow3"' in toml and 'urdf = "elbow3.urdf"' in toml
    (arm / "myarm.toml").write_text(toml.replace('name = "elbow3"', 'name = "myarm"')
                                    .replace('urdf = "elbow3.urdf"', 'urdf = "urdf/my_arm.urdf"'))
    out = tmp_path / "generated"
    assert fjm_main(["derive", "--model-file", str(arm / "myarm.toml"), "--out", str(out)]) == 0
    chain = json.loads((out / "myarm" / "chain.json").read_text())
    builtin = json.loads((GENERATED / "elbow3" / "chain.json").read_text())
    assert chain["urdf"] == "urdf/my_arm.urdf"
    assert chain["sha256"] == hashlib.sha256((arm / "urdf" / "my_arm.urdf").read_bytes()).hexdigest()
    assert {k: v for k, v in chain.items() if k not in ("model", "urdf")} == \
        {k: v for k, v in builtin.items() if k not in ("model", "urdf")}
    capsys.readouterr()
    xml = tmp_path / "myarm.xml"
    assert fjm_main(["export", "mjcf", str(out / "myarm"), "--out", str(xml)]) == 0
    assert fjm_main(["export", "mjcf", "elbow3", "--out", str(tmp_path / "elbow3.xml")]) == 0
    ours, theirs = xml.read_text().splitlines(), (tmp_path / "elbow3.xml").read_text().splitlines()
    assert ours[2:] == theirs[2:] and len(ours) > 20       # the first two lines name the model
    m = fjm_runtime.load(str(out / "myarm"))
    plant = MujocoPlant(m, xml, None)
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(20):
        x, u = rng.uniform(-1.0, 1.0, m.nx), rng.uniform(-20.0, 20.0, m.n)
        ref = m.f(x, None) + m.g(x, None) @ u
        worst = max(worst, float(np.max(np.abs(plant.xdot(x, u) - ref)) / np.max(np.abs(ref))))
    print(f"myarm: MuJoCo vs fjm accelerations, worst relative {worst:.3g}")
    assert worst < 1e-12
