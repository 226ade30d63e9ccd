"""An exported controller library next to the simulator's run of its design (tests of ``fjm export controller``).

:class:`CController` drives one struct of a compiled library through ctypes; :class:`Run` is the simulator's
run of a design with the raw reading of every sample; :func:`per_sample` and :func:`free_running` feed the
library those readings; :func:`relative` is the comparison measure.
"""
from __future__ import annotations

import ctypes
import json

import numpy as np

import fjm_runtime
from fjm_runtime.ccache import compile_library
from fjm_runtime.control.design import Design
from fjm_runtime.export.controller import amalgamation, design_controller, export_controller
from fjm_runtime.export.controller_step import raw_reading, rest_reading
from fjm_runtime.sim.sensor import noise_array

#: The gains file of a small design: link1, integral SMC on torque sensing at 1 kHz, one sample of delay
#: with prediction, the franka_like sensor.
LINK1_TORQUE_DESIGN = {"model": "link1", "kind": "ismc", "sensing": "torque", "rate": 1000.0, "delay": 1,
                       "predict": True, "noise": "franka_like",
                       "gains": {"lam": 10.0, "k_s": 20.0, "delta": 20.0, "u_max": 25.0}}

STRICT = ("-O2", "-fPIC", "-shared", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")
OK, SATURATED, NOT_FINITE, BAD = 0, 1, 2, 3


class CController:
    """One controller struct of an exported library, driven through ctypes (double or float)."""

    def __init__(self, lib, name, design, real):
        self.lib, self.name, self.real = lib, name, real
        L = design.layout
        self.n, self.nm = L.n, L.nm
        ptr = ctypes.POINTER(ctypes.c_float if real == "float" else ctypes.c_double)
        self.nc = design.cstate.nc
        for fn in ("init", "reset", "step", "set_state", "get_state"):
            lib[f"{name}_{fn}"].restype = ctypes.c_int
        lib[f"{name}_sizeof"].restype = ctypes.c_size_t
        self.buf = ctypes.create_string_buffer(int(lib[f"{name}_sizeof"]()))
        self._ptr, self.dtype = ptr, np.float32 if real == "float" else np.float64
        assert lib[f"{name}_init"](self.buf, None, None) == OK

    def _p(self, v):
        a = np.ascontiguousarray(v, dtype=self.dtype)
        return a, a.ctypes.data_as(self._ptr)

    def reset(self, m0):
        m0, p0 = self._p(m0)
        return self.lib[f"{self.name}_reset"](self.buf, p0)

    def set_state(self, c, u_last):
        (c, pc), (u, pu) = self._p(c), self._p(u_last)
        return self.lib[f"{self.name}_set_state"](self.buf, pc, pu)

    def get_state(self):
        (c, pc) = self._p(np.zeros(max(self.nc, 1)))
        assert self.lib[f"{self.name}_get_state"](self.buf, pc, None) == OK
        return c[:self.nc].astype(float)

    def step(self, m, r):
        (m, pm), (r, pr), (u, pu) = self._p(m), self._p(r), self._p(np.zeros(self.n))
        st = self.lib[f"{self.name}_step"](self.buf, pm, pr, pu)
        return st, u.astype(float)


_LIBS: dict = {}


def library(design, tmp_factory, real="double"):
    """The exported library of ``design`` compiled (strict flags, through the C cache) and loaded."""
    key = (design.name, json.dumps(design.design.as_dict(), sort_keys=True, default=str), real)
    if key not in _LIBS:
        out = tmp_factory.mktemp(design.name)
        export_controller(design, out)
        so = compile_library(amalgamation(out, design.name, real), f"{design.name}_controller_{real}", STRICT)
        _LIBS[key] = ctypes.CDLL(str(so))
    return CController(_LIBS[key], design.name + ("_float" if real == "float" else ""), design, real)


class Run:
    """The simulator's run of a design (true plant = nominal): the sample step folded by the casadi
    runner :func:`fjm_runtime.simulate` uses, so its step states ``W`` are at hand.

    ``W`` (N+1, nw) step states, ``U`` (N+1, n) applied torques (aux), ``R`` (N+1, 5n) reference rows,
    ``M`` (N+1, nm) the raw reading of every sample as the step made it, ``C`` (N+1, nc) the
    controller states, ``m0`` the rest reading, ``u0`` the torque holding the rest state.
    """

    def __init__(self, design, duration, reference=None, x0=None):
        from fjm_runtime.sim.loops import run_casadi
        from fjm_runtime.sim.sample_step import initial_step_state
        model, L, sensor, ctrl = design.model, design.layout, design.sensor, design.controller
        if reference is None:
            reference, x0 = design.design.reference(model), design.design.start_state(model)
        p = np.asarray(ctrl.p_nom, dtype=float)
        t = L.T * np.arange(int(round(duration / L.T)) + 1)
        if x0 is None:
            q0 = np.asarray(reference(0.0))[0]
            x0 = np.concatenate([q0, np.zeros(L.n), q0, np.zeros(L.n)])
        w0 = initial_step_state(model, L, x0, np.zeros(L.nz), p, seed=int(sensor.seed), sensor=sensor,
                                controller=ctrl)
        self.R = np.asarray(reference.sample(t), dtype=float).reshape(t.size, 5 * L.n)
        NOISE = noise_array(sensor, L.sensing, L.n, t.size)
        self.W, AUX = run_casadi(model, ctrl, L, p, w0, t, self.R, NOISE, None, 1e6)
        self.U = AUX[:, :L.n]
        self.M = np.stack([raw_reading(model, L, self.W[k], NOISE[k], p) for k in range(t.size)])
        self.C = design.cstate.from_step_state(self.W)
        self.m0 = rest_reading(model, L, x0, p)
        self.u0 = self.C[0][design.cstate.split(np.arange(design.cstate.nc))["u_buf"]][:L.n] \
            if L.delay else None


def free_running(ctrl, run, samples=None):
    """The library from ``reset(m0)`` on the run's readings: torques (k, n) and statuses."""
    k_end = run.M.shape[0] if samples is None else samples
    assert ctrl.reset(run.m0) == OK
    U, S = np.empty((k_end, ctrl.n)), np.empty(k_end, dtype=int)
    for k in range(k_end):
        S[k], U[k] = ctrl.step(run.M[k], run.R[k])
    return U, S


def per_sample(ctrl, run):
    """The library's torque at every sample, and its next controller state, from the SIMULATOR's
    controller state at that sample: ``(U, S, C_next)``."""
    U, S = np.empty_like(run.U), np.empty(run.U.shape[0], dtype=int)
    C_next = np.empty_like(run.C)
    for k in range(run.M.shape[0]):
        assert ctrl.set_state(run.C[k], run.U[k - 1] if k else run.U[0]) == OK
        S[k], U[k] = ctrl.step(run.M[k], run.R[k])
        C_next[k] = ctrl.get_state()
    return U, S, C_next


def relative(U, U_ref):
    """Per joint: the largest deviation over the run / that joint's largest torque; the worst joint."""
    scale = np.maximum(np.max(np.abs(U_ref), axis=0), 1e-300)
    return float(np.max(np.max(np.abs(U - U_ref), axis=0) / scale))


def make_design(model, kind, sensing, noise, delay=1, u_max=None, predict=None, interface=None, **gains):
    """A design of ``model`` at 1 kHz (prediction on when delayed, unless ``predict`` says otherwise; ``interface``
    a preset name or a table of CommandInterface fields, default motor)."""
    predict = delay > 0 if predict is None else predict
    spec = {"model": model, "kind": kind, "sensing": sensing, "rate": 1000.0, "delay": delay, "predict": predict,
            "noise": noise, "interface": interface, "gains": {"lam": 20.0, "k_s": 200.0, "delta": 5.0, **gains}}
    if u_max is not None:
        spec["gains"]["u_max"] = u_max
    return design_controller(fjm_runtime.load(model), Design.from_dict(spec))


def sine(design, amplitude=0.5, omega=2.0):
    from fjm_runtime.control.references import make_reference
    return make_reference("sine", design.layout.n, amplitude=amplitude, omega=omega)


#: Samples of the free-running comparison (from reset): the predictor and the law in replay, without
#: the plant, amplify a rounding difference by up to ~1.26 a sample (the Panda design), so only the
#: first samples of a free-running replay can agree to 1e-12; every sample is compared from the
#: simulator's own controller state (:func:`per_sample`).
FREE_SAMPLES = 10
