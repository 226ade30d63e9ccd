"""``fjm export controller`` exports what was verified and refuses what it cannot honour.

A design whose search found it misses its thresholds (``"meets": false``) is refused unless
``--unverified`` (then labelled so); a flag of the other export format, substeps out of range or
without prediction, a parameter or gain the C cannot hold, a name that is not a C prefix: one line
naming the flag, the value and the range, nothing written. Every shipped design exports, and its
exported step (the CasADi Function the C is generated from) gives the simulator's torques.
"""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.cli.main import main as fjm_main
from fjm_runtime.control.design import Design
from fjm_runtime.export.controller import design_controller, export_controller
from fjm_runtime.export.controller_checks import MAX_SUBSTEPS, default_c_name
from fjm_runtime.export.controller_step import controller_functions

from support.controller_runs import LINK1_TORQUE_DESIGN as LINK1, Run, relative


def _file(tmp_path, spec, name="design.json"):
    p = tmp_path / name
    p.write_text(json.dumps(spec))
    return p


def _refused(tmp_path, capsys, argv):
    """``fjm export ...`` with ``argv``: status 2, one stderr line without a traceback, nothing written."""
    out = tmp_path / "out"
    status = fjm_main(["export", *argv, "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert status == 2 and err.count("\n") == 0 and "Traceback" not in err, (status, err)
    assert not out.exists(), err
    return err


def _c_values(path, array):
    """The numbers of the C initializer ``array`` in the source at ``path``."""
    body = re.search(rf"{array}\[[A-Z0-9_]+\] = \{{(.*?)\}};", path.read_text(), re.S).group(1)
    return np.array([float(v) for v in body.replace("\n", " ").split(",")])


def test_unverified_design_is_refused_and_labelled(tmp_path, capsys):
    gains = _file(tmp_path, {**LINK1, "meets": False, "misses": [{"message": "rms"}]})
    err = _refused(tmp_path, capsys, ["controller", "link1", "--gains", str(gains)])
    assert f"--gains {gains}: \"meets\": false" in err and "--unverified" in err, err
    labels = {}
    for meets, flag in ((False, ["--unverified"]), (True, []), (None, [])):
        spec = {**LINK1, **({} if meets is None else {"meets": meets})}
        out = tmp_path / f"lib_{meets}"
        assert fjm_main(["export", "controller", "link1", "--gains", str(_file(tmp_path, spec)), "--out", str(out),
                         *flag]) == 0
        header = (out / "link1_ismc_tau_controller.h").read_text()
        labels[meets] = re.search(r"\* Design: (\w+)", header).group(1)
        assert f"**Design: {labels[meets]}" in (out / "README.md").read_text()
        # the library holds exactly the design's gains and nominal parameters, verified or not
        design = design_controller(fjm_runtime.load("link1"), Design.from_dict(spec), unverified=True)
        np.testing.assert_array_equal(_c_values(out / "link1_ismc_tau_controller.c", "link1_ismc_tau_gains_design"),
                                      np.asarray(design.controller.gains, dtype=float))
        np.testing.assert_array_equal(_c_values(out / "link1_ismc_tau_controller.c", "link1_ismc_tau_p_design"),
                                      np.asarray(design.controller.p_nom, dtype=float))
    assert labels == {False: "UNVERIFIED", True: "verified", None: "not"}, labels


@pytest.mark.parametrize("argv,expect", [
    (["--K", "3000"], "--K 3000: export controller does not use it"),
    (["--param", "K=3"], "--param K=3: export controller does not use it"),
    (["--timestep", "0.001"], "--timestep 0.001: export controller does not use it"),
    (["--gear-ratio", "100"], "--gear-ratio 100: export controller does not use it"),
    (["--substeps", "1e8"], f"--substeps 1e+08: expected an integer 1..{MAX_SUBSTEPS}"),
    (["--substeps", "0"], f"--substeps 0: expected an integer 1..{MAX_SUBSTEPS}"),
    (["--substeps", "2.5"], f"--substeps 2.5: expected an integer 1..{MAX_SUBSTEPS}"),
    (["--substeps", "nan"], f"--substeps nan: expected an integer 1..{MAX_SUBSTEPS}"),
    (["--name", "bad name!"], "--name 'bad name!': expected a C identifier of 1..64 characters"),
    (["--name", "a__b"], "--name 'a__b': expected a C identifier"),
    (["--name", "ctrl_"], "--name 'ctrl_': expected a C identifier"),
    (["--name", "int"], "--name 'int': expected a C identifier"),
    (["--name", "x" * 65], "expected a C identifier of 1..64 characters"),
])
def test_controller_flags_it_cannot_honour(tmp_path, capsys, argv, expect):
    err = _refused(tmp_path, capsys, ["controller", "link1", "--gains", str(_file(tmp_path, LINK1)), *argv])
    assert expect in err, err


def test_substeps_without_prediction_and_values_the_c_cannot_hold(tmp_path, capsys):
    no_predict = _file(tmp_path, {**LINK1, "predict": False}, "np.json")
    err = _refused(tmp_path, capsys, ["controller", "link1", "--gains", str(no_predict), "--substeps", "5"])
    assert f"--substeps 5: the design does not predict" in err and f"1..{MAX_SUBSTEPS}" in err, err
    params = tmp_path / "p.toml"
    for value in ("1e300", "1e-300"):
        params.write_text(f"[parameters]\nK = {value}\n")
        err = _refused(tmp_path, capsys, ["controller", "link1", "--gains", str(_file(tmp_path, LINK1)),
                                          "--params", str(params)])
        assert f"--params {params}: [parameters] K = {float(value):g}: expected 0 or 1e-12 <= |value| <= 1e+12" \
            in err, err
    nominal = _file(tmp_path, {**LINK1, "params": {"nominal": {"J_m": 1e300}}}, "nom.json")
    err = _refused(tmp_path, capsys, ["controller", "link1", "--gains", str(nominal)])
    assert f"--gains {nominal}: params.nominal.J_m = 1e+300: expected 0 or 1e-12" in err, err
    huge = _file(tmp_path, {**LINK1, "gains": {**LINK1["gains"], "k_s": 1e300}}, "ks.json")
    err = _refused(tmp_path, capsys, ["controller", "link1", "--gains", str(huge)])
    assert f"--gains {huge}: gain k_s = 1e+300: expected 0 or 1e-12 <= |value| <= 1e+20" in err, err


@pytest.mark.parametrize("argv", [["--gains", "g.json"], ["--unverified"], ["--substeps", "4"], ["--name", "x"],
                                  ["--params", "p.toml"]])
def test_mjcf_refuses_the_controller_flags(tmp_path, capsys, argv):
    err = _refused(tmp_path, capsys, ["mjcf", "link1", *argv])
    assert err.startswith(f"fjm: error: {argv[0]}") and "export mjcf does not use it" in err, err


def test_accepted_edges_and_default_names():
    """The range's ends are accepted as given; a model name that is not a C prefix gives a usable one."""
    m = fjm_runtime.load("link1")
    for substeps in (1, float(MAX_SUBSTEPS)):
        assert design_controller(m, Design.from_dict(LINK1), substeps=substeps).layout.substeps == int(substeps)
    assert design_controller(m, Design.from_dict(LINK1), name="arm_2").name == "arm_2"
    names = {t: default_c_name(t) for t in ("my-arm_ismc", "2dof_smc", "arm__x-_ismc", "int")}
    assert names == {"my-arm_ismc": "my_arm_ismc", "2dof_smc": "ctrl_2dof_smc", "arm__x-_ismc": "arm_x_ismc",
                     "int": "int_ctrl"}, names


def _shipped():
    """The shipped designs whose step outputs the motor torque (a joint-torque design's step outputs the desired
    link torque tau_d before the robot's layer: test_controller_impedance checks its library against the law)."""
    from importlib import resources
    folder = resources.files("fjm_runtime.control").joinpath("designed")
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".json")
                  and (json.loads(p.read_text()).get("interface") or {}).get("kind", "motor") == "motor")


@pytest.mark.slow
@pytest.mark.parametrize("file", _shipped())
def test_every_shipped_design_exports_and_its_step_is_the_simulators(tmp_path, file):
    """Each shipped design (panda_hd: seven nonlinear springs, predicted through psi^-1) exports, as does
    the same design without prediction (fjm design's default; no K_i needed); the exported step Function,
    evaluated from the simulator's controller state at each of 20 samples, gives the run's torques to 1e-12."""
    spec = Design.load(fjm_runtime.__path__[0] + f"/control/designed/{file}").as_dict()
    model = fjm_runtime.load(spec["model"])
    for predict in (True, False):
        design = design_controller(model, Design.from_dict({**spec, "predict": predict}))
        files = export_controller(design, tmp_path / f"lib_{predict}")
        assert f"{design.name}_float_ctrl_step.c" in files and f"{design.name}_controller.hpp" in files
        step, _ = controller_functions(model, design.controller, design.layout, design.name)
        run = Run(design, 0.02)
        p, g = np.asarray(design.controller.p_nom), np.asarray(design.controller.gains)
        U = np.stack([np.asarray(step(run.C[k], run.M[k], run.R[k], p, g)[0]).ravel() for k in range(run.M.shape[0])])
        rel = relative(U, run.U)
        print(f"{file} predict {predict}: exported step vs simulator, 20 samples: {rel:.3g}")
        assert rel <= 1e-12


@pytest.mark.parametrize("argv,expect", [
    (["--K", "1e300"], "--K = 1e+300: expected 0 or 1e-12 <= |value| <= 1e+12"),
    (["--param", "K=1e-300"], "--param K = 1e-300: expected 0 or 1e-12 <= |value| <= 1e+12"),
    (["--timestep", "1e6"], "--timestep 1e+06: expected 1e-07 <= timestep <= 0.01 s"),
    (["--timestep", "0"], "--timestep 0: expected 1e-07 <= timestep <= 0.01 s"),
])
def test_mjcf_values_out_of_range(tmp_path, capsys, argv, expect):
    out = tmp_path / "out.xml"
    assert fjm_main(["export", "mjcf", "link1", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert expect in err and err.count("\n") == 0 and not out.exists(), err


def test_label_of_a_searched_design_without_a_verdict():
    """The shipped Panda design predates the "meets" key: its label states its search's draws and worst
    RMS (the file's numbers), not "verified"."""
    from fjm_runtime.export.controller_checks import verification_text
    d = Design.shipped("panda", "ismc", "torque", 1000.0, 1)
    rms = max(d.report["worst_case"]["rms_second_half"])
    text = verification_text(d.meets, dict(d.report))
    assert d.meets is None and d.report["draws"] == 200 and rms < 2e-3
    assert text.startswith(f"searched by fjm design over 200 plant draws (worst second-half RMS {rms:.3g} rad, "
                           f"{d.report['worst_case']['diverged']} diverged)"), text


@pytest.mark.parametrize("interface", ["joint_torque", "motor"])
def test_the_library_outputs_what_the_interface_takes(interface):
    """joint_torque: the exported step outputs the law's tau_d (the robot filters, limits it and adds gravity;
    its last command and the current loop are not in the library's state); motor: the motor torque. Against
    the law evaluated on the same reading, and the runtime's filtered command, which differs."""
    from fjm_runtime.sim.sample_step import initial_measurement, initial_step_state, python_sample_step
    spec = dict(LINK1, delay=0, predict=False, noise="ideal", interface=interface)
    design = design_controller(fjm_runtime.load("link1"), Design.from_dict(spec))
    L, ctrl, CL = design.layout, design.controller, design.cstate
    step, _ = controller_functions(design.model, ctrl, L, "t")
    n = L.n
    assert CL.nc == L.nw - L.nx - n * (L.current_decay > 0) - n * (interface == "joint_torque")
    x = np.array([0.3, 0.2, 0.36, -0.1])
    p = design.model.params_array({})
    r = np.array([0.5, 0.1, 0.0, 0.0, 0.0])
    m = initial_measurement(design.model, L, x, p)
    w = initial_step_state(design.model, L, x, np.zeros(L.nz), p, controller=ctrl)
    u_lib = float(np.asarray(step(CL.from_step_state(w), m, r, ctrl.p_nom, ctrl.gains)[0]).ravel()[0])
    u_law = float(np.asarray(ctrl.evaluate(0.0, m, np.zeros(L.nz), r.reshape(5, 1)).u).ravel()[0])
    assert abs(u_lib - u_law) <= 1e-12 * max(1.0, abs(u_law))
    u_runtime = float(python_sample_step(design.model, ctrl, L, w, 0.0, r, np.zeros(L.nm), p)[1].u[0])
    if interface == "joint_torque":          # the robot's 100 Hz filter against its last command
        assert abs(u_runtime - u_law) > 0.1 * abs(u_law) > 0
    else:
        assert u_runtime == pytest.approx(u_law, rel=1e-12)



def test_a_joint_torque_library_with_prediction_is_the_simulators_law():
    """joint_torque with one sample of delay and prediction (the predictor runs the robot's torque loop and
    gravity on the nominal model, in the library too): from the simulator's controller state at each of 30
    samples, the exported step's tau_d is the law's, recovered from the robot's filtered commands c_k by
    inverting libfranka's recursion, tau_d = (c_k - (1 - a) c_{k-1}) / a."""
    spec = dict(LINK1, noise="ideal", interface={"kind": "joint_torque", "lowpass_cutoff_hz": 100.0, "K_T": -0.3,
                                                 "D_T": 0.005})
    design = design_controller(fjm_runtime.load("link1"), Design.from_dict(spec))
    L, ctrl = design.layout, design.controller
    assert L.predict and L.interface == "joint_torque" and L.has_last
    step, _ = controller_functions(design.model, ctrl, L, design.name)
    ref = fjm_runtime.make_reference("sine", 1, amplitude=0.3, omega=3.0, offset=0.3)
    run = Run(design, 0.03, ref, np.array([0.3, 0.0, 0.3 + 9.8 * np.sin(0.3) / 150.0, 0.0]))   # at rest, held
    p, g = np.asarray(ctrl.p_nom), np.asarray(ctrl.gains)
    U = np.stack([np.asarray(step(run.C[k], run.M[k], run.R[k], p, g)[0]).ravel() for k in range(run.M.shape[0])])
    c = np.vstack([run.W[0][L.extra_slices()[2]][None], run.U])
    a = L.lowpass_alpha
    tau_d = (c[1:] - (1.0 - a) * c[:-1]) / a
    assert relative(U, tau_d) <= 1e-12 and np.max(np.abs(U - run.U)) > 1e-3   # tau_d, not the filtered c
