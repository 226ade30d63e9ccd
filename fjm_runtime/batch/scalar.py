"""The scalar sampled-data batch loop: the batch sample step folded in C over runs and samples.

:class:`SampledBatchRunner` is the ctypes handle on a step of
:func:`fjm_runtime.batch.sampled.sampled_metric_step` compiled with :data:`SAMPLED_DRIVER`
(scalar, OpenMP across runs when it builds) or with the SIMD driver of
:mod:`fjm_runtime.batch.simd`; the sensor noise is generated in C per run and sample
(``noise.c``, :func:`noise_source`).
"""
from __future__ import annotations

from typing import Optional, Sequence

import casadi as ca
import numpy as np

from ..ccache import CompileError, compile_library, generate_source


def threads_arg(threads: Optional[int]) -> int:
    """``threads`` for the C drivers (validated): 0 = OpenMP's default (``OMP_NUM_THREADS`` or all cores)."""
    if threads is None:
        return 0
    t = int(threads)
    if t < 1:
        raise ValueError(f"threads = {threads!r}: expected None (all cores) or an integer >= 1")
    return t


def noise_source() -> str:
    """The C of the counter-based sensor noise (``noise.c``: ``fjm_splitmix64``, ``fjm_noise_row``)."""
    from importlib import resources
    return resources.files(__package__).joinpath("noise.c").read_text(encoding="utf-8")


#: C of the scalar sampled-data batch ``fjm_sampled_batch``: per run, the noise row of each sample
#: from the run's seed, then the step (``fjm_sampled_step``: acc, r, noise, flags).
SAMPLED_DRIVER = r"""
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif
int fjm_sampled_batch(int n_runs, int n_samples, int nacc, int nr, int nm, int nf, double* acc,
                      const double* R, const double* FL, const double* levels, const long long* chan,
                      const unsigned long long* seeds, int n_threads, int* threads_used) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  fjm_sampled_step_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  int failed = 0, used = 1, nt = 1;
#ifdef _OPENMP
  nt = n_threads > 0 ? n_threads : omp_get_max_threads();
#endif
  (void)nt; (void)n_threads;
  #pragma omp parallel num_threads(nt) if (nt > 1)  /* one thread: no team to wake or to wait for */
  {
#ifdef _OPENMP
    #pragma omp single
    used = omp_get_num_threads();
#endif
    #pragma omp for schedule(dynamic, 1) reduction(|:failed)
    for (int b = 0; b < n_runs; ++b) {
      double* buf = (double*)malloc(sizeof(double) * (2 * nacc + nm + sz_w + 1));
      casadi_int* iw = (casadi_int*)malloc(sizeof(casadi_int) * (sz_iw + 1));
      double *cur = buf, *nxt = buf + nacc, *noise = buf + 2 * nacc, *w = noise + nm;
      memcpy(cur, acc + (size_t)b * nacc, sizeof(double) * nacc);
      uint64_t key = fjm_splitmix64((uint64_t)seeds[b]);
      /* sz_arg, sz_res: a step that calls functions (outlined substeps) passes arg + 4, res + 1 on */
      const double** arg = (const double**)malloc(sizeof(double*) * (sz_arg > 4 ? sz_arg : 4));
      double** res = (double**)malloc(sizeof(double*) * (sz_res > 1 ? sz_res : 1));
      for (int k = 0; k < n_samples; ++k) {
        fjm_noise_row(key, (uint64_t)k, nm, levels, chan, noise);
        arg[0] = cur; arg[1] = R + (size_t)k * nr; arg[2] = noise; arg[3] = FL + (size_t)k * nf;
        res[0] = nxt;
        failed |= fjm_sampled_step(arg, res, iw, w, 0);
        double* t = cur; cur = nxt; nxt = t;
      }
      memcpy(acc + (size_t)b * nacc, cur, sizeof(double) * nacc);
      free(buf); free(iw); free((void*)arg); free(res);
    }
  }
  *threads_used = used;
  return failed;
}
"""


class SampledBatchRunner:
    """ctypes handle on a compiled sampled-data batch (scalar ``fjm_sampled_batch`` or SIMD
    ``fjm_sampled_batch_soa``); runs packed ``lanes`` at a time on the SIMD path.

    Attributes
    ----------
    path : Path
    lanes : int
    isa : str or None
    openmp : bool
    """

    def __init__(self, so_path, nacc: int, nr: int, nm: int, nf: int, lanes: int = 1, isa=None,
                 openmp: bool = False):
        import ctypes
        self.lib = ctypes.CDLL(str(so_path))
        entry = "fjm_sampled_batch" if lanes == 1 else "fjm_sampled_batch_soa"
        fn = getattr(self.lib, entry)
        dp = ctypes.POINTER(ctypes.c_double)
        fn.argtypes = ([ctypes.c_int] * 6 + [dp] * 4 + [ctypes.POINTER(ctypes.c_longlong),
                                                        ctypes.POINTER(ctypes.c_ulonglong),
                                                        ctypes.c_int, ctypes.POINTER(ctypes.c_int)])
        fn.restype = ctypes.c_int
        self._fn = fn
        self.path, self.nacc, self.nr, self.nm, self.nf = so_path, nacc, nr, nm, nf
        self.lanes, self.isa, self.openmp = int(lanes), isa, bool(openmp)

    @property
    def path_name(self) -> str:
        return "scalar" if self.lanes == 1 else f"simd-{self.isa}"

    def run(self, ACC0, R, FL, levels, channels, seeds, threads: Optional[int] = None):
        """``ACC0`` (B, nacc), ``R`` (S, nr), ``FL`` (S, nf), ``levels``/``channels`` (nm,),
        ``seeds`` (B,) uint64. Returns ``(acc (B, nacc), threads_used)``."""
        import ctypes
        ACC0 = np.asarray(ACC0, dtype=float)
        B, L = ACC0.shape[0], self.lanes
        seeds = np.asarray(seeds, dtype=np.uint64)
        if L > 1:
            G = -(-B // L)
            pad = np.vstack([ACC0, np.repeat(ACC0[-1:], G * L - B, axis=0)])
            acc = np.ascontiguousarray(pad.reshape(G, L, self.nacc).transpose(0, 2, 1))
            seeds = np.concatenate([seeds, np.repeat(seeds[-1:], G * L - B)])
            count = G
        else:
            acc, count = np.ascontiguousarray(ACC0).copy(), B
        R = np.ascontiguousarray(R, dtype=float)
        FL = np.ascontiguousarray(FL, dtype=float)
        lev = np.ascontiguousarray(levels, dtype=float)
        chan = np.ascontiguousarray(channels, dtype=np.int64)
        seeds = np.ascontiguousarray(seeds, dtype=np.uint64)
        dptr = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # noqa: E731
        used = ctypes.c_int(0)
        flag = self._fn(count, R.shape[0], self.nacc, self.nr, self.nm, self.nf, dptr(acc), dptr(R), dptr(FL),
                        dptr(lev), chan.ctypes.data_as(ctypes.POINTER(ctypes.c_longlong)),
                        seeds.ctypes.data_as(ctypes.POINTER(ctypes.c_ulonglong)),
                        threads_arg(threads), ctypes.byref(used))
        if flag:
            raise RuntimeError("compiled sampled batch step returned an error flag")
        if L > 1:
            acc = acc.transpose(0, 2, 1).reshape(-1, self.nacc)[:B].copy()
        return acc, int(used.value)


def sampled_scalar_runner(step: ca.Function, nm: int, flags: Sequence[str], parallel: bool) -> SampledBatchRunner:
    """Compile (cached) the sampled metric step with :data:`SAMPLED_DRIVER` (OpenMP when it builds)."""
    nacc, nr, nf = step.size1_in(0), step.size1_in(1), step.size1_in(3)
    source = generate_source(step) + noise_source() + SAMPLED_DRIVER
    if parallel:
        try:
            so = compile_library(source, "fjm_sampled_batch", tuple(flags) + ("-fopenmp",))
            return SampledBatchRunner(so, nacc, nr, nm, nf, openmp=True)
        except CompileError:
            pass
    return SampledBatchRunner(compile_library(source, "fjm_sampled_batch", flags), nacc, nr, nm, nf)
