"""The generated C sources: strict compilation, C == CasADi, and a single-precision build.

Each ``generated/<model>/<model>.c`` is compiled once per session into a shared
library (``-fPIC -shared``) with ``gcc -std=c99 -Wall -Wextra -Werror -pedantic``
and evaluated through ctypes in CasADi's calling convention
(``int f(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, int mem)``).

- strict compile: the flags above must produce no diagnostic at all;
- C == CasADi Function to 1e-12 relative (norm-wise per output) for every
  quantity, on random states and parameters, and the C sparsity of every
  output equals the CasADi one;
- ``-Dcasadi_real=float``: the same sources build in single precision and
  agree with the double build within ``FLOAT_RTOL`` (norm-wise relative, per
  output) on link1, planar2, planar3. The measured deviations are printed
  (``pytest -s``) and attached to the test report as user properties.

If the strict build fails, the library is rebuilt without ``-Werror`` so the
numeric comparisons still run (and the strict test reports the diagnostics).

A strict build that passed is kept in the fjm C cache (``$FJM_CACHE``, see
``fjm_runtime.ccache``) under ``sha256(source, compiler and its version, flags)``: the same
bytes through the same compiler and flags give the same verdict, so a later session loads that
library instead of compiling again (a changed source, flag or compiler is a new key; an entry
whose library does not match its recorded SHA-256 is rebuilt). A failing build is never cached.
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import os
import shutil
import subprocess
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Tuple

import casadi as ca
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.ccache import cache_dir
from fjm_runtime.model import QUANTITIES, available_models, generated_root
from support.c_function import CFunction

pytestmark = pytest.mark.slow  # builds C: `pytest -m "not slow"` skips it

MODELS = ("link1", "planar1", "planar2", "planar3", "planar4", "planar5", "planar6", "planar7", "elbow3", "panda",
          "baxter", "link1_complete", "planar2_complete", "panda_complete", "link1_hd", "arm1_hd", "panda_hd")
#: The models whose C holds the emitted control laws (the complete models ship the model quantities only).
CONTROL_MODELS = tuple(m for m in MODELS
                       if json.loads((generated_root() / m / "manifest.json").read_text()).get("controls"))
FLOAT_MODELS = ("link1", "planar2", "planar3")
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
#: Optimisation level: -O2, what users build with (README, examples/c) and what the bench measures.
OPT = "-O2"
C_RTOL = 1e-12
#: Documented single-precision tolerance (norm-wise relative, per output); float eps is 6e-8,
#: the deepest expressions (alpha: fourth time derivative of the link angle) lose ~3 digits.
FLOAT_RTOL = 1e-4
N_STATES = 6

#: gcc is a requirement of fjm (README, Quick start): a missing compiler is a failure, not a skip.
CC = shutil.which("gcc") or "gcc"


@dataclass
class Build:
    model: str
    real: str            # "double" or "float"
    strict_ok: bool
    diagnostics: str     # compiler output of the strict build
    lib: Path            # shared library (strict build, or the non -Werror fallback)
    seconds: float       # wall time of the strict compile (of the cached build, if cached)
    cached: bool = False  # the strict build came from the C cache (an earlier, identical compile)


def _compile(src: Path, out: Path, extra) -> Tuple[int, str, float]:
    cmd = [CC, *STRICT, OPT, "-fPIC", "-shared", *extra, str(src), "-o", str(out), "-lm"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    return proc.returncode, " ".join(cmd) + "\n" + proc.stdout + proc.stderr, time.perf_counter() - t0


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _strict_key(src: Path, extra) -> str:
    """sha256 of the source bytes, the compiler (resolved path and ``--version``) and the flags."""
    version = subprocess.run([CC, "--version"], capture_output=True, text=True).stdout
    h = hashlib.sha256(b"fjm tests/generated strict build\0")
    h.update(src.read_bytes())
    for part in (os.path.realpath(shutil.which(CC) or CC), version, *STRICT, OPT, "-fPIC", "-shared", *extra):
        h.update(b"\0" + part.encode())
    return h.hexdigest()


def _cached_strict(key: str):
    """``(library, seconds)`` of a verified cached strict build, or ``None``."""
    root = cache_dir()
    lib, meta = root / f"strict-{key}.so", root / f"strict-{key}.json"
    try:
        record = json.loads(meta.read_text())
        if record.get("key") == key and lib.is_file() and record.get("so_sha256") == _sha256(lib):
            return lib, float(record["seconds"])
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        pass
    return None


def _store_strict(key: str, built: Path, model: str, real: str, seconds: float) -> Path:
    """Copy a passing strict build into the cache (temporary file, then renamed: never half written)."""
    root = cache_dir()
    lib, meta = root / f"strict-{key}.so", root / f"strict-{key}.json"
    tmp_lib, tmp_meta = root / f".strict-{key}.so.{os.getpid()}", root / f".strict-{key}.json.{os.getpid()}"
    shutil.copyfile(built, tmp_lib)
    tmp_meta.write_text(json.dumps({"key": key, "so_sha256": _sha256(tmp_lib), "model": model, "real": real,
                                    "seconds": round(seconds, 3)}, indent=1))
    os.replace(tmp_lib, lib)     # library first, then the record that vouches for it
    os.replace(tmp_meta, meta)
    return lib


def _build(model: str, real: str, outdir: Path) -> Build:
    src = generated_root() / model / f"{model}.c"
    extra = ["-Dcasadi_real=float"] if real == "float" else []
    key = _strict_key(src, extra)
    hit = _cached_strict(key)
    if hit is not None:
        return Build(model, real, True, "", hit[0], hit[1], cached=True)
    lib = outdir / f"{model}_{real}.so"
    rc, diag, secs = _compile(src, lib, extra)
    ok = rc == 0 and not diag.split("\n", 1)[1].strip()
    if rc != 0:  # keep the numeric tests meaningful: rebuild without -Werror
        rc2, diag2, _ = _compile(src, lib, extra + ["-Wno-error"])
        assert rc2 == 0, f"{model} ({real}) does not compile even without -Werror:\n{diag2[:4000]}"
    if ok:
        _store_strict(key, lib, model, real, secs)
    return Build(model, real, ok, diag, lib, secs)


#: Models whose -O2 build takes most of this file's cold time (Baxter: 15 joints, ~18 s of gcc): their
#: checks run in CI's exhaustive pass (``pytest -m exhaustive`` in .ci/run), the others in ``make test``.
EXHAUSTIVE_C = ("baxter",)


def _params(models):
    """``models`` (names, or ``(name, real)`` pairs) as pytest parameters, :data:`EXHAUSTIVE_C` marked exhaustive."""
    out = []
    for m in models:
        values = m if isinstance(m, tuple) else (m,)
        marks = [pytest.mark.exhaustive] if values[0] in EXHAUSTIVE_C else []
        out.append(pytest.param(*values, marks=marks))
    return out


class Builds(dict):
    """``(model, real) -> Build``; a build not made up front is made on first use (the exhaustive ones)."""

    def __init__(self, outdir: Path):
        super().__init__()
        self.outdir = outdir

    def __missing__(self, key):
        self[key] = _build(*key, self.outdir)
        return self[key]


@pytest.fixture(scope="session")
def c_builds(tmp_path_factory) -> Builds:
    """Compile every model of ``make test`` (double) and FLOAT_MODELS (float) up front, two jobs at a time,
    biggest first; the models of :data:`EXHAUSTIVE_C` when a test asks for them."""
    builds = Builds(tmp_path_factory.mktemp("c_builds"))
    jobs = [(m, "double") for m in reversed(MODELS) if m not in EXHAUSTIVE_C] + [(m, "float") for m in FLOAT_MODELS]
    with ThreadPoolExecutor(max_workers=max(2, os.cpu_count() or 2)) as pool:
        for b in pool.map(lambda job: _build(*job, builds.outdir), jobs):
            builds[(b.model, b.real)] = b
    return builds


def random_points(model: fjm_runtime.Model, rng: np.random.Generator, count: int):
    """Random states (angles in [-pi, pi], rates in [-3, 3]) and parameters (defaults x U(0.5, 1.5))."""
    names = model.param_names
    for _ in range(count):
        n = model.n
        x = np.concatenate([rng.uniform(-np.pi, np.pi, n), rng.uniform(-3, 3, n),
                            rng.uniform(-np.pi, np.pi, n), rng.uniform(-3, 3, n)])
        p = np.array([model.default_params[k] for k in names]) * rng.uniform(0.5, 1.5, len(names))
        for i, k in enumerate(names):  # damping defaults to 0: give it a value so it is exercised
            if k.startswith("B") and p[i] == 0:
                p[i] = rng.uniform(0.0, 0.5)
        yield x, p


def rel_dev(a: np.ndarray, ref: np.ndarray) -> float:
    """Norm-wise relative deviation max|a - ref| / max|ref| (absolute if ref is all zero)."""
    scale = float(np.max(np.abs(ref))) if ref.size else 0.0
    err = float(np.max(np.abs(a - ref))) if ref.size else 0.0
    return err / scale if scale > 0 else err


def test_every_generated_model_is_checked():
    """A model added to generated/ without being added here would ship unchecked C."""
    assert sorted(MODELS) == available_models(generated_root())
    assert all((generated_root() / m / f"{m}.c").is_file() for m in MODELS)
    assert set(CONTROL_MODELS) >= {"link1", "panda", "baxter"}


@pytest.mark.parametrize("model,real", _params([(m, "double") for m in MODELS] + [(m, "float") for m in FLOAT_MODELS]))
def test_strict_compile(c_builds, model, real, record_property):
    """gcc -std=c99 -Wall -Wextra -Werror -pedantic accepts the generated C without a single diagnostic."""
    b = c_builds[(model, real)]
    record_property("compile_seconds", round(b.seconds, 2))
    record_property("compile_cached", b.cached)
    print(f"{model} ({real}): strict compile {b.seconds:.2f} s ({OPT}){' (cached build)' if b.cached else ''}")
    assert b.strict_ok, f"{model}.c fails the strict {real} build:\n{b.diagnostics[:3000]}"


@pytest.mark.parametrize("model", _params(MODELS))
def test_c_equals_casadi(c_builds, model, record_property):
    m = fjm_runtime.load(model)
    lib = ctypes.CDLL(str(c_builds[(model, "double")].lib))
    rng = np.random.default_rng(20261123 + MODELS.index(model))
    points = list(random_points(m, rng, N_STATES))
    worst = {}
    assert set(m.functions) >= ({"f", "g", "energy", "inertia"}), sorted(m.functions)
    for q, fn in m.functions.items():  # every model quantity it ships (the complete models: no T, alpha, ...)
        cf = CFunction(lib, f"{model}_{q}", ctypes.c_double)
        assert (cf.n_in, cf.n_out) == (fn.n_in(), fn.n_out()), q
        for i in range(fn.n_in()):
            assert cf.sparsity_in[i] == fn.sparsity_in(i), f"{q}: input {i} sparsity differs"
        for i in range(fn.n_out()):
            assert cf.sparsity_out[i] == fn.sparsity_out(i), f"{q}: output {i} sparsity differs"
        worst[q] = 0.0
        for x, p in points:
            ref = [fn(x, p)] if fn.n_out() == 1 else fn(x, p)
            got = cf(x, p)
            for r, g in zip(ref, got):
                r = np.asarray(ca.DM(r).full())
                assert np.all(np.isfinite(g)), f"{model}_{q}: non-finite C result"
                worst[q] = max(worst[q], rel_dev(g, r))
    record_property("c_vs_casadi_rel_dev", worst)
    print(f"{model}: C vs CasADi max relative deviation {worst}")
    bad = {q: d for q, d in worst.items() if not d <= C_RTOL}
    assert not bad, f"{model}: C differs from CasADi by more than {C_RTOL} (relative): {bad}"


@pytest.mark.parametrize("model", FLOAT_MODELS)
def test_single_precision(c_builds, model, record_property):
    """-Dcasadi_real=float matches the double build within FLOAT_RTOL (strictness: test_strict_compile)."""
    bf = c_builds[(model, "float")]
    m = fjm_runtime.load(model)
    lib_d = ctypes.CDLL(str(c_builds[(model, "double")].lib))
    lib_f = ctypes.CDLL(str(bf.lib))
    # Also proves the float library really works in float: its work vector sizes are in casadi_real
    # units, and a double-hardcoded path would give garbage (not a small deviation) when read as float.
    rng = np.random.default_rng(7 + FLOAT_MODELS.index(model))
    points = list(random_points(m, rng, 20))
    worst = {}
    for q in QUANTITIES:
        cd = CFunction(lib_d, f"{model}_{q}", ctypes.c_double)
        cf = CFunction(lib_f, f"{model}_{q}", ctypes.c_float)
        worst[q] = 0.0
        for x, p in points:
            # inputs rounded to float first, so the comparison measures the arithmetic only
            x32, p32 = x.astype(np.float32).astype(float), p.astype(np.float32).astype(float)
            for d, f in zip(cd(x32, p32), cf(x32, p32)):
                worst[q] = max(worst[q], rel_dev(f, d))
    record_property("float_vs_double_rel_dev", worst)
    print(f"{model}: float vs double max relative deviation "
          + ", ".join(f"{q} {d:.2e}" for q, d in worst.items()))
    assert max(worst.values()) > 0, "float build agrees bit for bit with double: casadi_real=float not honoured?"
    bad = {q: d for q, d in worst.items() if not d <= FLOAT_RTOL}
    assert not bad, f"{model}: single precision deviates by more than {FLOAT_RTOL}: {bad}"


@pytest.mark.parametrize("model", MODELS)
def test_no_hardcoded_double(model):
    """The only mention of ``double`` in the generated C is the overridable ``casadi_real`` default."""
    for suffix in (".c", ".h"):
        text = (generated_root() / model / f"{model}{suffix}").read_text()
        lines = [ln.strip() for ln in text.splitlines() if "double" in ln]
        assert lines == ["#define casadi_real double"], f"{model}{suffix}: {lines}"


def random_control_inputs(model: fjm_runtime.Model, kind: str, rng: np.random.Generator, count: int):
    """Random (x, z, r, p, gains) for ``control_<kind>``: flags 0/1, Hurwitz c, positive gains."""
    n = model.n
    entry = model.manifest["controls"][kind]
    nz = sum(b["size"] for b in entry["z"])
    for x, p in random_points(model, rng, count):
        if "measurement" in entry and entry["measurement"]["size"] == 6 * n:  # m = [x; tau_J; dtau_J] (6n)
            x = np.concatenate([x, rng.uniform(-50, 50, 2 * n)])
        elif "measurement" in entry:  # torque-sensed law: m = [q; dq; tau_J; dtau_J; dq_m] (5n)
            x = np.concatenate([x[:2 * n], rng.uniform(-50, 50, 2 * n), x[3 * n:]])
        z = rng.uniform(-1, 1, nz)
        if kind == "adaptive":  # positive K_hat and covariance
            z[n:2 * n] = rng.uniform(80, 220, n)
            z[5 * n:] = rng.uniform(1, 1e3, n)
        r = rng.uniform(-1, 1, 5 * n)
        lam = rng.uniform(2, 10)
        values = {"k_s": rng.uniform(0, 50, n), "delta": rng.uniform(0.5, 5, n), "k_lin": rng.uniform(0, 5, n),
                  "u_max": rng.uniform(1, 50, n), "beta_hat": (np.eye(n) * rng.uniform(0.01, 0.1)).ravel(),
                  "K_min": np.full(n, 100.0), "K_max": np.full(n, 200.0), "filter_rate": rng.uniform(5, 30),
                  "k_p": rng.uniform(10, 500, n), "k_d": rng.uniform(1, 20, n),
                  "K_p": rng.uniform(10, 2e3, n), "K_d": rng.uniform(1, 50, n), "K_T": rng.uniform(-0.9, 1, n),
                  "K_i": rng.uniform(0, 1e4, n), "K_q": rng.uniform(0, 2e3, n), "D_q": rng.uniform(0, 80, n)}
        for b in entry["gains"]:
            if b["size"] == 1 and b["name"] not in values:
                values[b["name"]] = float(rng.integers(0, 2))
            if b["name"] == "c":
                from math import comb
                values["c"] = np.array([comb(b["size"], k) * lam ** (b["size"] - k) for k in range(b["size"])])
        gains = np.concatenate([np.broadcast_to(values[b["name"]], (b["size"],)) for b in entry["gains"]])
        yield x, z, r, p, gains


@pytest.mark.parametrize("model", _params(CONTROL_MODELS))
def test_control_laws_c_equals_casadi(c_builds, model, record_property):
    """Every emitted law (and its _zdot part) in C equals its CasADi Function."""
    m = fjm_runtime.load(model)
    lib = ctypes.CDLL(str(c_builds[(model, "double")].lib))
    lib_f = ctypes.CDLL(str(c_builds[(model, "float")].lib)) if model in FLOAT_MODELS else None
    rng = np.random.default_rng(99 + MODELS.index(model))
    worst, worst_f = {}, {}
    for kind in m.manifest["controls"]:
        for name in [f"control_{kind}", f"control_{kind}_zdot"]:
            if name not in m.controls:
                continue
            fn = m.controls[name]
            cf = CFunction(lib, f"{model}_{name}", ctypes.c_double)
            cff = CFunction(lib_f, f"{model}_{name}", ctypes.c_float) if lib_f else None
            assert (cf.n_in, cf.n_out) == (fn.n_in(), fn.n_out()), name
            worst[name] = worst_f[name] = 0.0
            for args in random_control_inputs(m, kind, rng, 4):
                args = list(args)
                if name.endswith("_zdot"):
                    args += [rng.uniform(-60, 60, m.n), rng.uniform(-60, 60, m.n)]
                ref = fn(*args)
                ref = [ref] if fn.n_out() == 1 else ref
                ref = [np.asarray(ca.DM(v).full()) for v in ref]
                for r, g in zip(ref, cf(*args)):
                    assert np.all(np.isfinite(g)), name
                    worst[name] = max(worst[name], rel_dev(g, r))
                if cff is not None:
                    a32 = [np.asarray(a, dtype=np.float32).astype(float) for a in args]
                    for d, f in zip(cf(*a32), cff(*a32)):
                        worst_f[name] = max(worst_f[name], rel_dev(f, d))
    record_property("control_c_vs_casadi_rel_dev", worst)
    print(f"{model}: control laws C vs CasADi {worst}; float vs double {worst_f if lib_f else '-'}")
    bad = {q: d for q, d in worst.items() if not d <= C_RTOL}
    assert not bad, f"{model}: C control law differs from CasADi by more than {C_RTOL}: {bad}"
    bad = {q: d for q, d in worst_f.items() if not d <= FLOAT_RTOL}
    assert not bad, f"{model}: float control law deviates by more than {FLOAT_RTOL}: {bad}"


@pytest.mark.parametrize("model", _params(CONTROL_MODELS))
def test_feedforward_c_equals_casadi(c_builds, model, record_property):
    """``<model>_feedforward(r, p)`` in C equals its CasADi Function (every output) on random references."""
    m = fjm_runtime.load(model)
    fn = m.feedforward_function
    cf = CFunction(ctypes.CDLL(str(c_builds[(model, "double")].lib)), f"{model}_feedforward", ctypes.c_double)
    assert (cf.n_in, cf.n_out) == (fn.n_in(), fn.n_out()) == (2, 5)
    rng = np.random.default_rng(41 + MODELS.index(model))
    worst = 0.0
    for _, p in random_points(m, rng, N_STATES):
        r = rng.uniform(-1, 1, 5 * m.n)
        for ref, got in zip(fn(r, p), cf(r, p)):
            assert np.all(np.isfinite(got))
            worst = max(worst, rel_dev(got, ref.full()))
    record_property("feedforward_c_vs_casadi_rel_dev", worst)
    assert worst <= C_RTOL, f"{model}_feedforward: C differs from CasADi by {worst:.2e} (relative)"
