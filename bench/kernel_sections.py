"""Sections ``alpha_beta`` and ``spatial``: the compiled alpha + beta of the generated code against the
CasADi AD peer (planar chains, :mod:`bench.alpha_beta`) and the adam-robotics peer (the Panda,
:mod:`bench.spatial`), checked at random states and through the timed loops' checksums."""
from __future__ import annotations

import json
import statistics
from pathlib import Path

import numpy as np

from .checks import TOLERANCES, check, rel_diff
from .timing import log

__all__ = ["AB_MODELS", "bench_alpha_beta", "bench_spatial", "timed_loop_error"]

REPO = Path(__file__).resolve().parent.parent
AB_MODELS = ("link1", "planar2", "planar4", "planar7")


def timed_loop_error(m, x, p, libs, iters: int = 8) -> float:
    """Relative error of the timed C loops' checksum against the ``.casadi`` Functions.

    The timed loop of each library calls alpha + beta ``iters`` times at ``x`` with
    ``x[0]`` nudged by ``1e-9 (k & 7)`` and sums ``alpha[0] + beta[0, 0]``; the same sum
    is formed here from the model's Functions, so a loop that times the wrong work fails.

    Parameters
    ----------
    m : fjm_runtime.Model
    x : numpy.ndarray, shape (4n,)
    p : numpy.ndarray, shape (len(m.param_names),)
    libs : sequence
        Timing libraries with ``timed_run(x, p, iters) -> (seconds, checksum)``.
    iters : int

    Returns
    -------
    float
        The largest relative checksum error over ``libs``.
    """
    want = 0.0
    for k in range(iters):
        xk = x.copy()
        xk[0] = x[0] + 1e-9 * (k & 7)
        want += float(m.alpha(xk, p)[0]) + float(m.beta(xk, p)[0, 0])
    return max(abs(lib.timed_run(x, p, iters)[1] - want) / max(1.0, abs(want)) for lib in libs)


def _pair_outputs_error(lib, xs, p, gen_out, refs) -> float:
    """Largest relative difference of ``lib``'s alpha and beta at the states ``xs`` from the generated C's
    (``gen_out``) and the ``.casadi`` ones (``refs``)."""
    err = 0.0
    for xi, (ga, gb), (ra, rb) in zip(xs, gen_out, refs):
        a, b = lib(xi, p)
        err = max(err, rel_diff(a, ga), rel_diff(b, gb), rel_diff(a, ra), rel_diff(b, rb))
    return err


def _ratio_entry(gen_us: float, peers_us: dict) -> dict:
    """``generated_us``, the fastest peer's ``peer_us`` and ``peer_variant``, and their ``ratio``."""
    best = min(peers_us, key=peers_us.get)
    return {"generated_us": gen_us, "peer_us": peers_us[best], "peer_variant": best,
            "ratio": gen_us / peers_us[best]}


def bench_alpha_beta(work: Path, reps: int, checks: list, models=AB_MODELS) -> dict:
    """alpha + beta of the planar chains: generated C vs the AD peers, in one call and in two.

    The headline figures (``generated_us``, ``peer_us``, ``ratio``) are one call of a core that
    returns both (``<model>_control_core``, what every law calls, against the peer's core with
    the same outputs, CSE'd together); ``two_calls`` holds the same for ``alpha`` then ``beta``.
    """
    import fjm_runtime
    from .alpha_beta import build_generated, build_peer, time_interleaved
    tol, tol_chk = TOLERANCES["alpha_beta"], TOLERANCES["alpha_beta_checksum"]
    variants = ("structured", "generic")
    res = {}
    for name in models:
        m = fjm_runtime.load(name)
        rng = np.random.default_rng(1)
        xs = [rng.normal(scale=0.5, size=m.nx) for _ in range(3)]
        x = xs[0]
        p = m.params_array()
        log(f"alpha+beta {name}: compiling generated and peers ...")
        gen = {form: build_generated(m, work / "ab", one_call=form == "one") for form in ("one", "two")}
        # the .casadi Functions (what fjm_runtime loads) at the test states
        refs = [(m.alpha(xi, p), m.beta(xi, p)) for xi in xs]
        gen_out = [gen["two"](xi, p) for xi in xs]
        err_c = max(_pair_outputs_error(lib, xs, p, gen_out, refs) for lib in gen.values())
        entry = {"generated_c_vs_casadi": err_c}
        check(checks, f"alpha_beta.{name}.generated_c",
              f"{name}: generated C (`generated/{name}/{name}.c`; alpha, beta and control_core) vs the generated "
              "`.casadi` Functions", err_c, tol)
        peers, libs = {}, {("generated", "one"): gen["one"], ("generated", "two"): gen["two"]}
        for variant in variants:
            for form in ("two", "one"):
                peer, gcc_s, c_bytes = build_peer(name, variant, work / "ab", m.n, m.nx, one_call=form == "one")
                err = _pair_outputs_error(peer, xs, p, gen_out, refs)
                if form == "two":
                    peers[variant] = {"gcc_seconds": gcc_s, "c_bytes": c_bytes, "max_rel_diff_vs_generated": err}
                else:
                    peers[variant]["max_rel_diff_vs_generated"] = max(peers[variant]["max_rel_diff_vs_generated"], err)
                libs[variant, form] = peer
            check(checks, f"alpha_beta.{name}.{variant}",
                  f"{name}: AD peer ({variant}; alpha, beta and its core) vs generated C and `.casadi`",
                  peers[variant]["max_rel_diff_vs_generated"], tol)
        # the timed loops compute what they claim: checksum of 8 calls vs the .casadi Functions
        chk_err = timed_loop_error(m, x, p, list(libs.values()))
        check(checks, f"alpha_beta.{name}.timed_loop",
              f"{name}: checksum of the timed C loops (generated and peers, one call and two) vs the `.casadi` "
              "Functions", chk_err, tol_chk)
        us = dict(zip(libs, time_interleaved(list(libs.values()), x, p, reps=3 * reps)))
        for variant in variants:
            peers[variant]["us"], peers[variant]["us_two_calls"] = us[variant, "one"], us[variant, "two"]
        entry.update(_ratio_entry(us["generated", "one"], {v: us[v, "one"] for v in variants}))
        entry["two_calls"] = _ratio_entry(us["generated", "two"], {v: us[v, "two"] for v in variants})
        entry["peers"] = peers
        res[name] = entry
        log(f"  {name}: one call: generated {entry['generated_us']:.3f} us, peer ({entry['peer_variant']}) "
            f"{entry['peer_us']:.3f} us; two calls: {entry['two_calls']['generated_us']:.3f} / "
            f"{entry['two_calls']['peer_us']:.3f} us")
    return res


def bench_spatial(work: Path, reps: int, checks: list, name: str = "panda") -> dict:
    """alpha + beta of the spatial ``name``: generated C vs the adam-robotics + CasADi AD peer.

    As :func:`bench_alpha_beta`: the headline is one call of a core returning both, ``two_calls``
    the same for ``alpha`` then ``beta``.
    """
    import fjm_runtime
    from .alpha_beta import build_generated, time_interleaved
    from .ccutil import compile_object
    from .spatial import build_adam_peer, generated_alpha_beta_c
    tol, tol_chk = TOLERANCES["alpha_beta"], TOLERANCES["alpha_beta_checksum"]
    m = fjm_runtime.load(name)
    p = m.params_array({"m_load": 0.0})  # adam knows no payload: compare without one
    rng = np.random.default_rng(1)
    xs = [rng.normal(scale=0.5, size=m.nx) for _ in range(3)]
    x = xs[0]
    log(f"spatial {name}: gcc -O2 of the shipped {name}.c (every function it ships) ...")
    obj = work / "spatial" / f"{name}.o"
    obj.parent.mkdir(parents=True, exist_ok=True)
    gcc_all = statistics.median(compile_object(REPO / "generated" / name / f"{name}.c", obj)
                                for _ in range(max(1, reps // 2)))
    gen, gen_one = (build_generated(m, work / "spatial", obj=obj, one_call=one) for one in (False, True))
    ab_only = [generated_alpha_beta_c(m, work / "spatial") for _ in range(max(1, reps // 2))]
    log(f"spatial {name}: building the adam-robotics peer (CasADi AD, CSE, codegen, gcc -O2) ...")
    peer, peer_one, info = build_adam_peer(m, work / "spatial")
    refs = [(m.alpha(xi, p), m.beta(xi, p)) for xi in xs]
    gen_out = [gen(xi, p) for xi in xs]
    err_c = max(_pair_outputs_error(lib, xs, p, gen_out, refs) for lib in (gen, gen_one))
    check(checks, f"spatial.{name}.generated_c",
          f"{name}: generated C (`generated/{name}/{name}.c`; alpha, beta and control_core) vs the generated "
          "`.casadi` Functions", err_c, tol)
    err = max(_pair_outputs_error(lib, xs, p, gen_out, refs) for lib in (peer, peer_one))
    check(checks, f"spatial.{name}.adam_peer",
          f"{name}: adam-robotics + CasADi AD peer (same URDF; alpha, beta and its core) vs generated C and "
          "`.casadi`", err, tol)
    libs = [gen_one, peer_one, gen, peer]
    chk_err = timed_loop_error(m, x, p, libs)
    check(checks, f"spatial.{name}.timed_loop",
          f"{name}: checksum of the timed C loops (generated and adam peer, one call and two) vs the `.casadi` "
          "Functions", chk_err, tol_chk)
    gen_us, peer_us, gen2_us, peer2_us = time_interleaved(libs, x, p, reps=3 * reps)
    log(f"  {name}: one call: generated {gen_us:.2f} us, adam peer {peer_us:.2f} us; "
        f"two calls: {gen2_us:.2f} / {peer2_us:.2f} us")
    native = _native_cores(m, work / "spatial", xs, p, refs, reps, checks)
    manifest = json.loads((REPO / "generated" / name / "manifest.json").read_text())
    return {
        "n": int(m.n),
        "generated_us": gen_us, "peer_us": peer_us, "ratio": gen_us / peer_us,
        "two_calls": {"generated_us": gen2_us, "peer_us": peer2_us, "ratio": gen2_us / peer2_us},
        "generated_c_bytes_all": int(manifest["c_sources"][f"{name}.c"]), "generated_gcc_seconds_all": gcc_all,
        "generated_c_bytes": int(ab_only[0]["c_bytes"]),
        "generated_gcc_seconds": statistics.median(a["gcc_seconds"] for a in ab_only),
        "generated_ops": {**{q: int(manifest["functions"][q]["operations"]) for q in ("alpha", "beta")},
                          "core": int(manifest["control_core"]["operations"])},
        "peer_c_bytes": int(info["c_bytes"]), "peer_gcc_seconds": info["gcc_seconds"],
        "peer_build_seconds": info["build_seconds"], "peer_ops": info["ops"],
        "max_rel_diff_peer_vs_generated": err,
        "native": native,
    }


#: Flags of the informative row compiled for the machine's own CPU (every target stays at the bench's ``-O2``).
NATIVE_FLAGS = ("-march=native",)


def _native_cores(m, work: Path, xs, p, refs, reps: int, checks: list) -> dict:
    """The one-call cores of the generated C and of the adam peer, both compiled with :data:`NATIVE_FLAGS` too.

    What a user gets by compiling for the robot computer's CPU (vector instructions of three
    operands, fused multiply-add): the same work, the same flags on both sides, interleaved. A
    compiler that refuses the flags leaves ``{"error": ...}``.
    """
    import subprocess
    from .alpha_beta import build_generated, time_interleaved
    from .spatial import build_adam_peer
    try:
        gen = build_generated(m, work, one_call=True, extra=NATIVE_FLAGS)
        peer = build_adam_peer(m, work, extra=NATIVE_FLAGS, two_calls=False)[1]
    except subprocess.CalledProcessError as exc:
        log(f"  {m.name}: {' '.join(NATIVE_FLAGS)} refused by the compiler ({exc}); not measured")
        return {"error": f"{' '.join(NATIVE_FLAGS)}: {exc}"}
    gen_out = [gen(xi, p) for xi in xs]
    err = max(_pair_outputs_error(lib, xs, p, gen_out, refs) for lib in (gen, peer))
    check(checks, f"spatial.{m.name}.native",
          f"{m.name}: generated C and adam peer compiled with `-O2 {' '.join(NATIVE_FLAGS)}` (one call) vs the "
          "`.casadi` Functions", err, TOLERANCES["alpha_beta"])
    gen_us, peer_us = time_interleaved([gen, peer], xs[0], p, reps=3 * reps)
    log(f"  {m.name}, -O2 {' '.join(NATIVE_FLAGS)}: one call: generated {gen_us:.2f} us, adam peer {peer_us:.2f} us")
    return {"flags": "-O2 " + " ".join(NATIVE_FLAGS), "generated_us": gen_us, "peer_us": peer_us,
            "ratio": gen_us / peer_us}
