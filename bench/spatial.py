"""Spatial arm (the Panda): generated alpha + beta against the peer a user would build today.

The peer starts from the **same URDF** through adam-robotics' CasADi backend
(``adam.casadi.KinDynComputations``; version 0.5.0 models a floating base only,
so the base pose is the identity, the base velocity zero, and the joint block
``[6:, 6:]`` of the mass matrix and ``[6:]`` of the bias force are the
fixed-base ``D(q)`` and ``h(q, dq)``). The elastic model and every Lie
derivative are then CasADi AD, as in the planar AD peer (:mod:`bench.peers`)::

    y3 = D^-1 (-(h + K (q - q_m)))      (the same unpivoted LDL^T solve)
    f  = [dq; y3; dq_m; (K (q - q_m) - B_m dq_m) / J_m]
    y4 = jtimes(y3, x, f),   a = jtimes(y4, x, f)
    beta = J_m K^-1 D(q),    alpha = -beta a

Gravity is baked into adam's model (``gravity=[0, 0, -g0, 0, 0, 0]`` with the
model's default ``g0``) and adam knows nothing of the payload, so the comparison
uses the model's default parameters with ``m_load = 0``. Both sides go through
``ca.cse``, CasADi's code generator with the options ``make derive`` uses, gcc
with :data:`bench.ccutil.CFLAGS` and the same timing driver. Needs the ``bench``
extra (``adam-robotics``, ``liecasadi``).
"""
from __future__ import annotations

import contextlib
import io
import time
from pathlib import Path
from typing import Dict, Sequence, Tuple

import casadi as ca

from .alpha_beta import DRIVER, CompiledAlphaBeta, driver_defines
from .ccutil import compile_object, flags_tag, link_shared

REPO = Path(__file__).resolve().parent.parent


def adam_expressions(model) -> Tuple[ca.SX, ca.SX, Dict[str, ca.SX], float]:
    """SX ``(x, p, exprs, build_seconds)`` of the adam-robotics peer for a loaded spatial model.

    Parameters
    ----------
    model : fjm_runtime.Model
        A spatial model (``manifest["source"]`` names the URDF, base and joints).

    Returns
    -------
    x, p : casadi.SX
        State ``(4n,)`` and parameters in ``model.param_names`` order (only
        ``K*``, ``Jm*``, ``Bm*`` are used: gravity is baked, no payload).
    exprs : dict
        ``D``, ``h``, ``y3``, ``y4``, ``a``, ``alpha``, ``beta``.
    build_seconds : float
        Wall time to build the expressions (adam + AD).
    """
    from adam.casadi import KinDynComputations
    from derive.emit.ldl import ldl_factor, ldl_solve

    t0 = time.perf_counter()
    src = model.manifest["source"]
    urdf = Path(src["urdf"])
    if not urdf.is_absolute():
        urdf = REPO / urdf
    n = int(model.n)
    g0 = float(model.default_params["g0"])
    with contextlib.redirect_stderr(io.StringIO()):  # urdf_parser_py warns about Gazebo <dynamics> keys
        kd = KinDynComputations(str(urdf), list(src["joints"]), root_link=src["base"],
                                gravity=[0.0, 0.0, -g0, 0.0, 0.0, 0.0])
    x = ca.SX.sym("x", 4 * n)
    p = ca.SX.sym("p", len(model.param_names))
    names = list(model.param_names)
    K = ca.vertcat(*[p[names.index(f"K{i + 1}")] for i in range(n)])
    Jm = ca.vertcat(*[p[names.index(f"Jm{i + 1}")] for i in range(n)])
    Bm = ca.vertcat(*[p[names.index(f"Bm{i + 1}")] for i in range(n)])
    q, dq, qm, dqm = (x[i * n:(i + 1) * n] for i in range(4))
    H = ca.SX.eye(4)
    v0 = ca.SX.zeros(6)
    D = kd.mass_matrix(H, q)[6:, 6:]
    h = kd.bias_force(H, q, v0, dq)[6:]
    y3 = ldl_solve(ldl_factor(D), -(h + K * (q - qm)))
    f = ca.vertcat(dq, y3, dqm, (K * (q - qm) - Bm * dqm) / Jm)
    y4 = ca.jtimes(y3, x, f)
    a = ca.jtimes(y4, x, f)
    beta = ca.mtimes(ca.diag(Jm / K), D)
    alpha = -ca.mtimes(beta, a)
    exprs = {"D": D, "h": h, "y3": y3, "y4": y4, "a": a, "alpha": alpha, "beta": beta,
             "T": ca.vertcat(q, dq, y3, y4)}
    return x, p, exprs, time.perf_counter() - t0


def adam_functions(model) -> Tuple[Dict[str, ca.Function], float]:
    """``peer_adam_alpha/_beta(x, p)``, ``peer_adam_core(x, p) -> (y_hat, alpha, beta)`` (CSE'd) and the seconds
    to build the first two (adam + AD + CSE)."""
    t0 = time.perf_counter()
    x, p, e, _ = adam_expressions(model)
    out = {q: ca.Function(f"peer_adam_{q}", [x, p], [ca.cse(ca.vec(e[q]) if q == "alpha" else e[q])],
                          ["x", "p"], [q]) for q in ("alpha", "beta")}
    seconds = time.perf_counter() - t0
    out["core"] = ca.Function("peer_adam_core", [x, p], ca.cse([e["T"], ca.vec(e["alpha"]), e["beta"]]),
                              ["x", "p"], ["y_hat", "alpha", "beta"])
    return out, seconds


def _codegen(stem: str, fns, workdir: Path) -> Path:
    cg = ca.CodeGenerator(f"{stem}.c", {"with_header": True})  # the options of derive/emit/writer.py
    for fn in fns:
        cg.add(fn)
    return Path(cg.generate(str(workdir) + "/"))


def build_adam_peer(model, workdir: Path, extra: Sequence[str] = (), two_calls: bool = True):
    """Code-generate, compile and load the adam peer, as two calls (alpha, beta) and as one (its core).

    ``extra``: compiler flags after the bench's own. ``two_calls=False`` builds the core alone
    (the first of the returned peers is then None, and ``info`` has no C size nor gcc time).

    Returns
    -------
    (CompiledAlphaBeta, CompiledAlphaBeta, dict)
        The two-call and the one-call peer, and ``{"gcc_seconds", "c_bytes", "build_seconds", "ops"}``
        (C size and gcc time of alpha and beta; operations of alpha, beta and core).
    """
    from derive.emit.functions import operation_count
    workdir.mkdir(parents=True, exist_ok=True)
    fns, build_s = adam_functions(model)
    libs, info = {}, {"build_seconds": build_s, "ops": {q: operation_count(fns[q]) for q in fns}}
    suffix = flags_tag(extra)
    for stem, parts, one_call in (("peer_adam", ["alpha", "beta"], False), ("peer_adam_core", ["core"], True)):
        if not (one_call or two_calls):
            continue
        src = _codegen(stem, [fns[q] for q in parts], workdir)
        gcc_s = compile_object(src, workdir / f"{stem}{suffix}.o", extra)
        if not one_call:  # the size and compile time of alpha and beta, as for the generated ones
            info.update(gcc_seconds=gcc_s, c_bytes=src.stat().st_size)
        compile_object(DRIVER, workdir / f"driver_{stem}{suffix}.o", [*driver_defines(stem, one_call), *extra])
        lib = link_shared([workdir / f"{stem}{suffix}.o", workdir / f"driver_{stem}{suffix}.o"],
                          workdir / f"{stem}{suffix}.so")
        libs[one_call] = CompiledAlphaBeta(lib, model.n, model.nx)
    return libs.get(False), libs[True], info


def generated_alpha_beta_c(model, workdir: Path) -> Dict[str, float]:
    """C size and gcc time of the generated ``alpha`` and ``beta`` alone.

    The shipped ``<model>.c`` holds every function (control laws too); for a like-for-like size
    and compile time the two shipped ``.casadi`` Functions are code-generated
    alone with the same options.
    """
    workdir.mkdir(parents=True, exist_ok=True)
    src = _codegen(f"gen_ab_{model.name}", [model.functions["alpha"], model.functions["beta"]], workdir)
    gcc_s = compile_object(src, workdir / f"gen_ab_{model.name}.o")
    return {"c_bytes": src.stat().st_size, "gcc_seconds": gcc_s}
