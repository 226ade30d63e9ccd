"""``fjm export controller``: the C library IS the controller the simulator verified.

The reference is the simulator's own run (:func:`fjm_runtime.simulate`, the sampled loop of
:mod:`fjm_runtime.sim.sample_step`): its plant states, the run's sensor noise and tau_J offset give
the raw reading of every sample exactly as the step makes it (``raw_reading``); fed sample after
sample to the exported library (ctypes), the torques must be the run's applied torques ``res.u``
(double: to 1e-12 of each joint's largest torque; float: a bounded deviation, printed). Bad readings
never give a NaN torque; two controllers interleaved give the torques of each alone.
"""
from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.control.design import Design
from fjm_runtime.export.controller import design_controller, export_controller

from support.controller_runs import (BAD, FREE_SAMPLES, LINK1_TORQUE_DESIGN, NOT_FINITE, OK, SATURATED, Run,
                                     free_running, library, make_design, per_sample, relative, sine)


def _panda_design():
    return design_controller(fjm_runtime.load("panda"), Design.shipped("panda", "ismc", "torque", 1000.0, 1))


def _check_equal(design, tmp_path_factory, duration, reference=None, float_bound=None):
    run = Run(design, duration, reference)
    lib = library(design, tmp_path_factory)
    U, S, C_next = per_sample(lib, run)
    rel = relative(U, run.U)
    rel_c = relative(C_next[:-1], run.C[1:]) if run.C.shape[1] else 0.0
    Uf, _ = free_running(lib, run, FREE_SAMPLES)
    rel_free = relative(Uf, run.U[:FREE_SAMPLES])
    print(f"\n{design.name} ({design.sensor.name}, {duration:g} s): double max rel dev per sample {rel:.3g}, "
          f"free-running first {FREE_SAMPLES} samples {rel_free:.3g}, state {rel_c:.3g}")
    assert np.all(np.isfinite(U)) and np.all(S != NOT_FINITE)
    assert rel <= 1e-12, f"{design.name}: the C torques deviate from the simulator's by {rel:.3g} (relative)"
    assert rel_c <= 1e-12, f"{design.name}: the C controller state deviates by {rel_c:.3g} (relative)"
    assert rel_free <= 1e-12, f"{design.name}: from reset, the C torques deviate by {rel_free:.3g} (relative)"
    if float_bound is not None:
        U32, _, _ = per_sample(library(design, tmp_path_factory, "float"), run)
        rel_f = relative(U32, run.U)
        print(f"{design.name}: float max rel dev per sample {rel_f:.3g}")
        assert rel_f <= float_bound, f"{design.name}: float build deviates by {rel_f:.3g} > {float_bound:g}"
    return run, S


# -- equality with the simulator --------------------------------------------------------------------

@pytest.mark.slow
def test_panda_shipped_design_equals_simulator(tmp_path_factory):
    """The Panda's shipped design (torque-sensed ismc, panda_white noise, filtered dtau_J, delay 1 with
    prediction, 11 substeps): 1 s of the design's task, C torques == the run's to 1e-12."""
    _check_equal(_panda_design(), tmp_path_factory, 1.0, float_bound=5e-2)


@pytest.mark.slow
@pytest.mark.exhaustive
def test_panda_shipped_design_equals_simulator_10s(tmp_path_factory):
    _check_equal(_panda_design(), tmp_path_factory, 10.0, float_bound=5e-2)


@pytest.mark.slow
@pytest.mark.exhaustive
def test_baxter_shipped_design_equals_simulator(tmp_path_factory):
    """The tree (15 joints, two arms on a torso): Baxter's shipped design (torque-sensed ismc, delay 1 with
    prediction), 1 s of its task; its controller's compile takes a minute, so CI's exhaustive pass."""
    design = design_controller(fjm_runtime.load("baxter"), Design.shipped("baxter", "ismc", "torque", 1000.0, 1))
    _check_equal(design, tmp_path_factory, 1.0, float_bound=5e-2)


@pytest.mark.slow
@pytest.mark.exhaustive
def test_panda_hd_shipped_design_equals_simulator(tmp_path_factory):
    """The Panda on harmonic drives (seven datasheet curves, motor friction): its shipped design, whose
    predictor rebuilds q_m through the curves' inverse psi^-1(tau_J); 1 s, C == simulator to 1e-12."""
    design = design_controller(fjm_runtime.load("panda_hd"),
                               Design.shipped("panda_hd", "ismc", "torque", 1000.0, 1))
    _check_equal(design, tmp_path_factory, 1.0, float_bound=5e-2)


@pytest.mark.slow
@pytest.mark.parametrize("sensing, noise, predict", [("torque", "franka_like", None), ("state", "panda_white", None),
                                                     ("torque", "panda_white", False)])
def test_datasheet_spring_equals_simulator(tmp_path_factory, sensing, noise, predict):
    """arm1_hd (a three-segment curve): torque sensing predicts through psi^-1, state sensing resets the
    held torque to psi(q_m - q), torque sensing without prediction (fjm design's default) needs no K_i;
    2 s, C == simulator to 1e-12."""
    design = make_design("arm1_hd", "ismc", sensing, noise, u_max=60.0, predict=predict, lam=30.0, k_s=100.0,
                         delta=5.0)
    _check_equal(design, tmp_path_factory, 2.0, sine(design, amplitude=0.3, omega=3.0), float_bound=1e-2)


#: Gains that track on a 2 s sine with a torque limit below the run's peak (the limit is reached,
#: but most samples are the unclipped law).
_SOFT = {"lam": 5.0, "k_s": 10.0, "delta": 20.0}


@pytest.mark.slow
@pytest.mark.parametrize("model,kind,sensing,noise,gains,u_max", [
    # rate limit + conditional integration, differentiated velocities, quantization, tau_J offset
    ("link1", "ismc", "torque", "franka_like", {"lam": 10.0, "k_s": 20.0, "delta": 20.0}, 25.0),
    ("link1", "smc", "state", "panda_white", {"lam": 10.0, "k_s": 20.0, "delta": 20.0}, 10.0),
    ("planar3", "ismc", "torque", "panda_white", _SOFT, 60.0),
    ("planar3", "ismc", "state", "franka_like", _SOFT, 40.0),
    ("planar3", "fl", "torque", "panda_white", _SOFT, 60.0),
])
def test_small_models_equal_simulator(tmp_path_factory, model, kind, sensing, noise, gains, u_max):
    """Each sensing, law and sensor pre-processing: 2 s, C == simulator to 1e-12; the limits are
    reached on some samples and most samples are the unclipped law."""
    design = make_design(model, kind, sensing, noise, u_max=u_max, **gains)
    run, S = _check_equal(design, tmp_path_factory, 2.0, sine(design), float_bound=1e-3)
    print(f"{design.name}: limited on {np.mean(S == SATURATED):.1%} of the samples")
    assert np.any(S == SATURATED), "the run never reaches a limit: the limits are not exercised"
    assert np.mean(S == OK) > 0.5, "the run is mostly at a limit: the law itself is hardly compared"


@pytest.mark.slow
def test_rate_limit_is_applied_in_c(tmp_path_factory):
    """A motor interface limited to 1000 N m/s: the C torque never changes by more than 1 N m a sample, and it
    does change by exactly that while the limit holds it (the clip is in the library, not the caller)."""
    design = make_design("link1", "ismc", "torque", "franka_like", u_max=25.0, lam=10.0, k_s=20.0, delta=20.0,
                         interface={"torque_rate_limit": 1000.0})
    run = Run(design, 1.0, sine(design))
    U, S = free_running(library(design, tmp_path_factory), run)
    dU = np.abs(np.diff(np.vstack([run.u0[None], U]), axis=0))
    assert np.max(dU) <= 1.0 + 1e-9
    at_limit = np.isclose(dU[:, 0], 1.0, rtol=0, atol=1e-9)
    assert np.sum(at_limit) > 10
    assert np.all(S[at_limit] == SATURATED)


# -- robustness and independence ---------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_reading_holds_the_last_torque(tmp_path_factory, bad):
    """A NaN/inf reading (any slot) or reference: the last torque again, status INPUT_NOT_FINITE, the
    state kept (the next good sample gives, bit for bit, the torque it gives without the bad one)."""
    design = make_design("planar3", "ismc", "torque", "panda_white", u_max=60.0, **_SOFT)
    run = Run(design, 0.1, sine(design))
    U_ref, _ = free_running(library(design, tmp_path_factory), run)
    ctrl = library(design, tmp_path_factory)
    assert ctrl.reset(run.m0) == OK
    k_bad = 50
    for k in range(run.M.shape[0]):
        if k == k_bad:
            for slot in range(run.M.shape[1]):
                m = run.M[k].copy(); m[slot] = bad
                st, u = ctrl.step(m, run.R[k])
                assert st == NOT_FINITE and np.array_equal(u, U_ref[k - 1]), f"slot {slot}"
            for slot in range(run.R.shape[1]):
                r = run.R[k].copy(); r[slot] = bad
                st, u = ctrl.step(run.M[k], r)
                assert st == NOT_FINITE and np.array_equal(u, U_ref[k - 1]), f"reference slot {slot}"
        st, u = ctrl.step(run.M[k], run.R[k])
        assert st in (OK, SATURATED)
        np.testing.assert_array_equal(u, U_ref[k])


@pytest.mark.slow
def test_overflowing_reading_never_gives_a_nan_torque(tmp_path_factory):
    """A finite reading whose law overflows (1e308 rad): the result is checked too; the torque is
    finite whatever the status."""
    design = make_design("planar3", "ismc", "torque", "panda_white", u_max=60.0, **_SOFT)
    run = Run(design, 0.02, sine(design))
    for slot in range(run.M.shape[1]):
        ctrl = library(design, tmp_path_factory)
        assert ctrl.reset(run.m0) == OK
        m = run.M[5].copy(); m[slot] = 1e308
        st, u = ctrl.step(m, run.R[5])
        assert np.all(np.isfinite(u)), f"slot {slot}: status {st}, u {u}"


@pytest.mark.slow
def test_two_controllers_interleaved_equal_each_alone(tmp_path_factory):
    """Two structs of one library, stepped alternately on different readings: each gives, bit for
    bit, the torques it gives alone (no hidden shared state)."""
    design = make_design("planar3", "ismc", "state", "franka_like", u_max=40.0, **_SOFT)
    run_a, run_b = Run(design, 0.5, sine(design)), Run(design, 0.5, sine(design, 0.3, 3.0))
    U_a, _ = free_running(library(design, tmp_path_factory), run_a)
    U_b, _ = free_running(library(design, tmp_path_factory), run_b)
    a, b = library(design, tmp_path_factory), library(design, tmp_path_factory)
    assert a.reset(run_a.m0) == OK and b.reset(run_b.m0) == OK
    for k in range(run_a.M.shape[0]):
        _, ua = a.step(run_a.M[k], run_a.R[k])
        _, ub = b.step(run_b.M[k], run_b.R[k])
        np.testing.assert_array_equal(ua, U_a[k])
        np.testing.assert_array_equal(ub, U_b[k])
    assert np.max(np.abs(U_a - U_b)) > 1.0      # the two runs differ: a shared state would show


@pytest.mark.slow
def test_step_before_reset_is_refused(tmp_path_factory):
    """``step`` before ``reset``: BAD_ARGUMENT and no torque written."""
    design = make_design("link1", "smc", "state", "ideal", delay=0)
    lib = library(design, tmp_path_factory)
    st, u = lib.step(np.zeros(4), np.zeros(5))
    assert st == BAD and np.all(u == 0)


@pytest.mark.slow
def test_cli_export_builds_strict_in_double_float_and_cxx(tmp_path):
    """``fjm export controller`` + ``make``: -std=c99 -Wall -Wextra -Werror -pedantic in double and float,
    and g++ -std=c++17 -Wall -Wextra -Werror, without a diagnostic; a C++ caller links the library."""
    import shutil
    from fjm_runtime.cli.main import main
    assert shutil.which("make") and shutil.which("g++"), "make and g++ are needed (the C++ class is built)"
    gains = tmp_path / "design.json"
    gains.write_text(json.dumps(LINK1_TORQUE_DESIGN))
    out = tmp_path / "lib"
    assert main(["export", "controller", "link1", "--gains", str(gains), "--out", str(out)]) == 0
    proc = subprocess.run(["make", "-C", str(out)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "warning" not in proc.stderr.lower()
    for lib in ("liblink1_ismc_tau.a", "liblink1_ismc_tau_float.a"):
        assert (out / lib).is_file()
    cxx = tmp_path / "use.cpp"
    cxx.write_text('#include "link1_ismc_tau_controller.h"\n#include <cmath>\n'
                   "int main() { link1_ismc_tau_controller c; double m0[5] = {0.1, 0, 0, 0, 0.1};\n"
                   "  double r[5] = {0.1, 0, 0, 0, 0}; double u[1];\n"
                   "  if (link1_ismc_tau_init(&c, nullptr, nullptr) != LINK1_ISMC_TAU_OK) return 1;\n"
                   "  if (link1_ismc_tau_reset(&c, m0) != LINK1_ISMC_TAU_OK) return 2;\n"
                   "  if (link1_ismc_tau_step(&c, m0, r, u) > LINK1_ISMC_TAU_SATURATED) return 3;\n"
                   "  return std::isfinite(u[0]) ? 0 : 4; }\n")
    exe = tmp_path / "use"
    proc = subprocess.run(["g++", "-std=c++17", "-Wall", "-Wextra", "-Werror", f"-I{out}", str(cxx),
                           str(out / "liblink1_ismc_tau.a"), "-lm", "-o", str(exe)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert subprocess.run([str(exe)]).returncode == 0


_STANDIN = """// stand-in for <casadi/casadi.hpp>: the global names it declares (casadi_types.hpp, mem.h)
typedef long long int casadi_int;
typedef double casadi_real;
namespace casadi { class Function; }
"""

_CXX_RUN = r"""#include "NAME_controller.hpp"
#include <casadi/casadi.hpp>
#if defined(casadi_real) || defined(casadi_int)
#error "casadi_real or casadi_int leaked as a macro"
#endif
#include <cstdio>
#include <cstdlib>
#include <new>

static long allocations = 0;  // every operator new of the program
void* operator new(std::size_t size) {
  ++allocations; void* p = std::malloc(size ? size : 1); if (!p) throw std::bad_alloc(); return p; }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

template <typename Real>
static long run(FILE* in, FILE* out, long K) {  // class and C API side by side; returns allocations in update
  using C = NAME::Controller<Real>;
  C cls;
  typename NAME::CApi<Real>::State c_api_state{}; auto* c_api = &c_api_state;
  typename C::Reading m{}; typename C::Reference r{}; typename C::Torque u{}; typename C::Torque u_c{};
  double v;
  for (auto& x : m) { if (std::fread(&v, sizeof v, 1, in) != 1) std::exit(9); x = Real(v); }
  if (cls.init() != NAME::Status::ok || NAME::CApi<Real>::init(c_api, nullptr, nullptr) != 0) std::exit(10);
  if (cls.reset(m) != NAME::Status::ok || NAME::CApi<Real>::reset(c_api, m.data()) != 0) std::exit(11);
  long in_update = 0;
  for (long k = 0; k < K; ++k) {
    for (auto& x : m) { if (std::fread(&v, sizeof v, 1, in) != 1) std::exit(12); x = Real(v); }
    for (auto& x : r) { if (std::fread(&v, sizeof v, 1, in) != 1) std::exit(13); x = Real(v); }
    long before = allocations;
    int st = int(cls.update(m, r, u));
    in_update += allocations - before;
    int st_c = NAME::CApi<Real>::step(c_api, m.data(), r.data(), u_c.data());
    for (std::size_t j = 0; j < C::N; ++j) { double a = u[j], b = u_c[j]; std::fwrite(&a, sizeof a, 1, out);
                                              std::fwrite(&b, sizeof b, 1, out); }
    double s[2] = {double(st), double(st_c)};
    std::fwrite(s, sizeof s[0], 2, out);
  }
  return in_update;
}

int main(int argc, char** argv) {
  if (argc != 4) return 7;
  long K = std::atol(argv[1]);
  FILE* in = std::fopen(argv[2], "rb"); FILE* out = std::fopen(argv[3], "wb");
  if (!in || !out) return 8;
  long a = run<double>(in, out, K);
  std::rewind(in);
  long b = run<float>(in, out, K);
  std::printf("%ld %ld\n", a, b);
  return 0;
}
"""


def _defined_symbols(archive):
    out = subprocess.run(["nm", "-g", "--defined-only", str(archive)], capture_output=True, text=True, check=True)
    return {parts[2] for parts in (line.split() for line in out.stdout.splitlines()) if len(parts) == 3}


@pytest.mark.slow
def test_cxx_class_after_casadi_header_and_float_double_in_one_program(tmp_path):
    """The C++17 class (after our header, a header declaring casadi_int/casadi_real as casadi.hpp does,
    g++ -Wall -Wextra -Werror) gives, sample for sample, bit for bit the C API's torques and statuses in
    double and in float, in ONE program linking both libraries (their exported symbols are disjoint), on
    the simulator's readings of a run; update allocates nothing; the float torques stay within 1 % of
    the double ones (per joint, of its largest torque). The real <casadi/casadi.hpp> after our header
    compiles too where the casadi package ships it."""
    import shutil
    from pathlib import Path
    import casadi
    assert shutil.which("make") and shutil.which("g++") and shutil.which("nm"), "make, g++ and nm are needed"
    design = make_design("planar2", "ismc", "torque", "franka_like", u_max=40.0, **_SOFT)
    out, name = tmp_path / "lib", design.name
    export_controller(design, out)
    proc = subprocess.run(["make", "-C", str(out), "CC=gcc", "CXX=g++"], capture_output=True, text=True)
    assert proc.returncode == 0 and "warning" not in proc.stderr.lower(), proc.stderr[-2000:]
    sym_d, sym_f = _defined_symbols(out / f"lib{name}.a"), _defined_symbols(out / f"lib{name}_float.a")
    print(f"{name}: {len(sym_d)} double and {len(sym_f)} float symbols, {len(sym_d & sym_f)} shared")
    assert len(sym_d) == len(sym_f) > 10 and not sym_d & sym_f
    standin = tmp_path / "standin" / "casadi"
    standin.mkdir(parents=True)
    (standin / "casadi.hpp").write_text(_STANDIN)
    src, exe = tmp_path / "run.cpp", tmp_path / "run"
    src.write_text(_CXX_RUN.replace("NAME", name))
    proc = subprocess.run(["g++", "-std=c++17", "-O2", "-Wall", "-Wextra", "-Werror", f"-I{out}",
                           f"-I{standin.parent}", str(src), str(out / f"lib{name}.a"), str(out / f"lib{name}_float.a"),
                           "-lm", "-o", str(exe)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    run = Run(design, 0.5, sine(design))
    K, n = run.M.shape[0], design.layout.n
    np.concatenate([run.m0] + [np.concatenate([run.M[k], run.R[k]]) for k in range(K)]).tofile(tmp_path / "in.bin")
    proc = subprocess.run([str(exe), str(K), str(tmp_path / "in.bin"), str(tmp_path / "out.bin")],
                          capture_output=True, text=True)
    assert proc.returncode == 0, (proc.returncode, proc.stderr)
    assert proc.stdout.split() == ["0", "0"], proc.stdout           # no allocation in update
    rows = np.fromfile(tmp_path / "out.bin").reshape(2, K, 2 * n + 2)
    for real, r in zip(("double", "float"), rows):
        np.testing.assert_array_equal(r[:, 0:2 * n:2], r[:, 1:2 * n:2], err_msg=real)  # class == C API
        np.testing.assert_array_equal(r[:, 2 * n], r[:, 2 * n + 1], err_msg=real)
        assert np.all(np.isfinite(r[:, :2 * n])) and np.all(r[:, 2 * n] <= SATURATED), real
    U_d, U_f = rows[0][:, 0:2 * n:2], rows[1][:, 0:2 * n:2]
    rel = relative(U_d, run.U)
    rel_f = relative(U_f, U_d)
    print(f"{name}: C++ double vs simulator, free running {rel:.3g}; float vs double {rel_f:.3g}")
    assert relative(U_d[:FREE_SAMPLES], run.U[:FREE_SAMPLES]) <= 1e-12 and rel_f <= 1e-2
    real_hpp = Path(casadi.__file__).parent / "include" / "casadi" / "casadi.hpp"
    if real_hpp.is_file():
        use = tmp_path / "use_casadi.cpp"
        use.write_text(f'#include "{name}_controller.hpp"\n#include <casadi/casadi.hpp>\n'
                       f"int main() {{ {name}::Controller<float> c; casadi::SX x = casadi::SX::sym(\"x\");\n"
                       "  return c.init() == " f"{name}::Status::ok && x.is_symbolic() ? 0 : 1; }}\n")
        proc = subprocess.run(["g++", "-std=c++17", "-Wall", "-Wextra", "-Werror", "-fsyntax-only", f"-I{out}",
                               "-isystem", str(real_hpp.parent.parent), str(use)], capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr[-3000:]
