"""The scalar batch loop: the closed-loop step with running metrics, folded in C over runs and samples.

:func:`metric_step` is the one sample of a run as a CasADi Function of an accumulator
(state, running sums of the metrics of :func:`fjm_runtime.sim.metrics.metrics_from_sums`,
the TRUE parameters); :class:`BatchRunner` is the ctypes handle on it compiled with
the fold driver of :mod:`fjm_runtime.ccache` (OpenMP across runs when it builds).
The SIMD form of the same step is :mod:`fjm_runtime.batch.simd`.
"""
from __future__ import annotations

from typing import Optional, Sequence

import casadi as ca
import numpy as np

from ..ccache import DEFAULT_FLAGS, CompileError, compile_library, fold_driver, generate_source
from ..sim.step import casadi_functions, symbolic_closed_loop_rk4


def metric_step(model, controller, dt: float, max_state: float) -> ca.Function:
    """``(acc, r0, rh, r1, flags) -> acc_next`` for one sample (SX).

    ``acc = [w; u_prev; sum_e2; sum_e2_half; max_u; last_outside_k; tv; first_bad_k; p]``
    (the TRUE parameters ``p`` ride along unchanged, so a fold maps only the references);
    ``flags = [in_second_half, k, is_first, is_last]``.
    """
    fns = casadi_functions(model)
    if fns is None or not hasattr(controller, "symbolic_evaluate"):
        raise ValueError("simulate_batch: needs a model with CasADi Functions and a controller "
                         "with symbolic_evaluate")
    n, nx = int(model.n), int(model.nx)
    nz = int(getattr(controller, "n_states", 0))
    nw = nx + nz
    n_par = len(model.param_names)
    acc = ca.SX.sym("acc", nw + n + 6 + n_par)
    r0, rh, r1 = (ca.SX.sym(nm, 5 * n) for nm in ("r0", "rh", "r1"))
    fl = ca.SX.sym("flags", 4)
    p = acc[nw + n + 6:]
    w, u_prev = acc[:nw], acc[nw:nw + n]
    sum_e2, sum_e2_half, max_u, last_out, tv, first_bad = (acc[nw + n + i] for i in range(6))
    half, k, first, last = fl[0], fl[1], fl[2], fl[3]
    x = w[:nx]
    w_step, out = symbolic_closed_loop_rk4(fns, controller, w, r0, rh, r1, p, nx, n, dt)
    u, s = out["u"], out["s"]
    w_next = ca.if_else(last, w, w_step)
    e1 = x[:n] - r0[:n]
    e2 = ca.sumsqr(e1)
    delta = ca.DM(np.asarray(getattr(controller, "delta", np.full(n, np.inf)), dtype=float))
    outside = ca.mmax(ca.fabs(s) - delta) > 0
    absw = ca.fabs(w_next)
    ok = (ca.mmax(absw) <= max_state) * (ca.sum1(absw) <= 1e308)  # NaN compares false
    acc_next = ca.vertcat(
        w_next, u,
        sum_e2 + e2, sum_e2_half + half * e2,
        ca.fmax(max_u, ca.mmax(ca.fabs(u))),
        ca.if_else(outside, k, last_out),
        tv + (1 - first) * ca.sum1(ca.fabs(u - u_prev)),
        ca.if_else((1 - ok) * (first_bad < 0) * (1 - last), k + 1, first_bad),
        p,
    )
    # cse: T and alpha share sin(q), cos(q) etc. once the model Functions are inlined
    return ca.Function("fjm_metric_step", [acc, r0, rh, r1, fl], [ca.cse(acc_next)])


#: C of the scalar batch entry ``fjm_batch`` (the fold driver over runs and samples, final accumulators only).
DRIVER = fold_driver("fjm_metric_step") + r"""
int fjm_batch(int n_runs, int n_samples, int nacc, int nr, double* acc,
              const double* R0, const double* RH, const double* R1, const double* FL,
              int n_threads, int* threads_used) {
  return fjm_fold(n_runs, n_samples, nacc, nr, 4, 0, acc, R0, RH, R1, FL, 0, 0, n_threads, threads_used);
}
"""


def threads_arg(threads: Optional[int]) -> int:
    """``threads`` for the C drivers (validated): 0 = OpenMP's default (``OMP_NUM_THREADS`` or all cores)."""
    if threads is None:
        return 0
    t = int(threads)
    if t < 1:
        raise ValueError(f"threads = {threads!r}: expected None (all cores) or an integer >= 1")
    return t


class BatchRunner:
    """ctypes handle on the compiled batch loop (step + driver, cached by source hash).

    Attributes
    ----------
    path : Path
        The shared object.
    lanes : int
        Runs per statement (1: scalar loop).
    openmp : bool
        Built with ``-fopenmp`` (runs spread over threads).
    """

    lanes = 1
    isa = None
    _entry = "fjm_batch"

    def __init__(self, so_path, nacc: int, nr: int, openmp: bool = False):
        import ctypes
        self.lib = ctypes.CDLL(str(so_path))
        fn = getattr(self.lib, self._entry)
        dp = ctypes.POINTER(ctypes.c_double)
        fn.argtypes = [ctypes.c_int] * 4 + [dp] * 5 + [ctypes.c_int, ctypes.POINTER(ctypes.c_int)]
        fn.restype = ctypes.c_int
        self._fn = fn
        self.nacc, self.nr, self.path, self.openmp = nacc, nr, so_path, bool(openmp)

    @property
    def path_name(self) -> str:
        """The ``BatchResult.info["path"]`` of this runner (one of :data:`PATHS`)."""
        return "scalar"

    def _pack(self, ACC0):
        return np.ascontiguousarray(ACC0, dtype=float).copy(), ACC0.shape[0]

    def _unpack(self, acc, B):
        return acc

    def run(self, ACC0, R0, RH, R1, FL, threads: Optional[int] = None):
        """``ACC0`` (B, nacc); ``R*`` (S, 5n) and ``FL`` (S, 4) row-major.

        Returns ``(acc, threads_used)`` with ``acc`` of shape (B, nacc).
        """
        import ctypes
        ACC0 = np.asarray(ACC0, dtype=float)
        if ACC0.ndim != 2 or ACC0.shape[1] != self.nacc:
            raise ValueError("BatchRunner: inconsistent argument shapes")
        arrs = [np.ascontiguousarray(a, dtype=float) for a in (R0, RH, R1, FL)]
        S = arrs[0].shape[0]
        if any(a.shape[0] != S for a in arrs):
            raise ValueError("BatchRunner: inconsistent argument shapes")
        acc, count = self._pack(ACC0)
        ptr = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # noqa: E731
        used = ctypes.c_int(0)
        flag = self._fn(count, S, self.nacc, self.nr, ptr(acc), *map(ptr, arrs),
                        threads_arg(threads), ctypes.byref(used))
        if flag:
            raise RuntimeError("compiled batch step returned an error flag")
        return self._unpack(acc, ACC0.shape[0]), int(used.value)

    def __call__(self, ACC0, R0, RH, R1, FL, threads: Optional[int] = None) -> np.ndarray:
        """:meth:`run` without the thread count: the final accumulators (B, nacc)."""
        return self.run(ACC0, R0, RH, R1, FL, threads)[0]


def scalar_runner(step: ca.Function, flags: Sequence[str], parallel: bool) -> BatchRunner:
    """Compile (cached) ``step`` (a :func:`metric_step`) with the scalar driver; OpenMP when ``parallel`` builds."""
    nacc, nr = step.size1_in(0), step.size1_in(1)
    source = generate_source(step) + DRIVER
    if parallel:
        try:
            so = compile_library(source, "fjm_batch", tuple(flags) + ("-fopenmp",))
            return BatchRunner(so, nacc, nr, openmp=True)
        except CompileError:
            pass
    return BatchRunner(compile_library(source, "fjm_batch", flags), nacc, nr)


def batch_runner(model, controller, dt: float, max_state: float = 1e6,
                 flags: Sequence[str] = DEFAULT_FLAGS, parallel: bool = True) -> BatchRunner:
    """Compile (once, cached) the metric step plus a scalar C loop over runs and samples.

    The number of runs and steps is a run-time argument: one build serves
    every batch size and duration. Runs are spread over cores with OpenMP
    when ``parallel`` and ``-fopenmp`` works (falls back to serial).
    """
    return scalar_runner(metric_step(model, controller, float(dt), float(max_state)), flags, parallel)


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
  #pragma omp parallel num_threads(nt)
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
