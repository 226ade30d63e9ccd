"""Compiled closed loop: the RK4 + sliding-mode step as C, compiled once and cached.

The step is the same CasADi graph the ``'casadi'`` backend of
:func:`fjm_runtime.simulate.simulate` builds (controller sample with NOMINAL
parameters, zero-order hold, RK4 of the plant with TRUE parameters). Two
compiled forms:

* :func:`closed_loop_runner`: its ``mapaccum`` over ``N`` steps as a CasADi
  Function, code-generated, compiled and loaded with :func:`casadi.external`;
* :func:`closed_loop_library`: the step code-generated with a plain C loop over
  the steps (``ctypes``; the number of steps is a run-time argument, so one
  build serves every duration). ``simulate(..., backend="compiled")`` uses
  this one: it skips CasADi's call and DM-conversion overhead (about 3x faster
  on link1 10 s at 1 kHz).

Cache: ``$FJM_CACHE`` or ``$XDG_CACHE_HOME/fjm`` (default ``~/.cache/fjm``).
An entry is ``<key>.so`` plus ``<key>.json`` where ``key = sha256(C source,
compiler, flags)``. The JSON records the SHA-256 of the shared object; an entry
whose record is missing, unreadable, for another key, or whose bytes do not
match, is rebuilt, never loaded. New entries are written to a temporary file
and renamed into place (never overwritten in place), so concurrent processes
and already-loaded libraries are safe.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path
from typing import Optional, Sequence, Tuple

import casadi as ca
import numpy as np

from ..sim.step import assemble, build_fused_step, casadi_functions, check_divergence

#: Default compiler flags (also part of the cache key).
DEFAULT_FLAGS: Tuple[str, ...] = ("-O2", "-fPIC", "-shared")

_memo: dict = {}
_lock = threading.Lock()


class CompileError(RuntimeError):
    """The C compiler is missing or failed."""


def cache_dir() -> Path:
    """The compiled-code cache directory (created on demand)."""
    env = os.environ.get("FJM_CACHE")
    if env:
        root = Path(env)
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        root = Path(base) / "fjm"
    root.mkdir(parents=True, exist_ok=True)
    return root


def _compiler() -> str:
    exe = os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc")
    if not exe:
        raise CompileError("no C compiler found (looked for $CC, gcc, cc); install gcc or set CC")
    return exe


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def generate_source(fn: ca.Function) -> str:
    """C source of ``fn`` (CasADi code generator, same options as ``make derive``)."""
    with tempfile.TemporaryDirectory(prefix="fjm-cg-") as tmp:
        cg = ca.CodeGenerator(f"{fn.name()}.c", {"with_header": False})
        cg.add(fn)
        path = cg.generate(tmp + os.sep)
        return Path(path).read_text()


def cache_key(source: str, flags: Sequence[str], compiler: Optional[str] = None) -> str:
    """``sha256(source, compiler, flags)`` as hex."""
    h = hashlib.sha256()
    h.update(source.encode())
    h.update(b"\0" + (compiler or _compiler()).encode())
    for f in flags:
        h.update(b"\0" + f.encode())
    return h.hexdigest()


def _entry_valid(so: Path, meta: Path, key: str) -> bool:
    try:
        record = json.loads(meta.read_text())
        return (record.get("key") == key and so.is_file()
                and record.get("so_sha256") == _sha256_file(so))
    except (OSError, ValueError, AttributeError):
        return False


def _build(source: str, key: str, flags: Sequence[str], root: Path, name: str) -> Path:
    so, meta = root / f"{key}.so", root / f"{key}.json"
    with tempfile.TemporaryDirectory(prefix="fjm-build-", dir=root) as tmp:
        src = Path(tmp) / f"{name}.c"
        src.write_text(source)
        out = Path(tmp) / f"{key}.so"
        cmd = [_compiler(), *flags, str(src), "-o", str(out), "-lm"]
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if proc.returncode != 0:
            raise CompileError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-4000:]}")
        digest = _sha256_file(out)
        tmp_meta = Path(tmp) / f"{key}.json"
        tmp_meta.write_text(json.dumps({"key": key, "so_sha256": digest, "function": name,
                                        "flags": list(flags), "compiler": _compiler()}, indent=1))
        os.replace(out, so)          # library first, then the record that vouches for it
        os.replace(tmp_meta, meta)
    return so


def compile_library(source: str, name: str, flags: Sequence[str] = DEFAULT_FLAGS,
                    cache: Optional[Path] = None) -> Path:
    """Compile C ``source`` to a shared object in the cache (or reuse a verified entry).

    Returns the path of the ``.so``; the caller loads it (``ctypes`` or
    ``casadi.external``). Same cache rules as :func:`compile_function`.
    """
    key = cache_key(source, flags)
    root = Path(cache) if cache is not None else cache_dir()
    root.mkdir(parents=True, exist_ok=True)
    with _lock:
        so, meta = root / f"{key}.so", root / f"{key}.json"
        if _entry_valid(so, meta, key):
            return so
        return _build(source, key, flags, root, name)


def compile_function(fn: ca.Function, flags: Sequence[str] = DEFAULT_FLAGS,
                     cache: Optional[Path] = None) -> ca.Function:
    """Code-generate ``fn``, compile it (or reuse a verified cache entry), load it.

    Parameters
    ----------
    fn : casadi.Function
        Any code-generatable Function (SX, or MX of SX/maps).
    flags : sequence of str
        Compiler flags; must produce a shared object (default ``-O2 -fPIC -shared``).
    cache : Path, optional
        Cache directory (default :func:`cache_dir`).

    Returns
    -------
    casadi.Function
        ``casadi.external(fn.name(), <cached .so>)``, same signature as ``fn``.
    """
    source = generate_source(fn)
    key = cache_key(source, flags)
    root = Path(cache) if cache is not None else cache_dir()
    root.mkdir(parents=True, exist_ok=True)
    memo_key = (str(root), key)
    with _lock:
        hit = _memo.get(memo_key)
        if hit is not None:
            return hit
        so, meta = root / f"{key}.so", root / f"{key}.json"
        ext = None
        if _entry_valid(so, meta, key):
            try:
                ext = ca.external(fn.name(), str(so))
            except RuntimeError:
                ext = None
        if ext is None:
            so = _build(source, key, flags, root, fn.name())
            ext = ca.external(fn.name(), str(so))
        _memo[memo_key] = ext
        return ext


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


_FOLD_DRIVER = r"""
/* fjm driver: for each run, fold FJM_STEP over the samples (runs spread over OpenMP threads when
 * built with -fopenmp); with W (AUX) given, the state (second output) after every step is stored
 * row by row, else only the final state is written back into acc. E: 5th input, stride ne (0: constant). */
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif
static int fjm_fold(int n_runs, int n_samples, int nw, int nr, int ne, int naux, double* acc,
                    const double* R0, const double* RH, const double* R1, const double* E,
                    double* W, double* AUX, int n_threads, int* threads_used) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  FJM_STEP_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
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
    #pragma omp for schedule(dynamic, 4) reduction(|:failed)
    for (int b = 0; b < n_runs; ++b) {
      double* buf = (double*)malloc(sizeof(double) * (2 * nw + sz_w + 1));
      casadi_int* iw = (casadi_int*)malloc(sizeof(casadi_int) * (sz_iw + 1));
      double *a = buf, *a2 = buf + nw, *w = buf + 2 * nw;
      memcpy(a, acc + (size_t)b * nw, sizeof(double) * nw);
      const double* cur = a;
      const double* arg[8];
      double* res[4];
      for (int k = 0; k < n_samples; ++k) {
        size_t row = (size_t)b * n_samples + k;
        double* dst = W ? W + row * nw : (cur == a ? a2 : a);
        arg[0] = cur; arg[1] = R0 + (size_t)k * nr; arg[2] = RH + (size_t)k * nr;
        arg[3] = R1 + (size_t)k * nr; arg[4] = E + (size_t)k * ne;
        res[0] = dst; res[1] = AUX ? AUX + row * naux : 0;
        failed |= FJM_STEP(arg, res, iw, w, 0);
        cur = dst;
      }
      memcpy(acc + (size_t)b * nw, cur, sizeof(double) * nw);
      free(buf); free(iw);
    }
  }
  *threads_used = used;
  return failed;
}
"""


def fold_driver(step_name: str) -> str:
    """C of the one driver loop ``fjm_fold`` over runs and samples, calling the step ``step_name``.

    Used by the single-run compiled loop (``fjm_run``: one run, every state stored) and by
    the scalar batch (``fjm_batch`` in :mod:`fjm_runtime.batch`: many runs, final
    accumulators only).
    """
    return _FOLD_DRIVER.replace("FJM_STEP", step_name)


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
