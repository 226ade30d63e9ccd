"""The Panda's shipped design, as the exported C library, against MuJoCo's complete Panda.

    .venv/bin/python examples/mujoco_c_controller.py [--duration 10] [--gains FILE] [--noise PRESET] [--keep DIR]

1. ``fjm export controller panda --gains <shipped design>`` writes the C library of
   ``fjm_runtime/control/designed/panda_ismc_tau_1000hz_d1.json`` (torque-sensed integral
   SMC, 1 kHz, sensor preset ``panda_white``, dtau_J the filtered difference of tau_J, one
   sample of delay with prediction over the nominal REDUCED model) into a temporary directory;
   ``make -C DIR lib<name>.so`` builds it (strict C99) and ``ctypes`` loads it.
2. ``fjm export mjcf panda --complete`` (``write_mjcf``) writes the COMPLETE Panda (rotors on the
   links, gear ratio 100: spin coupling and gyroscopic terms the law was not designed with);
   MuJoCo integrates it with RK4 at ``1 ms / substeps`` (fjm's substeps rule for that plant).
3. Every millisecond ``t_k``: MuJoCo's state gives the RAW reading the robot hands over,
   ``[q; dq; tau_J; dtau_J; dq_m]`` with the design's sensor noise (``noise_array``: the
   simulator's own noise sequence; quantization and the tau_J offset when the preset has
   them; the design's dtau_J slot is not read: the library filters tau_J), built by
   :func:`fjm_runtime.export.controller_step.raw_reading`. ``<name>_step`` returns the torque,
   which MuJoCo holds over ``[t_k, t_k+1)``. The delay is the library's: as in the sample step
   (:mod:`fjm_runtime.sim.sample_step`) the law at ``t_k`` sees the reading of ``t_{k-1}``
   (its ring buffer), predicted one sample ahead with the nominal model under the torque
   already sent. Nothing else is done in Python: no filter, no buffer, no clipping.
4. It prints the design's figures -- worst-joint second-half RMS, time at a torque limit,
   torque jitter on joints 1-4 -- against the thresholds ``fjm design`` verified it with
   (2e-3 rad, 2 %, 3 N m) and exits with 0 when all hold, 1 otherwise.

``--gains FILE`` runs another design file of the Panda (e.g. a new ``fjm design`` result).
``--law impedance`` runs the motor-side impedance instead (franka_like sensing, 1 kHz, one sample of delay
with prediction, the ``motor`` interface: the shipped ``panda_impedance_1000hz_d1.json`` when there is one,
else the law's default gains on the same task) against MuJoCo's REDUCED Panda (the model the law was derived
for), the library's torque command going through the interface's 2 kHz current loop per MuJoCo step
(:class:`fjm_runtime.export.bridge.Actuation`; the complete-Panda run holds ``ctrl = u`` over the sample, as it
was measured). Measured with the default gains over the 10 s task: worst-joint RMS 3.9e-5 rad (joint 7), jitter
0.14 N m on joints 1-4, never at a torque limit; fjm's simulator of the same design on the same plant agrees to
0.5 % per joint (3 s).
``--noise franka_like`` exports the design's gains with that sensor preset instead (quantized
encoders, differentiated velocities, tau_J offset, 1000 N m/s torque-rate limit), all handled in the
library. The shipped gains were designed for ``panda_white`` and do NOT hold with ``franka_like``:
measured, every sample at a limit, worst RMS 1.4e2 rad over 10 s; fjm's own simulator on the reduced
plant diverges the same way (``fjm simulate panda --gains <shipped> --sensing torque --delay-samples 1
--predict --noise franka_like``). That needs a design made for that sensor, not a change here.
"""

from __future__ import annotations

import argparse
import ctypes
import dataclasses
import subprocess
import sys
import tempfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np

import fjm_runtime
from fjm_runtime.control.design import Design
from fjm_runtime.control.coupling import complete_plant
from fjm_runtime.export.controller import design_controller, export_controller
from fjm_runtime.export.controller_step import raw_reading, rest_reading
from fjm_runtime.sim.metrics import rms_second_half, time_at_limit, torque_jitter
from fjm_runtime.sim.sensor import noise_array, offset_normals
from fjm_runtime.sim.substeps import resolve_substeps

DESIGN = Path(fjm_runtime.__file__).parent / "control" / "designed" / "panda_ismc_tau_1000hz_d1.json"
MAX_RMS, MAX_AT_LIMIT, MAX_JITTER, JITTER_JOINTS = 2e-3, 0.02, 3.0, slice(0, 4)   # fjm design's thresholds
OK, SATURATED, NOT_FINITE, BAD = 0, 1, 2, 3                                       # <name>_status


def load_design(noise=None, path=DESIGN):
    """The Panda design of ``path`` (``ControllerDesign``); ``noise``: another sensor preset for its gains."""
    gains = Design.load(path, where=str(path))
    gains = dataclasses.replace(gains, file=str(path))
    if noise is not None:
        gains = dataclasses.replace(gains, sensor=None, noise=noise)
    return design_controller(fjm_runtime.load("panda"), gains)


def impedance_design():
    """The Panda's motor-side impedance as a ``ControllerDesign``: the shipped design for franka_like, 1 kHz,
    delay 1 when there is one, else the law's default gains (the Panda's effort limits) on the shipped
    design's task, franka_like sensing, one sample of delay with prediction, the motor interface."""
    model = fjm_runtime.load("panda")
    shipped = Design.shipped("panda", "impedance", "full", 1000.0, 1)
    if shipped is not None:
        return design_controller(model, shipped)
    task = Design.load(DESIGN, where=str(DESIGN)).task
    spec = {"model": "panda", "kind": "impedance", "sensing": "full", "rate": 1000.0, "delay": 1, "predict": True,
            "noise": "franka_like", "interface": "motor", "reference": dict(task),
            "gains": {"u_max": [float(v) for v in model.limits.effort]}}
    return design_controller(model, Design.from_dict(spec, "impedance design (default gains)"))


def build_library(design, out_dir) -> Path:
    """Export ``design`` into ``out_dir`` and build ``lib<name>.so`` with the library's own Makefile."""
    export_controller(design, out_dir)
    target = f"lib{design.name}.so"
    proc = subprocess.run(["make", "--no-print-directory", "-C", str(out_dir), target], capture_output=True,
                          text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"make -C {out_dir} {target} failed:\n{proc.stderr[-2000:]}")
    return Path(out_dir) / target


class CController:
    """One ``<name>_controller`` struct of the compiled library, through ctypes (double build)."""

    def __init__(self, so_path, design):
        self.lib, self.name = ctypes.CDLL(str(so_path)), design.name
        self.n, self.nm, self.nc = design.layout.n, design.layout.nm, design.cstate.nc
        for fn in ("init", "reset", "step", "get_state", "set_state"):
            getattr(self.lib, f"{self.name}_{fn}").restype = ctypes.c_int
        getattr(self.lib, f"{self.name}_sizeof").restype = ctypes.c_size_t
        self.buf = ctypes.create_string_buffer(int(getattr(self.lib, f"{self.name}_sizeof")()))
        self.u = np.zeros(self.n)
        if self._call("init", None, None) != OK:
            raise RuntimeError(f"{self.name}_init failed")

    def _call(self, fn, *arrays):
        args = [None if a is None else a.ctypes.data_as(ctypes.POINTER(ctypes.c_double)) for a in arrays]
        return getattr(self.lib, f"{self.name}_{fn}")(self.buf, *args)

    def reset(self, m0) -> int:
        return self._call("reset", np.ascontiguousarray(m0, dtype=float))

    def step(self, m, r):
        """``(status, u)`` of one sample: reading ``m`` (nm), reference rows ``r`` (5n)."""
        st = self._call("step", np.ascontiguousarray(m, dtype=float), np.ascontiguousarray(r, dtype=float), self.u)
        return st, self.u.copy()

    def get_state(self):
        """``(c, u_last)``: the controller state (nc) and the last torque (n)."""
        c, u = np.zeros(max(self.nc, 1)), np.zeros(self.n)
        if self._call("get_state", c, u) != OK:
            raise RuntimeError(f"{self.name}_get_state failed")
        return c[:self.nc], u

    def set_state(self, c, u_last) -> int:
        return self._call("set_state", np.ascontiguousarray(c, dtype=float), np.ascontiguousarray(u_last, dtype=float))


def mujoco_plant(out_dir, design, x0, reduced=False):
    """``(MujocoPlant, substeps, true parameters)``: the complete Panda (defaults, N = 100) in MuJoCo, or with
    ``reduced`` the reduced Panda (the design's model at its defaults)."""
    from fjm_runtime.export.bridge import MujocoPlant
    from fjm_runtime.export.mjcf import write_mjcf
    if reduced:
        model, T = design.model, design.layout.T
        p = dict(model.default_params)
        subs = resolve_substeps(None, model, x0, model.params_array(p), T)
        plant = MujocoPlant(model, write_mjcf(model, Path(out_dir) / "panda.xml", p, timestep=T / subs), p)
        plant.set_state(x0)
        return plant, subs, p
    complete = fjm_runtime.load("panda_complete")
    p = dict(complete.default_params)
    T = design.layout.T
    subs = resolve_substeps(None, complete_plant(complete), x0, complete.params_array(p), T)
    path = write_mjcf(complete, Path(out_dir) / "panda_complete.xml", p, complete=True, timestep=T / subs)
    plant = MujocoPlant(complete, path, p)
    plant.set_state(x0)
    return plant, subs, p


def run(design, ctrl, duration, work_dir, record=False, reduced=False):
    """The closed loop: ``ctrl`` (a :class:`CController`) drives MuJoCo's complete Panda for ``duration`` s
    (``reduced``: the reduced Panda, the torque command through the design's interface per MuJoCo step).

    Returns
    -------
    SimpleNamespace
        ``t`` (N+1,), ``x`` (N+1, 4n) fjm's state read from MuJoCo, ``u`` (N+1, n) the library's
        torques (``u[k]`` held over ``[t_k, t_k+1)``; the last row is not applied), ``e1`` (N+1, n),
        ``status`` (N+1,), ``m`` (N+1, nm) the raw readings, ``r`` (N+1, 5n) the reference rows,
        ``noise`` (N+1, nm) the sensor noise in them, ``substeps``, ``u_max``, ``p`` the plant's parameters
        in the reduced model's order; with ``record``: ``c`` (N+1, nc) and ``u_last`` (N+1, n), the
        library's state before each step, and ``offset`` (n) the run's tau_J offset.
    """
    model, L, sensor = design.model, design.layout, design.sensor
    ref, x0 = design.design.reference(model), design.design.start_state(model)
    plant, subs, p_plant = mujoco_plant(work_dir, design, x0, reduced)
    act = None
    if reduced:
        from fjm_runtime.export.bridge import Actuation
        act = Actuation(plant, design.controller, L.T, subs, x0, np.zeros(L.nz), design.interface)
    p = model.params_array({k: p_plant[k] for k in model.param_names})   # the plant's K, for tau_J
    n, steps = L.n, int(round(duration / L.T))
    t = L.T * np.arange(steps + 1)
    R = np.asarray(ref.sample(t), dtype=float).reshape(t.size, 5 * n)
    noise = noise_array(sensor, L.sensing, n, t.size)
    w = np.zeros(L.nw)                                  # only the plant state and the tau_J offset are read
    offset = sensor.offsets(n) * offset_normals(int(sensor.seed), n) if L.offset else np.zeros(n)
    if L.offset:
        w[L.extra_slices()[1]] = offset
    if ctrl.reset(rest_reading(model, L, x0, p)) != OK:
        raise RuntimeError(f"{design.name}_reset failed")
    X, U, M = np.zeros((t.size, L.nx)), np.zeros((t.size, n)), np.zeros((t.size, L.nm))
    S = np.zeros(t.size, dtype=int)
    C, U_last = (np.zeros((t.size, ctrl.nc)), np.zeros((t.size, n))) if record else (None, None)
    for k in range(t.size):
        X[k] = w[:L.nx] = plant.state()
        M[k] = raw_reading(model, L, w, noise[k], p)
        if record:
            C[k], U_last[k] = ctrl.get_state()
        S[k], U[k] = ctrl.step(M[k], R[k])
        if k < steps and act is not None:
            act.run(U[k])                               # the library applies the motor interface's rate limit
        elif k < steps:
            plant.step(U[k], subs)
    e1 = X[:, :n] - R[:, :n]
    return SimpleNamespace(t=t, x=X, u=U, e1=e1, status=S, m=M, r=R, noise=noise, substeps=subs, c=C, reduced=reduced,
                           u_last=U_last, offset=offset, p=p,
                           u_max=np.asarray(design.design.gains["u_max"], dtype=float))


def figures(res) -> dict:
    """The design's figures of merit per joint and whether each holds its threshold."""
    rms, at_limit, jitter = rms_second_half(res), time_at_limit(res), torque_jitter(res)
    finite = bool(np.all(np.isfinite(res.x)) and np.all(np.isfinite(res.u)))
    checks = {"rms": finite and float(np.max(rms)) <= MAX_RMS,
              "at_limit": float(np.max(at_limit)) <= MAX_AT_LIMIT,
              "jitter": finite and float(np.max(jitter[JITTER_JOINTS])) <= MAX_JITTER}
    return {"rms": rms, "at_limit": at_limit, "jitter": jitter, "checks": checks, "holds": all(checks.values())}


def sensor_label(sensor) -> str:
    """The preset a sensor's levels are (a design file stores the levels, not the preset's name)."""
    from fjm_runtime.sim.sensor import PRESETS
    same = lambda a, b: {k: v for k, v in a.as_dict().items() if k != "name"} == \
        {k: v for k, v in b.as_dict().items() if k != "name"}  # noqa: E731
    return next((name for name, make in PRESETS.items() if same(make(sensor.seed), sensor)), sensor.name)


def report(design, res, fig) -> str:
    j = lambda v: int(np.argmax(v)) + 1  # noqa: E731 - the worst joint, 1-based
    rms, lim, jit = fig["rms"], fig["at_limit"], fig["jitter"]
    mark = {True: "holds", False: "FAILS"}
    lines = [f"{design.name} (C library, {sensor_label(design.sensor)} noise, delay {design.layout.delay}, prediction "
             f"{'on' if design.layout.predict else 'off'}) vs MuJoCo's "
             f"{'reduced Panda (' if getattr(res, 'reduced', False) else 'complete Panda (N = 100, '}{res.substeps} RK4 "
             f"steps per sample), {res.t[-1]:g} s",
             "RMS error, second half (rad):  " + " ".join(f"{v:.2e}" for v in rms),
             "time at a torque limit:        " + " ".join(f"{v:.1%}" for v in lim),
             "torque jitter (N m):           " + " ".join(f"{v:.2f}" for v in jit),
             f"worst-joint RMS {np.max(rms):.2e} rad (joint {j(rms)}) <= {MAX_RMS:g}: {mark[fig['checks']['rms']]}",
             f"time at a limit {np.max(lim):.2%} (joint {j(lim)}) <= {MAX_AT_LIMIT:.0%}: "
             f"{mark[fig['checks']['at_limit']]}",
             f"jitter joints 1-4 {np.max(jit[JITTER_JOINTS]):.2f} N m (joint {j(jit[JITTER_JOINTS])}) <= "
             f"{MAX_JITTER:g}: {mark[fig['checks']['jitter']]}",
             f"status: {np.sum(res.status == OK)} ok, {np.sum(res.status == SATURATED)} saturated, "
             f"{np.sum(res.status == NOT_FINITE)} input not finite"]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=10.0, help="simulated seconds (default 10, the design's)")
    ap.add_argument("--gains", type=Path, default=DESIGN, help="a design file of the Panda (default: the shipped "
                    "1 kHz, delay 1, torque-sensed ismc design)")
    ap.add_argument("--noise", default=None, help="sensor preset instead of the design's own (e.g. franka_like)")
    ap.add_argument("--keep", type=Path, default=None, help="export and build here instead of a temp directory")
    ap.add_argument("--law", choices=("design", "impedance"), default="design",
                    help="impedance: the motor-side impedance on MuJoCo's reduced Panda (default: --gains)")
    args = ap.parse_args(argv)
    reduced = args.law == "impedance"
    design = impedance_design() if reduced else load_design(args.noise, args.gains)
    with tempfile.TemporaryDirectory(prefix="fjm-mujoco-c-") as tmp:
        work = args.keep or Path(tmp)
        so = build_library(design, work)
        res = run(design, CController(so, design), args.duration, work, reduced=reduced)
    fig = figures(res)
    print(report(design, res, fig))
    return 0 if fig["holds"] else 1


if __name__ == "__main__":
    sys.exit(main())
