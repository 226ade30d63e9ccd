"""Compiled closed loop: the RK4 + sliding-mode step as C, compiled once and cached.

The step is the same CasADi graph the ``'casadi'`` backend of
:func:`fjm_runtime.sim.simulate.simulate` builds (controller sample with NOMINAL
parameters, zero-order hold, RK4 of the plant with TRUE parameters). Two
compiled forms:

* :func:`closed_loop_runner`: its ``mapaccum`` over ``N`` steps as a CasADi
  Function, code-generated, compiled and loaded with :func:`casadi.external`;
* :func:`closed_loop_library`: the step code-generated with a plain C loop over
  the steps (``ctypes``; the number of steps is a run-time argument, so one
  build serves every duration). ``simulate(..., backend="compiled")`` uses
  this one: it skips CasADi's call and DM-conversion overhead (about 3x faster
  on link1 10 s at 1 kHz).

Compiling and caching: :mod:`fjm_runtime.ccache`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import casadi as ca
import numpy as np

from ..ccache import DEFAULT_FLAGS, compile_function, compile_library, fold_driver, generate_source
from ..sim.sample_step import sample_step_function
from ..sim.step import assemble, build_fused_step, casadi_functions, check_divergence


# -- the closed loop ----------------------------------------------------------

def closed_loop_step(model, controller, dt: float) -> ca.Function:
    """The fused step ``(w, r0, rh, r1, p_true) -> (w_next, [u; s; y_hat])`` (SX)."""
    fns = casadi_functions(model)
    if fns is None or not hasattr(controller, "symbolic_evaluate"):
        raise ValueError("backend = 'compiled': the model exposes no CasADi Functions or the "
                         "controller has no symbolic_evaluate; use backend='python'")
    nz = int(getattr(controller, "n_states", 0))
    return build_fused_step(fns, controller, int(model.nx), int(model.n), nz,
                             len(model.param_names), float(dt))


def closed_loop_runner(model, controller, dt: float, n_steps: int,
                       flags: Sequence[str] = DEFAULT_FLAGS) -> ca.Function:
    """Compiled ``mapaccum`` of :func:`closed_loop_step` over ``n_steps`` steps.

    Signature ``(w0, R0, RH, R1, p_true) -> (W, AUX)`` with ``R*`` of shape
    ``(5n, n_steps)`` (reference at ``t_k``, ``t_k + dt/2``, ``t_k + dt``) and
    ``W`` ``(nx + nz, n_steps)`` the states after each step.
    """
    step = closed_loop_step(model, controller, dt)
    runner = step.mapaccum("fjm_closed_loop", int(n_steps))
    return compile_function(runner, flags)


_LOOP_DRIVER = fold_driver("fjm_closed_loop_step") + r"""
int fjm_run(int n_steps, int nw, int nr, int naux, const double* w0, const double* R0,
            const double* RH, const double* R1, const double* p, double* W, double* AUX) {
  double* acc = (double*)malloc(sizeof(double) * (nw + 1));
  int used = 1, flag;
  memcpy(acc, w0, sizeof(double) * nw);
  flag = fjm_fold(1, n_steps, nw, nr, 0, naux, acc, R0, RH, R1, p, W, AUX, 1, &used);
  free(acc);
  return flag;
}
"""


class CompiledLoop:
    """The closed-loop step compiled with a C loop over steps (``ctypes``; steps chosen per call).

    ``loop(w0, R0, RH, R1, p) -> (W, AUX)``: ``R*`` of shape (N, 5n) row-major
    (reference at ``t_k``, ``t_k + dt/2``, ``t_k + dt``), ``W`` (N, nw) the
    states after each step, ``AUX`` (N, 6n) = ``[u; s; y_hat]`` of each sample.
    """

    def __init__(self, so_path: Path, nw: int, nr: int, naux: int, n_par: int):
        import ctypes
        self.lib = ctypes.CDLL(str(so_path))
        dp = ctypes.POINTER(ctypes.c_double)
        self.lib.fjm_run.argtypes = [ctypes.c_int] * 4 + [dp] * 7
        self.lib.fjm_run.restype = ctypes.c_int
        self.nw, self.nr, self.naux, self.n_par, self.path = nw, nr, naux, n_par, so_path
        self._dp = dp

    def __call__(self, w0, R0, RH, R1, p, out=None):
        w0 = np.ascontiguousarray(w0, dtype=float).reshape(self.nw)
        p = np.ascontiguousarray(p, dtype=float).reshape(self.n_par)
        R0, RH, R1 = (np.ascontiguousarray(a, dtype=float) for a in (R0, RH, R1))
        N = R0.shape[0]
        if any(a.shape != (N, self.nr) for a in (R0, RH, R1)):
            raise ValueError(f"references: expected three arrays of shape (N, {self.nr})")
        W, AUX = out if out is not None else (np.empty((N, self.nw)), np.empty((N, self.naux)))
        ptr = lambda a: a.ctypes.data_as(self._dp)
        if self.lib.fjm_run(N, self.nw, self.nr, self.naux, ptr(w0), ptr(R0), ptr(RH), ptr(R1),
                            ptr(p), ptr(W), ptr(AUX)):
            raise RuntimeError("compiled closed-loop step returned an error flag")
        return W, AUX


def closed_loop_library(model, controller, dt: float,
                        flags: Sequence[str] = DEFAULT_FLAGS) -> CompiledLoop:
    """Compile (once, cached) :func:`closed_loop_step` plus a C loop; any number of steps."""
    step = closed_loop_step(model, controller, dt)
    step = ca.Function("fjm_closed_loop_step", step.mx_in() if step.is_a("MXFunction") else step.sx_in(),
                       step.call(step.mx_in() if step.is_a("MXFunction") else step.sx_in()))
    if step.is_a("MXFunction"):
        step = step.expand()
    source = generate_source(step) + _LOOP_DRIVER
    so = compile_library(source, "fjm_closed_loop", flags)
    return CompiledLoop(so, step.size1_in(0), step.size1_in(1), step.size1_out(1), step.size1_in(4))


def run_compiled(model, controller, reference, p_true, x0, z0, dt, n_steps, max_state):
    """Run the compiled closed loop; returns ``t, X, Z, U, S, Yh, R`` like the other backends."""
    nx, n = int(model.nx), int(model.n)
    loop = closed_loop_library(model, controller, dt)
    t = dt * np.arange(n_steps + 1)
    r_half = reference.sample(0.5 * dt * np.arange(2 * n_steps + 1)).reshape(2 * n_steps + 1, 5 * n)
    R = r_half[0::2].reshape(n_steps + 1, 5, n)
    w0 = np.concatenate([np.asarray(x0, float), np.asarray(z0, float)])
    w_out, a_out = loop(w0, r_half[0:-1:2], r_half[1::2], r_half[2::2], p_true)
    check_divergence(t[1:], w_out, a_out[:, :n], max_state)
    return assemble(controller, t, np.vstack([w0[None], w_out]), a_out, R, nx, n)


# -- the sampled-data loop (the sample step of sim/sample_step.py) -------------------------------

_SAMPLED_DRIVER = r"""
#include <stdlib.h>
int fjm_sampled_run(int n_samples, int nw, int nr, int nm, int naux, const double* w0, const double* R,
                    const double* NOISE, const double* p, double* W, double* AUX) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  fjm_sample_step_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  double* work = (double*)malloc(sizeof(double) * (sz_w + 1));
  casadi_int* iw = (casadi_int*)malloc(sizeof(casadi_int) * (sz_iw + 1));
  const double** arg = (const double**)malloc(sizeof(double*) * (sz_arg + 4));
  double** res = (double**)malloc(sizeof(double*) * (sz_res + 2));
  const double* cur = w0;
  int failed = 0;
  for (int k = 0; k < n_samples; ++k) {
    arg[0] = cur; arg[1] = R + (size_t)k * nr; arg[2] = NOISE + (size_t)k * nm; arg[3] = p;
    res[0] = W + (size_t)k * nw; res[1] = AUX + (size_t)k * naux;
    failed |= fjm_sample_step(arg, res, iw, work, 0);
    cur = W + (size_t)k * nw;
  }
  free(work); free(iw); free(arg); free(res);
  return failed;
}
"""


class SampledLoop:
    """The sample step compiled with a C loop over samples (``ctypes``).

    ``loop(w0, R, NOISE, p) -> (W, AUX)``: ``R`` (N, 5n) and ``NOISE`` (N, nm) one row per
    sample, ``W`` (N, nw) the step state after each sample, ``AUX`` (N, 6n) ``[u; s; y_hat]``.
    """

    def __init__(self, so_path: Path, nw: int, nr: int, nm: int, naux: int, n_par: int):
        import ctypes
        self.lib = ctypes.CDLL(str(so_path))
        dp = ctypes.POINTER(ctypes.c_double)
        self.lib.fjm_sampled_run.argtypes = [ctypes.c_int] * 5 + [dp] * 6
        self.lib.fjm_sampled_run.restype = ctypes.c_int
        self.sizes = (nw, nr, nm, naux, n_par)
        self.path, self._dp = so_path, dp

    def __call__(self, w0, R, NOISE, p):
        nw, nr, nm, naux, n_par = self.sizes
        w0 = np.ascontiguousarray(w0, dtype=float).reshape(nw)
        p = np.ascontiguousarray(p, dtype=float).reshape(n_par)
        R, NOISE = np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(NOISE, dtype=float)
        N = R.shape[0]
        if R.shape != (N, nr) or NOISE.shape != (N, nm):
            raise ValueError(f"R, NOISE with shapes {R.shape}, {NOISE.shape}: expected (N, {nr}) and (N, {nm})")
        W, AUX = np.empty((N, nw)), np.empty((N, naux))
        ptr = lambda a: a.ctypes.data_as(self._dp)  # noqa: E731
        if self.lib.fjm_sampled_run(N, nw, nr, nm, naux, ptr(w0), ptr(R), ptr(NOISE), ptr(p), ptr(W), ptr(AUX)):
            raise RuntimeError("compiled sample step returned an error flag")
        return W, AUX


def sampled_loop_library(model, controller, layout, flags: Sequence[str] = DEFAULT_FLAGS) -> SampledLoop:
    """Compile (once, cached) the sample step of ``layout`` plus a C loop over samples."""
    if casadi_functions(model) is None or not hasattr(controller, "symbolic_evaluate"):
        raise ValueError("backend = 'compiled': the model exposes no CasADi Functions or the "
                         "controller has no symbolic_evaluate; use backend='python'")
    step = sample_step_function(model, controller, layout)
    so = compile_library(generate_source(step) + _SAMPLED_DRIVER, "fjm_sampled_loop", flags)
    return SampledLoop(so, step.size1_in(0), step.size1_in(1), step.size1_in(2), step.size1_out(1),
                       step.size1_in(3))
