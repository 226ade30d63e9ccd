"""From a robot's log to a controller that holds on the true plant: excite, log, identify, design, verify.

    .venv/bin/python examples/identify_roundtrip.py [MODEL] [--duration 20] [--design] [--out DIR]

MuJoCo plays the robot (an engine nobody here wrote); nothing of the TRUE plant is known to fjm
except through the log:

1. ``fjm excite``: a rest-to-rest Fourier-series excitation for the model (best-conditioned of 20 draws
   and 40 local-search steps, within the limits).
2. The TRUE plant: the model's defaults with the stiffness x1.15, the rotor inertia x0.9, motor
   damping B_m and dry friction on every rotor (MuJoCo's ``frictionloss``, a constraint-based
   Coulomb friction, not fjm's tanh), exported with ``fjm export mjcf`` and run by MuJoCo at 1 kHz
   with the torque held over the sample on fjm's substeps. The log is what a torque-sensed arm
   records: ``q``, ``q_m`` through quantized noisy encoders and ``tau_J`` with noise and a constant
   offset (the ``franka_like`` sensor levels), and the commanded torque ``u`` of a PD on the motor
   angle plus the nominal feedforward of the excitation (a loop that is stable whatever the spring).
3. ``fjm identify``: stiffness, rotor inertia, damping and Coulomb friction per joint -> params.toml.
4. The controller on the identified values: the shipped design's gains where the model has one
   (the Panda), else ``fjm design MODEL --params params.toml`` (state sensing, ``panda_white`` noise,
   delay 1 with prediction: seconds for link1; ``--design`` forces it, minutes for the Panda).
   The ``franka_like`` preset's torque-rate limit makes every design of this law family miss (a
   rare draw diverges: docs/design-command.md), so the control loop's noise is ``panda_white``.
5. That controller, exported as the C library, on the TRUE MuJoCo plant with the design's noise and
   one sample of delay with prediction: worst-joint RMS, time at a limit, jitter.

It prints identified against true values (error in %), the fit's residuals, the final tracking,
and exits with 0 when the identification meets its tolerances (stiffness 2 %, rotor inertia 5 %)
and the loop holds (RMS <= 2e-3 rad, <= 2 % at a limit).
"""
from __future__ import annotations

import argparse
import importlib.util
import dataclasses
import subprocess
import sys
import tempfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np

import fjm_runtime
from fjm_runtime.control.design import Design
from fjm_runtime.drives import role_names
from fjm_runtime.export.controller import design_controller
from fjm_runtime.export.controller_step import raw_reading, rest_reading
from fjm_runtime.ident.excite import design_excitation
from fjm_runtime.ident.identify import identify
from fjm_runtime.ident.mujoco_robot import (B_M, FRICTION, JM_FACTOR, K_FACTOR, RATE, mujoco_log, mujoco_plant,
                                             true_params)
from fjm_runtime.ident.report import table_lines
from fjm_runtime.sim.metrics import rms_second_half, time_at_limit, torque_jitter
from fjm_runtime.sim.rest import rest_state
from fjm_runtime.sim.sensor import noise_array, offset_normals
from fjm_runtime.sim.substeps import resolve_substeps

HERE = Path(__file__).resolve().parent
TOLERANCE = {"stiffness": 0.02, "rotor inertia": 0.05}


def _c_example():
    spec = importlib.util.spec_from_file_location("mujoco_c_controller", HERE / "mujoco_c_controller.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def errors(model, ident) -> dict:
    """``{name: (identified, true, relative error)}`` for the model's K, J_m, B_m and the friction."""
    p, out = true_params(model), {}
    K, J, B = (role_names(model, role) for role in ("stiffness", "rotor_inertia", "damping"))
    for i in range(model.n):
        for nm in (K[i], J[i], B[i]):
            out[nm] = (ident.values[nm], p[nm], ident.values[nm] / p[nm] - 1.0)
        fc = f"F_c{i + 1}"
        if fc in ident.values:
            out[fc] = (ident.values[fc], FRICTION, ident.values[fc] / FRICTION - 1.0)
    return out


def controller_spec(model, params_file: Path, design: bool, work: Path, sensing: str, noise: str) -> Design:
    """Step 4: the shipped design (if the model has one and ``design`` is False), else ``fjm design
    MODEL --params params.toml`` (``sensing``, ``noise``, delay 1); params.nominal = the identified values."""
    from fjm_runtime.analysis.search.draws import load_params_file
    nominal = load_params_file(params_file, model).overrides
    spec = None if design else Design.shipped(model.name, "ismc", "torque", RATE, 1)
    if spec is None:
        out = work / "design.json"
        cmd = [sys.executable, "-m", "fjm_runtime.cli", "design", model.name, "--params", str(params_file),
               "--sensing", sensing, "--noise", noise, "--predict", "--out", str(out)]
        print("4. " + " ".join(["fjm"] + cmd[3:]))
        subprocess.run(cmd, check=False, stdout=subprocess.DEVNULL)
        spec = Design.load(out, where=str(out))
        print(f"   design {'meets' if spec.meets else 'MISSES'} its thresholds on fjm's draws; gains "
              f"{spec.gains}")
    else:
        print(f"4. the shipped design of {model.name} (gains {sorted(spec.gains)}) on the identified values")
    return dataclasses.replace(spec, params={**(spec.params or {}), "nominal": nominal}, source="round trip")


def closed_loop(model, spec: Design, duration: float, work: Path, friction: float = FRICTION):
    """Step 5: the design's C library on the TRUE MuJoCo plant, the design's noise, delay and task."""
    cex = _c_example()
    design = design_controller(model, spec)
    lib = cex.CController(cex.build_library(design, work / "lib"), design)
    L, sensor = design.layout, design.sensor
    ref = spec.reference(model)
    if ref is None:                       # a generic design's task: sines from rest (fjm design --task sine)
        from fjm_runtime.control.references import make_reference
        r = spec.task or {}
        ref = make_reference("sine", model.n, amplitude=r.get("amplitude", 0.5), omega=r.get("omega", 1.0))
    p_true = true_params(model)
    p = model.params_array(p_true)
    x0 = rest_state(model, ref(0.0)[0], p_true)
    plant = mujoco_plant(model, p_true, work, resolve_substeps(None, model, x0, p, L.T), friction)
    plant.set_state(x0)
    subs = resolve_substeps(None, model, x0, p, L.T)
    n, steps = L.n, int(round(duration / L.T))
    t = L.T * np.arange(steps + 1)
    R = np.asarray(ref.sample(t), dtype=float).reshape(t.size, 5 * n)
    noise = noise_array(sensor, L.sensing, n, t.size)
    w = np.zeros(L.nw)
    if L.offset:
        w[L.extra_slices()[1]] = sensor.offsets(n) * offset_normals(int(sensor.seed), n)
    lib.reset(rest_reading(model, L, x0, p))
    X, U = np.zeros((t.size, L.nx)), np.zeros((t.size, n))
    for k in range(t.size):
        X[k] = w[:L.nx] = plant.state()
        _, U[k] = lib.step(raw_reading(model, L, w, noise[k], p), R[k])
        if k < steps:
            plant.step(U[k], subs)
    u_max = getattr(design.controller, "u_max", None)
    res = SimpleNamespace(t=t, x=X, u=U, e1=X[:, :n] - R[:, :n], u_max=None if u_max is None else np.asarray(u_max))
    return res, design


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", nargs="?", default="panda")
    ap.add_argument("--duration", type=float, default=20.0, help="length of the excitation log, s (default 20)")
    ap.add_argument("--loop-duration", type=float, default=10.0, help="final closed loop, s (default 10)")
    ap.add_argument("--design", action="store_true",
                    help="run fjm design on the identified values even where a shipped design exists (Panda: minutes)")
    ap.add_argument("--sensing", choices=("state", "torque"), default="state", help="fjm design's sensing (state)")
    ap.add_argument("--noise", default="panda_white", help="fjm design's sensor preset (panda_white)")
    ap.add_argument("--out", type=Path, default=None, help="keep the files here (default: a temp directory)")
    args = ap.parse_args(argv)
    m = fjm_runtime.load(args.model)
    with tempfile.TemporaryDirectory(prefix="fjm-roundtrip-") as tmp:
        work = args.out or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        exc = design_excitation(m, args.duration)
        print(f"1. excitation: condition number {exc.condition:.3g}, limits used {exc.usage}")
        log = mujoco_log(m, exc.reference, args.duration, work)
        print(f"2. MuJoCo log: {log.t.size} samples of the true plant (K x{K_FACTOR}, J_m x{JM_FACTOR}, B_m {B_M}, "
              f"frictionloss {FRICTION} N m), franka_like sensor levels")
        ident = identify(m, log)
        params = ident.to_toml(work / "params.toml", m)
        print("3. identified:\n   " + "\n   ".join(table_lines(ident)))
        errs = errors(m, ident)
        for nm, (v, true, e) in errs.items():
            print(f"   {nm:6s} identified {v:10.5g}  true {true:10.5g}  error {100 * e:+7.2f} %")
        K, J = role_names(m, "stiffness"), role_names(m, "rotor_inertia")
        seen = lambda k: k not in ident.not_excited  # noqa: E731 - the file keeps the model's value for the others
        ok_id = all(abs(errs[k][2]) <= TOLERANCE["stiffness"] for k in K if seen(k)) and \
            all(abs(errs[j][2]) <= TOLERANCE["rotor inertia"] for j in J if seen(j))
        if ident.not_excited:
            print(f"   not excited (the model's value kept): {', '.join(ident.not_excited)}")
        spec = controller_spec(m, params, args.design, work, args.sensing, args.noise)
        res, design = closed_loop(m, spec, args.loop_duration, work)
    rms, lim, jit = rms_second_half(res), time_at_limit(res), torque_jitter(res)
    holds = bool(np.all(np.isfinite(res.x))) and float(np.max(rms)) <= 2e-3 and float(np.max(lim)) <= 0.02
    print(f"5. {design.name} on the identified values vs the TRUE MuJoCo plant ({args.loop_duration:g} s, "
          f"delay 1 with prediction): worst RMS {np.max(rms):.2e} rad, {100 * np.max(lim):.1f} % at a limit, "
          f"jitter {np.max(jit):.2f} N m: {'holds' if holds else 'FAILS'}")
    print(f"identification of the excited parameters within tolerance (K {TOLERANCE['stiffness']:.0%}, "
          f"J_m {TOLERANCE['rotor inertia']:.0%}): "
          f"{'yes' if ok_id else 'NO'}")
    return 0 if ok_id and holds else 1


if __name__ == "__main__":
    sys.exit(main())
