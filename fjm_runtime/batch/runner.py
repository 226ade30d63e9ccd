"""Batch closed-loop runs: many TRUE plants, one controller, one compiled call.

:func:`simulate_batch` folds the closed-loop step of :mod:`fjm_runtime.compiled`
over all samples while accumulating the per-run metrics of
:func:`fjm_runtime.simulate.compute_metrics` (so no trajectory is stored), maps
that over the runs (OpenMP when the compiler supports it) and compiles the
whole thing once (cached like the single-run backend).

Which code ran is recorded in :attr:`BatchResult.info` (``info["path"]`` is one
of :data:`PATHS`); a requested SIMD form that cannot be used falls back to the
scalar loop only with a :class:`SimdFallbackWarning` naming the reason.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence

import casadi as ca
import numpy as np

from ..ccache import DEFAULT_FLAGS, CompileError, compile_library, fold_driver, generate_source
from ..sim.metrics import metrics_from_sums
from ..sim.step import casadi_functions, symbolic_closed_loop_rk4

METRIC_NAMES = ("final_error", "rms_error", "rms_error_second_half", "max_abs_u",
                "reaching_time", "total_variation_u")

#: Values of ``BatchResult.info["path"]``: the SIMD form for the instruction set it was
#: built for (``simd-generic``: no x86 vector flags known, lanes left to the compiler),
#: or the scalar C loop.
PATHS = ("simd-avx512", "simd-avx2", "simd-sse2", "simd-generic", "scalar")


class SimdFallbackWarning(RuntimeWarning):
    """``simd=True`` was requested but the scalar loop ran (the message names why)."""


@dataclass
class BatchResult:
    """Per-run results of :func:`simulate_batch` (``B`` runs).

    Attributes
    ----------
    params : ndarray, shape (B, n_params)
        TRUE parameters of each run (``param_names`` order).
    metrics : dict str -> ndarray, shape (B,)
        The fields of :class:`fjm_runtime.simulate.Metrics`; NaN for diverged runs.
    diverged : ndarray of bool, shape (B,)
    divergence_time : ndarray, shape (B,)
        First time the state was non-finite or beyond ``max_state`` (NaN if never).
    x_final : ndarray, shape (B, 4n)
    results : list of SimulationResult or None
        Full trajectories, only with ``trajectories=True``.
    info : dict
        How the batch ran: ``path`` (one of :data:`PATHS`), ``reason`` (why the
        scalar loop ran; ``None`` on a SIMD path), ``threads`` (OpenMP threads
        used), ``lanes`` (runs per vector statement, 1 for scalar),
        ``instructions`` (SX instructions of one step) and ``library`` (the
        compiled shared object).
    """

    params: np.ndarray
    metrics: Dict[str, np.ndarray]
    diverged: np.ndarray
    divergence_time: np.ndarray
    x_final: np.ndarray
    results: Optional[list] = None
    info: dict = field(default_factory=dict)

    def table(self) -> List[dict]:
        """One dict per run: parameters by name are not known here; index, metrics, diverged."""
        return [dict(run=i, diverged=bool(self.diverged[i]),
                     **{k: float(v[i]) for k, v in self.metrics.items()})
                for i in range(self.diverged.size)]


def _metric_step(model, controller, dt: float, max_state: float) -> ca.Function:
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


_DRIVER = fold_driver("fjm_metric_step") + r"""
int fjm_batch(int n_runs, int n_samples, int nacc, int nr, double* acc,
              const double* R0, const double* RH, const double* R1, const double* FL,
              int n_threads, int* threads_used) {
  return fjm_fold(n_runs, n_samples, nacc, nr, 4, 0, acc, R0, RH, R1, FL, 0, 0, n_threads, threads_used);
}
"""


def _threads_arg(threads: Optional[int]) -> int:
    """``threads`` for the C drivers: 0 = OpenMP's default (``OMP_NUM_THREADS`` or all cores)."""
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
                        _threads_arg(threads), ctypes.byref(used))
        if flag:
            raise RuntimeError("compiled batch step returned an error flag")
        return self._unpack(acc, ACC0.shape[0]), int(used.value)

    def __call__(self, ACC0, R0, RH, R1, FL, threads: Optional[int] = None) -> np.ndarray:
        """:meth:`run` without the thread count: the final accumulators (B, nacc)."""
        return self.run(ACC0, R0, RH, R1, FL, threads)[0]


def _scalar_runner(step: ca.Function, flags: Sequence[str], parallel: bool) -> BatchRunner:
    nacc, nr = step.size1_in(0), step.size1_in(1)
    source = generate_source(step) + _DRIVER
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
    return _scalar_runner(_metric_step(model, controller, float(dt), float(max_state)), flags, parallel)


def simulate_batch(model, controller, reference, params_true_array, *, duration: float,
                   dt: float = 1e-3, x0=None, max_state: float = 1e6, trajectories: bool = False,
                   parallel: bool = True, simd: bool = True,
                   threads: Optional[int] = None) -> BatchResult:
    """Run ``B`` closed loops (one per row of ``params_true_array``) in one compiled call.

    Parameters
    ----------
    model, controller, reference
        As for :func:`fjm_runtime.simulate.simulate`; the controller (nominal
        parameters) and the reference are shared by all runs.
    params_true_array : array_like, shape (B, n_params)
        TRUE plant parameters per run, columns in ``model.param_names`` order.
    duration, dt, x0, max_state
        As for :func:`simulate` (``x0`` shared by all runs).
    trajectories : bool
        Also return every run's :class:`SimulationResult` (compiled backend, one
        run at a time; memory grows with ``B * duration / dt``).
    parallel : bool
        Spread the runs over cores with OpenMP (serial if ``-fopenmp`` fails).
    simd : bool
        Evaluate 8 runs per instruction with vector instructions (AVX-512, AVX2
        or SSE2, whatever this CPU has) and vector sin/cos (glibc libmvec); the
        per-run constants (TRUE parameters) are hoisted out of the time loop.
        Agrees with the scalar code to rounding. ``False``: the scalar C loop.
        If the SIMD form cannot be used (the step is larger than
        :data:`SIMD_MAX_INSTRUCTIONS`, an operation it does not support, a
        failed build) the scalar loop runs and a :class:`SimdFallbackWarning`
        names the reason (also in ``info["reason"]``).
    threads : int, optional
        OpenMP threads for this call (default: ``OMP_NUM_THREADS`` or all
        cores); ignored when ``parallel`` is false. ``info["threads"]`` is the
        number actually used.

    Returns
    -------
    BatchResult
        ``info["path"]`` says which code ran (one of :data:`PATHS`).
    """
    from ..sim.simulate import simulate
    n, nx = int(model.n), int(model.nx)
    P = np.asarray(params_true_array, dtype=float)
    if P.ndim == 1 and P.size == len(model.param_names):
        P = P[None, :]
    if P.ndim != 2 or P.shape[1] != len(model.param_names) or P.shape[0] < 1:
        raise ValueError(f"params_true_array with shape {np.shape(params_true_array)}: expected "
                         f"(B, {len(model.param_names)}) with columns {', '.join(model.param_names)}")
    if not np.all(np.isfinite(P)):
        raise ValueError("params_true_array: expected finite values")
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"duration = {duration!r}: expected a finite value > 0 s")
    if not (np.isfinite(dt) and 0 < dt <= duration):
        raise ValueError(f"dt = {dt!r}: expected a finite step with 0 < dt <= duration")
    B = P.shape[0]
    n_steps = int(round(duration / dt))
    r_half = reference.sample(0.5 * dt * np.arange(2 * n_steps + 3)).reshape(-1, 5 * n)
    R = r_half[0::2]
    if x0 is None:
        x0 = np.zeros(nx)
        x0[0:n] = R[0, :n]
        x0[2 * n:3 * n] = R[0, :n]
    x0 = np.asarray(x0, dtype=float)
    if x0.shape != (nx,) or not np.all(np.isfinite(x0)):
        raise ValueError(f"x0 with shape {x0.shape}: expected finite ({nx},) = [q_l; dq_l; q_m; dq_m]")
    z0 = np.asarray(controller.initial_state(0.0, x0, R[0].reshape(5, n)), dtype=float)
    acc0 = np.concatenate([x0, z0, np.zeros(n), [0.0, 0.0, 0.0, -1.0, 0.0, -1.0]])
    ACC0 = np.hstack([np.tile(acc0, (B, 1)), P]).T
    t = dt * np.arange(n_steps + 1)
    half = (t >= 0.5 * t[-1]).astype(float)
    FL = np.vstack([half, np.arange(n_steps + 1, dtype=float),
                    (np.arange(n_steps + 1) == 0).astype(float),
                    (np.arange(n_steps + 1) == n_steps).astype(float)])
    _threads_arg(threads)  # validate before compiling anything
    step = _metric_step(model, controller, float(dt), float(max_state))
    runner, reason = None, "simd=False requested"
    if simd:
        if step.n_instructions() > SIMD_MAX_INSTRUCTIONS:
            reason = (f"the step has {step.n_instructions()} SX instructions > "
                      f"SIMD_MAX_INSTRUCTIONS = {SIMD_MAX_INSTRUCTIONS}")
        else:
            try:
                runner = _simd_runner(step, len(model.param_names), DEFAULT_FLAGS, None, parallel)
                reason = None
            except (CompileError, ValueError) as exc:
                reason = f"SIMD build failed: {type(exc).__name__}: {str(exc)[:2000]}"
        if runner is None:
            warnings.warn(f"simulate_batch: scalar loop instead of SIMD: {reason}",
                          SimdFallbackWarning, stacklevel=2)
    if runner is None:
        runner = _scalar_runner(step, DEFAULT_FLAGS, parallel)
    acc, used = runner.run(ACC0.T, R[:n_steps + 1], r_half[1:2 * n_steps + 2:2], R[1:n_steps + 2],
                           FL.T, threads if parallel else 1)
    info = {"path": runner.path_name, "reason": reason, "threads": used, "lanes": runner.lanes,
            "openmp": runner.openmp, "instructions": int(step.n_instructions()),
            "library": str(runner.path)}
    nw = nx + z0.size
    sum_e2, sum_half, max_u, last_out, tv, first_bad = (acc[:, nw + n + i] for i in range(6))
    x_fin = acc[:, :nx]
    metrics = metrics_from_sums(t, np.max(np.abs(x_fin[:, :n] - R[n_steps, :n]), axis=1), sum_e2, sum_half,
                                max_u, last_out, tv, n)
    diverged = first_bad >= 0
    for v in metrics.values():
        v[diverged] = np.nan
    results = None
    if trajectories:
        results = [simulate(model, controller, reference, duration=duration, dt=dt, true_params=P[i],
                            x0=x0, max_state=max_state, backend="compiled") if not diverged[i] else None
                   for i in range(B)]
    return BatchResult(params=P, metrics=metrics, diverged=diverged,
                       divergence_time=np.where(diverged, first_bad * dt, np.nan),
                       x_final=x_fin, results=results, info=info)


# -- SIMD across runs ------------------------------------------------------------------------
# The metric step is re-emitted "structure of arrays": every scalar instruction of the SX
# Function becomes a loop over LANES runs, which the compiler turns into vector
# instructions; sin/cos go to glibc's vector math library (libmvec); instructions that
# depend on the per-run parameters only are evaluated once per run. Results agree with the
# scalar code to rounding (libmvec sin/cos: < 4 ulp; x / p -> x * (1 / p)), not bit for bit.

def soa_source(step: ca.Function, lanes: int, varying=(0,), invariant_from: int = None) -> str:
    """C source of ``step`` evaluated on ``lanes`` runs at once (inputs in ``varying`` per lane).

    GCC vector extensions: every SX instruction becomes one statement on a vector of
    ``lanes`` doubles (compiled to AVX-512/AVX2/SSE2 instructions); sin/cos and friends
    go through short lane loops that gcc maps to glibc's vector math (libmvec).
    Defines ``fjm_prologue(acc, inv)``, ``fjm_step_soa(inv, arg, res)`` and the driver
    ``fjm_batch_soa``; varying inputs and every output are laid out ``[nz][lane]``.
    Entries ``>= invariant_from`` of input 0 are constant along a run (the TRUE
    parameters riding in the accumulator): every instruction that depends on them and
    constants only is hoisted into the prologue (once per run group, not once per
    step), and a division by such a value becomes a multiplication by its reciprocal
    (rounding may differ by one ulp).
    """
    O = ca
    L = int(lanes)
    unary = {
        O.OP_NEG: "-({a})", O.OP_SQ: "({a})*({a})", O.OP_TWICE: "2.*({a})", O.OP_INV: "1./({a})",
        O.OP_SIN: "v_sin({a})", O.OP_COS: "v_cos({a})", O.OP_TAN: "v_tan({a})", O.OP_EXP: "v_exp({a})",
        O.OP_LOG: "v_log({a})", O.OP_SQRT: "v_sqrt({a})", O.OP_TANH: "v_tanh({a})",
        O.OP_ATAN: "v_atan({a})", O.OP_ASIN: "v_asin({a})", O.OP_ACOS: "v_acos({a})",
        O.OP_FABS: "(vd)((vl)({a}) & 0x7fffffffffffffffLL)",
        O.OP_NOT: "v_b(({a}) == 0.)", O.OP_ASSIGN: "({a})",
        O.OP_SIGN: "v_sign({a})",
    }
    binary = {
        O.OP_ADD: "({a})+({b})", O.OP_SUB: "({a})-({b})", O.OP_MUL: "({a})*({b})",
        O.OP_DIV: "({a})/({b})", O.OP_POW: "v_pow({a},{b})", O.OP_CONSTPOW: "v_pow({a},{b})",
        O.OP_FMIN: "v_sel(({a})<({b}), {a}, {b})", O.OP_FMAX: "v_sel(({a})>({b}), {a}, {b})",
        O.OP_LT: "v_b(({a})<({b}))", O.OP_LE: "v_b(({a})<=({b}))",
        O.OP_EQ: "v_b(({a})==({b}))", O.OP_NE: "v_b(({a})!=({b}))",
        O.OP_AND: "v_b((({a})!=0.) & (({b})!=0.))", O.OP_OR: "v_b((({a})!=0.) | (({b})!=0.))",
        O.OP_IF_ELSE_ZERO: "(vd)((vl)({b}) & (({a}) != 0.))", O.OP_ATAN2: "v_atan2({a},{b})",
        O.OP_COPYSIGN: "v_copysign({a},{b})",
    }
    body, pro = [], []
    src = {}
    n_inv = [0]
    recip = {}

    def new_inv():
        n_inv[0] += 1
        return n_inv[0] - 1

    def ref(slot):
        kind, j = src[slot]
        return f"inv[{j}]" if kind == "inv" else f"w{j}"

    used = set()
    for k in range(step.n_instructions()):
        op = step.instruction_id(k)
        i = step.instruction_input(k)
        o = step.instruction_output(k)
        if op == ca.OP_CONST:
            j = new_inv()
            pro.append(f"inv[{j}] = V0 + {float(step.instruction_constant(k))!r};")
            src[o[0]] = ("inv", j)
        elif op == ca.OP_INPUT:
            if invariant_from is not None and i[0] == 0 and i[1] >= invariant_from:
                j = new_inv()
                pro.append(f"memcpy(&inv[{j}], acc + {i[1]}*LANES, sizeof(vd));")
                src[o[0]] = ("inv", j)
            else:
                if i[0] in varying:
                    body.append(f"memcpy(&w{o[0]}, arg[{i[0]}] + {i[1]}*LANES, sizeof(vd));")
                else:
                    body.append(f"w{o[0]} = V0 + arg[{i[0]}][{i[1]}];")
                src[o[0]] = ("w", o[0]); used.add(o[0])
        elif op == ca.OP_OUTPUT:
            body.append(f"{{ vd t = {ref(i[0])}; memcpy(res[{o[0]}] + {o[1]}*LANES, &t, sizeof(vd)); }}")
        elif op in unary or op in binary:
            args = list(i[:1]) if op in unary else list(i[:2])
            fmt = unary[op] if op in unary else binary[op]
            if all(src[a][0] == "inv" for a in args):
                j = new_inv()
                pro.append(f"inv[{j}] = " + fmt.format(a=ref(args[0]), b=ref(args[-1])) + ";")
                src[o[0]] = ("inv", j)
                continue
            if op == ca.OP_DIV and src[args[1]][0] == "inv":
                d = src[args[1]][1]
                if d not in recip:
                    recip[d] = new_inv()
                    pro.append(f"inv[{recip[d]}] = 1./inv[{d}];")
                expr = f"({ref(args[0])})*inv[{recip[d]}]"
            else:
                expr = fmt.format(a=ref(args[0]), b=ref(args[-1]))
            body.append(f"w{o[0]} = {expr};")
            src[o[0]] = ("w", o[0]); used.add(o[0])
        else:
            raise ValueError(f"soa_source: operation {op} not supported")
    decl = ", ".join(f"w{j}" for j in sorted(used)) or "w_unused"
    lane_fns = []
    for fn in ("sin", "cos", "tan", "exp", "log", "sqrt", "tanh", "atan", "asin", "acos"):
        lane_fns.append(f"static inline vd v_{fn}(vd x) {{ double a[LANES], r[LANES]; memcpy(a, &x, sizeof x); "
                        f"for (int l = 0; l < LANES; ++l) r[l] = {fn}(a[l]); memcpy(&x, r, sizeof x); return x; }}")
    for fn in ("pow", "atan2", "copysign"):
        lane_fns.append(f"static inline vd v_{fn}(vd x, vd y) {{ double a[LANES], b[LANES], r[LANES]; "
                        f"memcpy(a, &x, sizeof x); memcpy(b, &y, sizeof y); "
                        f"for (int l = 0; l < LANES; ++l) r[l] = {fn}(a[l], b[l]); memcpy(&x, r, sizeof x); return x; }}")
    return "\n".join([
        "/* fjm: SIMD-across-runs form of the closed-loop metric step (generated, do not edit). */",
        "#define __FAST_MATH__ 1  /* only to expose glibc's vector math declarations (libmvec) */",
        "#include <math.h>",
        "#undef __FAST_MATH__",
        "#include <stdlib.h>",
        "#include <string.h>",
        f"#define LANES {L}",
        "typedef double vd __attribute__((vector_size(8 * LANES)));",
        "typedef long long vl __attribute__((vector_size(8 * LANES)));",
        "static const vd V0 = {0};",
        "static inline vd v_b(vl m) { return __builtin_convertvector(-m, vd); }",
        "static inline vd v_sel(vl m, vd a, vd b) { return (vd)(((vl)a & m) | ((vl)b & ~m)); }",
        "static inline vd v_sign(vd x) { return v_sel(x < 0., V0 - 1., v_sel(x > 0., V0 + 1., x)); }",
        *lane_fns,
        f"#define SZ_INV {max(1, n_inv[0])}",
        "static void fjm_prologue(const double* restrict acc, vd* restrict inv) {",
        *("  " + ln for ln in pro),
        "}",
        "static void fjm_step_soa(const vd* restrict inv, const double** arg, double** res) {",
        f"  vd {decl};",
        *("  " + ln for ln in body),
        "}",
        r"""
#ifdef _OPENMP
#include <omp.h>
#endif
int fjm_batch_soa(int n_groups, int n_samples, int nacc, int nr, double* acc,
                  const double* R0, const double* RH, const double* R1, const double* FL,
                  int n_threads, int* threads_used) {
  int used = 1, nt = 1;
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
    #pragma omp for schedule(dynamic, 1)
    for (int g = 0; g < n_groups; ++g) {
      vd* inv = aligned_alloc(64, sizeof(vd) * SZ_INV);
      double* buf = malloc(sizeof(double) * 2 * nacc * LANES);
      double *cur = buf, *nxt = buf + nacc * LANES;
      memcpy(cur, acc + (size_t)g * nacc * LANES, sizeof(double) * nacc * LANES);
      fjm_prologue(cur, inv);
      const double* arg[5];
      double* res[1];
      for (int k = 0; k < n_samples; ++k) {
        arg[0] = cur; arg[1] = R0 + (size_t)k * nr; arg[2] = RH + (size_t)k * nr;
        arg[3] = R1 + (size_t)k * nr; arg[4] = FL + (size_t)k * 4;
        res[0] = nxt;
        fjm_step_soa(inv, arg, res);
        double* t = cur; cur = nxt; nxt = t;
      }
      memcpy(acc + (size_t)g * nacc * LANES, cur, sizeof(double) * nacc * LANES);
      free(inv); free(buf);
    }
  }
  *threads_used = used;
  return 0;
}
"""])


def _cpu_flags() -> set:
    try:
        with open("/proc/cpuinfo") as fh:
            for ln in fh:
                if ln.startswith("flags"):
                    return set(ln.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def _vector_isa() -> tuple:
    """``(name, flags)``: the instruction set of the SIMD batch, chosen from THIS machine's CPU.

    ``name`` is ``avx512``, ``avx2``, ``sse2`` or ``generic``; the flags are part of
    the cache key, so a machine with another instruction set never loads a library
    built for this one.
    """
    cpu = _cpu_flags()
    if {"avx512f", "avx512dq"} <= cpu:
        return "avx512", ("-mavx512f", "-mavx512dq", "-mprefer-vector-width=512")
    if "avx2" in cpu:
        return "avx2", ("-mavx2",)
    if "sse2" in cpu:
        return "sse2", ()
    return "generic", ()


def _vector_flags() -> tuple:
    """Compiler flags of :func:`_vector_isa`."""
    return _vector_isa()[1]


class SimdBatchRunner(BatchRunner):
    """ctypes handle on the SIMD batch loop; same calls as :class:`BatchRunner`.

    Runs are packed ``lanes`` at a time ("structure of arrays"); the last group
    is filled with copies of the last run.
    """

    _entry = "fjm_batch_soa"

    def __init__(self, so_path, nacc: int, nr: int, lanes: int, isa: str = "generic",
                 openmp: bool = True):
        super().__init__(so_path, nacc, nr, openmp=openmp)
        self.lanes, self.isa = int(lanes), isa

    @property
    def path_name(self) -> str:
        return f"simd-{self.isa}"

    def _pack(self, A):
        B, L = A.shape[0], self.lanes
        G = -(-B // L)
        pad = np.vstack([A, np.repeat(A[-1:], G * L - B, axis=0)])   # fill the last group
        return np.ascontiguousarray(pad.reshape(G, L, self.nacc).transpose(0, 2, 1)), G

    def _unpack(self, soa, B):
        return soa.transpose(0, 2, 1).reshape(-1, self.nacc)[:B].copy()


#: Largest step (SX instructions) emitted in SIMD form (a guard against pathological
#: compile times; gcc handles the vector-extension code in about linear time:
#: link1 0.2 s, planar3 0.3 s).
SIMD_MAX_INSTRUCTIONS = 200000


def _simd_runner(step: ca.Function, n_par: int, flags: Sequence[str], lanes: Optional[int],
                 parallel: bool = True) -> SimdBatchRunner:
    lanes = int(lanes) if lanes else 8
    isa, vflags = _vector_isa()
    extra = ("-fno-math-errno", "-ffp-contract=off") + (("-fopenmp",) if parallel else ()) + vflags
    source = soa_source(step, lanes, invariant_from=step.size1_in(0) - n_par)
    so = compile_library(source, "fjm_batch_soa", tuple(flags) + extra)
    return SimdBatchRunner(so, step.size1_in(0), step.size1_in(1), lanes, isa, openmp=parallel)


def simd_batch_runner(model, controller, dt: float, max_state: float = 1e6,
                      flags: Sequence[str] = DEFAULT_FLAGS, lanes: Optional[int] = None,
                      parallel: bool = True) -> SimdBatchRunner:
    """Compile (cached) the SIMD-across-runs batch loop (``lanes`` runs per instruction,
    default 8: one AVX-512 vector, two AVX2 vectors or four SSE2 vectors per operation).

    ``-ffp-contract=off`` keeps the arithmetic identical to the scalar code (no FMA
    contraction); only sin/cos (libmvec) may differ by a few ulp. Raises
    :class:`~fjm_runtime.compiled.CompileError` or ``ValueError`` (an operation
    :func:`soa_source` does not support) instead of falling back.
    """
    step = _metric_step(model, controller, float(dt), float(max_state))
    return _simd_runner(step, len(model.param_names), flags, lanes, parallel)
