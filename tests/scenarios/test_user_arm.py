"""A user's own URDF arm, in a folder outside the repository, through every command as a user runs them.

A two-joint arm (a yaw and a pitch joint, adapted from derive/robots/elbow3) and its model file are
written into a temporary folder with a space in its name; then, in-process through ``fjm``'s
``main``: derive (its ``--out`` folder is what every later command is given), simulate, analyze
(the default gains), design (the smallest budget: it ends with a verdict, met or missed), simulate
on the design, export controller (``--unverified`` exactly when the design missed, and the README
says which), export mjcf (MuJoCo's accelerations equal fjm's ``f + g u``), excite, and identify on a
log of the excitation played by MuJoCo on the TRUE plant (stiffness x1.15, rotor inertia x0.9,
damping and dry friction: :mod:`fjm_runtime.ident.mujoco_robot`, as examples/identify_roundtrip.py):
the truth lies inside the interval the parameter file states for K, J_m and B_m on both joints, and the
gravity-loaded joint's stiffness within 2 %.

Every command ends with its documented exit status, no output holds a traceback, and no message
names the arm by a name no command finds (``fjm design twoarm``) or tells the user to re-run
``make derive``.
"""
from __future__ import annotations

import json
import shlex
import sys
import warnings

import numpy as np
import pytest

import mujoco  # noqa: F401  (the dev extra: no skip)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

import fjm_runtime
from fjm_runtime.cli.main import main as fjm_main
from fjm_runtime.export.bridge import MujocoPlant
from fjm_runtime.ident.excite import FourierReference
from fjm_runtime.ident.log import write_log
from fjm_runtime.ident.mujoco_robot import FRICTION, mujoco_log, true_params

URDF = """<?xml version="1.0"?>
<robot name="twoarm">
  <link name="base_link"/>
  <joint name="yaw" type="revolute">
    <origin xyz="0 0 0.3" rpy="0 0 0"/>
    <parent link="base_link"/>
    <child link="turret"/>
    <axis xyz="0 0 1"/>
    <limit lower="-2.5" upper="2.5" effort="50" velocity="2"/>
  </joint>
  <link name="turret">
    <inertial>
      <origin xyz="0 0 0.05" rpy="0 0 0"/>
      <mass value="2.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.011" iyz="0" izz="0.008"/>
    </inertial>
  </link>
  <joint name="pitch" type="revolute">
    <origin xyz="0 0.05 0.1" rpy="0 0 0"/>
    <parent link="turret"/>
    <child link="upper_arm"/>
    <axis xyz="0 1 0"/>
    <limit lower="-1.5" upper="1.5" effort="30" velocity="2"/>
  </joint>
  <link name="upper_arm">
    <inertial>
      <origin xyz="0.01 0 0.2" rpy="0 0 0"/>
      <mass value="1.5"/>
      <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.021" iyz="0" izz="0.003"/>
    </inertial>
  </link>
  <joint name="tool_joint" type="fixed">
    <origin xyz="0 0 0.4" rpy="0 0 0"/>
    <parent link="upper_arm"/>
    <child link="tool0"/>
  </joint>
  <link name="tool0"/>
</robot>
"""

MODEL_FILE = """[model]
name = "twoarm"
urdf = "urdf/twoarm.urdf"
base = "base_link"
tip = "tool0"
description = "A user's two-joint arm"

[joints.default]
K = 400.0         # N m/rad
Jm = 0.05         # kg m^2
Bm = 0.0          # N m s/rad
"""

#: What no output may hold: a traceback, the advice for the repository's own models, the arm's bare name
#: as a command argument (no command finds it by name: it lives outside the repository).
FORBIDDEN = ("Traceback", "make derive", "fjm design twoarm", "fjm simulate twoarm", "fjm excite twoarm",
             "(command line)")


@pytest.mark.slow
def test_a_users_urdf_arm_goes_through_every_command(tmp_path, capfd):
    arm = tmp_path / "my arm"
    (arm / "urdf").mkdir(parents=True)
    (arm / "urdf" / "twoarm.urdf").write_text(URDF)
    (arm / "twoarm.toml").write_text(MODEL_FILE)
    out, work = tmp_path / "my models", tmp_path / "work"
    work.mkdir()
    said = []

    def fjm(*argv, status=(0,)):
        with warnings.catch_warnings(record=True) as caught:     # numpy's notes would reach the user's terminal
            warnings.simplefilter("always")
            got = fjm_main([str(a) for a in argv])
        numeric = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
        assert not numeric, f"fjm {argv[0]}: {numeric}"
        o, e = capfd.readouterr()
        said.append(o + e)
        assert got in status, f"fjm {' '.join(map(str, argv))} exited {got}:\n{e}"
        for bad in FORBIDDEN:
            assert bad not in o + e, f"fjm {argv[0]}: {bad!r} in its output:\n{o + e}"
        return got, o, e

    # derive: chain.json is written beside the model for the MJCF export
    fjm("derive", "--model-file", arm / "twoarm.toml", "--out", out)
    assert (out / "twoarm" / "manifest.json").is_file() and (out / "twoarm" / "chain.json").is_file()
    m = fjm_runtime.load(str(out))
    assert m.name == "twoarm" and m.n == 2 and list(m.limits.effort) == [50.0, 30.0]

    # simulate on the --out folder: the default gains named as such, the URDF's efforts applied
    _, o, e = fjm("simulate", out, "--duration", "0.5", "--json", "--quiet")
    rep = json.loads(o)
    assert rep["gains_source"] == "defaults" and rep["settings"]["effort_limits"] == [50.0, 30.0]
    assert "the default gains" in e and "effort limits applied: 50, 30 N m" in e
    assert not rep["diverged"] and max(rep["rms_second_half"]) < 0.05
    assert all(p <= lim for p, lim in zip(rep["peak_torque"], (50.0, 30.0)))

    # analyze the same default gains (0: stable everywhere, 1: not; both documented)
    _, o, e = fjm("analyze", out / "twoarm", "--plants", "nominal", "--no-margins", "--task-times", "0.5",
                  "--json", status=(0, 1))
    record = json.loads(o)
    assert record["gains_source"] == "defaults" and record["model"] == "twoarm"
    assert np.isfinite(record["summary"]["rho"])

    # design on the smallest budget: a verdict either way (0 meets, 1 misses), recorded in the file
    design = work / "design.json"
    got, _, e = fjm("design", out, "--law", "ismc", "--draws", "3", "--recheck-draws", "0", "--duration", "0.5",
                    "--screen-draws", "3", "--screen-duration", "0.3", "--rounds", "1", "--threads", "1",
                    "--out", design, status=(0, 1))
    verdict = json.loads(design.read_text())
    assert verdict["model"] == "twoarm" and verdict["meets"] is (got == 0)
    assert ("meets every threshold" if got == 0 else "miss") in e.strip().splitlines()[-1]

    # simulate on the design: its conditions taken, the run holds
    _, o, e = fjm("simulate", out, "--gains", design, "--duration", "0.3", "--json", "--quiet", status=(0, 3))
    rep = json.loads(o)
    assert "the design's conditions" in e and rep["settings"]["sensing"] == verdict["sensing"]
    assert rep["settings"]["delay_samples"] == verdict["delay"]

    # export controller: --unverified exactly when the design missed, and the README says which
    ctl = work / "controller"
    fjm("export", "controller", out, "--gains", design, "--out", ctl, *([] if verdict["meets"] else ["--unverified"]))
    readme = next(ctl.glob("README*")).read_text()
    assert ("verified: the design meets" in readme) is verdict["meets"]
    assert ("UNVERIFIED" in readme) is (not verdict["meets"])

    # export mjcf: MuJoCo's accelerations from the file equal fjm's f + g u
    xml = work / "twoarm.xml"
    fjm("export", "mjcf", out, "--out", xml)
    plant = MujocoPlant(m, xml, None)
    rng = np.random.default_rng(5)
    for _ in range(5):
        x, u = rng.uniform(-1.0, 1.0, m.nx), rng.uniform(-10.0, 10.0, m.n)
        ref = m.f(x, None) + m.g(x, None) @ u
        assert np.max(np.abs(plant.xdot(x, u) - ref)) <= 1e-12 * np.max(np.abs(ref))

    # excite, then MuJoCo plays the excitation on the TRUE plant and logs it as a torque-sensed arm would
    exc = work / "excitation.csv"
    fjm("excite", out, "--duration", "5", "--out", exc, "--candidates", "4", "--iterations", "4")
    fourier = json.loads(exc.with_suffix(".json").read_text())["fourier"]
    reference = FourierReference(fourier["q0"], fourier["a"], fourier["b"], fourier["w0"])
    log = write_log(work / "log.csv", mujoco_log(m, reference, 5.0, work))

    # identify: the stiffness within 2 % of the truth, the hint names the arm by its path
    params = work / "params.toml"
    _, o, e = fjm("identify", out, log, "--out", params)
    assert f"fjm design {shlex.quote(str(m.directory))} --params {shlex.quote(str(params))}" in o
    assert params.read_text().startswith(f"# fjm identify {shlex.quote(str(m.directory))} {log}:")
    identified = tomllib.loads(params.read_text())
    true = {**true_params(m), "F_c1": FRICTION, "F_c2": FRICTION}
    for k in ("K1", "K2", "Jm1", "Jm2", "Bm1", "Bm2"):    # the truth inside the interval the file states
        value, half = identified["parameters"][k], identified["spread"][k]
        assert abs(value / true[k] - 1.0) <= half, (k, value, true[k], half)
    assert abs(identified["parameters"]["K2"] / true["K2"] - 1.0) < 0.02   # the gravity-loaded joint
    assert len(said) == 9
