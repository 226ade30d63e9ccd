"""The impedance laws in the exported C library (``fjm export controller``): the Panda's motor-side impedance
(franka_like, one sample of delay with prediction, the motor interface) gives the simulator's torques and
controller state to 1e-12 per sample and from reset; the joint impedance on the franka interface outputs the
law's tau_d (recovered from the robot's filtered commands); the C++ class runs it; a law on an interface it is
not made for is refused in one line."""
from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.control.design import Design, task_start
from fjm_runtime.export.controller import design_controller
from fjm_runtime.export.controller_step import controller_functions
from fjm_runtime.validation import FjmValueError

from support.controller_runs import FREE_SAMPLES, NOT_FINITE, SATURATED, Run, free_running, library, per_sample, relative


def _spec(kind, interface, **gains):
    m = fjm_runtime.load("panda")
    return {"model": "panda", "kind": kind, "sensing": "full", "rate": 1000.0, "delay": 1, "predict": True,
            "noise": "franka_like", "interface": interface, "gains": {"u_max": list(m.limits.effort), **gains}}


def _task_run(design, duration):
    m, ref = design.model, design.model.task.reference()
    return Run(design, duration, ref, task_start(m, ref, "holding gravity", design.controller.p_nom))


@pytest.mark.slow
def test_panda_impedance_library_equals_simulator(tmp_path_factory):
    """0.5 s of the Panda's task from rest holding gravity: per sample from the simulator's controller state,
    the C torques and next state are the run's to 1e-12; from reset, the first samples too."""
    design = design_controller(fjm_runtime.load("panda"), Design.from_dict(_spec("impedance", "motor")))
    run = _task_run(design, 0.5)
    lib = library(design, tmp_path_factory)
    U, S, C_next = per_sample(lib, run)
    rel, rel_c = relative(U, run.U), relative(C_next[:-1], run.C[1:])
    Uf, _ = free_running(lib, run, FREE_SAMPLES)
    rel_free = relative(Uf, run.U[:FREE_SAMPLES])
    print(f"\n{design.name}: per sample {rel:.3g}, state {rel_c:.3g}, from reset {rel_free:.3g}")
    assert np.all(S != NOT_FINITE) and np.max(np.abs(run.U)) > 1.0
    assert rel <= 1e-12 and rel_c <= 1e-12 and rel_free <= 1e-12


@pytest.mark.slow
def test_panda_joint_impedance_library_outputs_the_laws_tau_d(tmp_path_factory):
    """franka interface: the library's output is tau_d; the simulator's commands are the robot's filtered
    c_k = a tau_d + (1 - a) c_{k-1} (rate-limited), so on every sample the 1 N m per tick limit did not hold,
    tau_d = (c_k - (1 - a) c_{k-1}) / a is the library's to 1e-12."""
    design = design_controller(fjm_runtime.load("panda"), Design.from_dict(_spec("joint_impedance", "franka")))
    L = design.layout
    run = _task_run(design, 0.2)
    U, S, _ = per_sample(library(design, tmp_path_factory), run)
    c = np.vstack([run.W[0][L.extra_slices()[2]][None], run.U])
    free = np.all(np.abs(np.diff(c, axis=0)) < 0.999 * np.asarray(L.rate_step), axis=1)
    a = L.lowpass_alpha
    tau_d = (c[1:] - (1.0 - a) * c[:-1]) / a
    rel = relative(U[free], tau_d[free])
    print(f"\n{design.name}: tau_d vs the simulator's law {rel:.3g} on {np.mean(free):.0%} of the samples")
    assert np.all(S <= SATURATED) and np.mean(free) > 0.5
    assert rel <= 1e-12 and np.max(np.abs(U - run.U)) > 1e-3     # tau_d, not the filtered command


@pytest.mark.slow
def test_cli_export_impedance_and_the_cxx_class(tmp_path):
    """`fjm export controller panda --gains impedance.json` + make (strict C99, float, C++17 check), then a C++
    program driving ``panda_impedance::Controller<double>`` from reset on the simulator's readings: its first
    samples are the simulator's torques to 1e-12, every one finite."""
    from fjm_runtime.cli.main import main
    assert shutil.which("make") and shutil.which("g++"), "make and g++ are needed (the C++ class is built)"
    gains = tmp_path / "impedance.json"
    gains.write_text(json.dumps(_spec("impedance", "motor")))
    out = tmp_path / "lib"
    assert main(["export", "controller", "panda", "--gains", str(gains), "--out", str(out)]) == 0
    proc = subprocess.run(["make", "-C", str(out)], capture_output=True, text=True)
    assert proc.returncode == 0 and "warning" not in proc.stderr.lower(), proc.stderr[-2000:]
    src, exe = tmp_path / "run.cpp", tmp_path / "run"
    src.write_text('#include "panda_impedance_controller.hpp"\n#include <cstdio>\n#include <cstdlib>\n'
                   "int main(int argc, char** argv) {\n  using C = panda_impedance::Controller<double>;\n"
                   "  if (argc != 4) return 1;\n  C ctrl; C::Reading m{}; C::Reference r{}; C::Torque u{}; long K = std::atol(argv[1]);\n"
                   '  FILE* in = std::fopen(argv[2], "rb"); FILE* out = std::fopen(argv[3], "wb");\n'
                   "  if (!in || !out || std::fread(m.data(), sizeof(double), C::NM, in) != C::NM) return 2;\n"
                   "  if (ctrl.init() != panda_impedance::Status::ok || ctrl.reset(m) != panda_impedance::Status::ok)"
                   " return 3;\n"
                   "  for (long k = 0; k < K; ++k) {\n"
                   "    if (std::fread(m.data(), sizeof(double), C::NM, in) != C::NM) return 4;\n"
                   "    if (std::fread(r.data(), sizeof(double), r.size(), in) != r.size()) return 5;\n"
                   "    if (int(ctrl.update(m, r, u)) > int(panda_impedance::Status::saturated)) return 6;\n"
                   "    std::fwrite(u.data(), sizeof(double), C::N, out); }\n  std::fclose(out); return 0; }\n")
    proc = subprocess.run(["g++", "-std=c++17", "-O2", "-Wall", "-Wextra", "-Werror", f"-I{out}", str(src),
                           str(out / "libpanda_impedance.a"), "-lm", "-o", str(exe)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    design = design_controller(fjm_runtime.load("panda"), Design.load(gains))
    run = _task_run(design, 0.1)
    K = run.M.shape[0]
    np.concatenate([run.m0] + [np.concatenate([run.M[k], run.R[k]]) for k in range(K)]).tofile(tmp_path / "in.bin")
    proc = subprocess.run([str(exe), str(K), str(tmp_path / "in.bin"), str(tmp_path / "out.bin")])
    assert proc.returncode == 0
    U = np.fromfile(tmp_path / "out.bin").reshape(K, 7)
    rel = relative(U[:FREE_SAMPLES], run.U[:FREE_SAMPLES])
    print(f"\nC++ class from reset vs the simulator, first {FREE_SAMPLES} samples: {rel:.3g}")
    assert np.all(np.isfinite(U)) and rel <= 1e-12


@pytest.mark.parametrize("kind, interface, needle", [("impedance", "franka", "impedance on motor"),
                                                     ("joint_impedance", "motor", "joint_torque interface")])
def test_a_law_on_the_wrong_interface_is_refused(kind, interface, needle):
    with pytest.raises(FjmValueError) as e:
        design_controller(fjm_runtime.load("panda"), Design.from_dict(_spec(kind, interface), "impedance.json"))
    msg = str(e.value)
    assert "\n" not in msg and needle in msg and f"interface {interface}" in msg and "impedance.json" in msg


def test_the_step_of_a_joint_impedance_design_is_its_law():
    """No compile: the exported step at the rest state of the task is the law evaluated on the same reading."""
    from fjm_runtime.sim.sample_step import initial_measurement, initial_step_state
    spec = dict(_spec("joint_impedance", "franka"), delay=0, predict=False, noise="ideal")
    design = design_controller(fjm_runtime.load("panda"), Design.from_dict(spec))
    L, ctrl, CL, m = design.layout, design.controller, design.cstate, design.model
    step, _ = controller_functions(m, ctrl, L, "t")
    ref = m.task.reference()
    x = task_start(m, ref, "holding gravity", ctrl.p_nom)
    r = np.asarray(ref.sample(np.array([0.3])), dtype=float).reshape(-1)
    meas = initial_measurement(m, L, x, ctrl.p_nom)
    w = initial_step_state(m, L, x, np.zeros(L.nz), ctrl.p_nom, controller=ctrl)
    u_lib = np.asarray(step(CL.from_step_state(w), meas, r, ctrl.p_nom, ctrl.gains)[0]).ravel()
    u_law = np.asarray(ctrl.evaluate(0.0, meas, np.zeros(L.nz), r.reshape(5, m.n)).u).ravel()
    assert np.max(np.abs(u_lib - u_law)) <= 1e-12 * max(1.0, np.max(np.abs(u_law))) and np.max(np.abs(u_law)) > 0.1
