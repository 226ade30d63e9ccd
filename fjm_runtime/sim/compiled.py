"""The compiled sampled-data loop: THE sample step (:mod:`fjm_runtime.sim.sample_step`) in C, built once and cached.

Two compiled forms of the step ``fjm_sample_step(w, r, noise, p) -> (w_next, aux)``:

* :func:`sampled_loop_library`: the step code-generated with a plain C loop over the samples
  (``ctypes``; the number of samples is a run-time argument, so one build serves every
  duration). ``simulate(..., backend="compiled")`` uses this one (:mod:`fjm_runtime.sim.loops`);
* :func:`sampled_loop_runner`: the step's ``mapaccum`` over ``N`` samples as a CasADi Function,
  code-generated, compiled and loaded with :func:`casadi.external` (CasADi's call and
  DM conversion on top; the benchmark reports it for context).

Compiling and caching: :mod:`fjm_runtime.ccache`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import casadi as ca
import numpy as np

from ..ccache import DEFAULT_FLAGS, compile_function, compile_library, generate_source
from ..sim.sample_step import sample_step_function
from ..sim.step import casadi_functions

__all__ = ["SampledLoop", "sampled_loop_library", "sampled_loop_runner"]


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

    def __call__(self, w0, R, NOISE, p, out=None):
        """``(W, AUX)`` for ``N = R.shape[0]`` samples; ``out``: preallocated ``(W, AUX)`` to fill."""
        nw, nr, nm, naux, n_par = self.sizes
        w0 = np.ascontiguousarray(w0, dtype=float).reshape(nw)
        p = np.ascontiguousarray(p, dtype=float).reshape(n_par)
        R, NOISE = np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(NOISE, dtype=float)
        N = R.shape[0]
        if R.shape != (N, nr) or NOISE.shape != (N, nm):
            raise ValueError(f"R, NOISE with shapes {R.shape}, {NOISE.shape}: expected (N, {nr}) and (N, {nm})")
        W, AUX = out if out is not None else (np.empty((N, nw)), np.empty((N, naux)))
        if W.shape != (N, nw) or AUX.shape != (N, naux) or not (W.flags.c_contiguous and AUX.flags.c_contiguous):
            raise ValueError(f"out with shapes {W.shape}, {AUX.shape}: expected C-contiguous "
                             f"({N}, {nw}) and ({N}, {naux})")
        ptr = lambda a: a.ctypes.data_as(self._dp)  # noqa: E731
        if self.lib.fjm_sampled_run(N, nw, nr, nm, naux, ptr(w0), ptr(R), ptr(NOISE), ptr(p), ptr(W), ptr(AUX)):
            raise RuntimeError("compiled sample step returned an error flag")
        return W, AUX


def _step(model, controller, layout) -> ca.Function:
    """The sample step as ONE SX Function (each RK4 substep a call of one outlined Function), else MX.

    Expanded, the generated C is straight-line code the compiler optimizes as a whole (link1,
    one substep: 3.3x faster than the MX graph's calls of ``f``, ``g`` and the law's Functions);
    outlined substeps keep its size independent of the number of substeps.
    """
    if casadi_functions(model) is None or not hasattr(controller, "symbolic_evaluate"):
        raise ValueError("backend = 'compiled': the model exposes no CasADi Functions or the "
                         "controller has no symbolic_evaluate; use backend='python'")
    step = sample_step_function(model, controller, layout, outline=True)
    try:
        return step.expand()
    except Exception:  # noqa: BLE001 - a graph that cannot be expanded (e.g. an external call) stays MX
        return step


def sampled_loop_library(model, controller, layout, flags: Sequence[str] = DEFAULT_FLAGS) -> SampledLoop:
    """Compile (once, cached) the sample step of ``layout`` plus a C loop over samples."""
    step = _step(model, controller, layout)
    so = compile_library(generate_source(step) + _SAMPLED_DRIVER, "fjm_sampled_loop", flags)
    return SampledLoop(so, step.size1_in(0), step.size1_in(1), step.size1_in(2), step.size1_out(1),
                       step.size1_in(3))


def sampled_loop_runner(model, controller, layout, n_samples: int,
                        flags: Sequence[str] = DEFAULT_FLAGS) -> ca.Function:
    """The sample step's ``mapaccum`` over ``n_samples`` samples, compiled (cached) and loaded back.

    Signature ``(w0, R, NOISE, p_true) -> (W, AUX)`` with ``R`` (5n, N) and ``NOISE`` (nm, N) one
    column per sample, ``W`` (nw, N) the step state after each sample and ``AUX`` (6n, N).
    """
    step = _step(model, controller, layout)
    return compile_function(step.mapaccum("fjm_sampled_mapaccum", int(n_samples)), flags)
