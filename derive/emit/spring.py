"""Emit a model with nonlinear joint springs (:mod:`derive.core.spring`): CasADi Functions, C, manifest, report.

The same file names, Function names and signatures as a linear model (:mod:`derive.emit.writer`),
so ``fjm_runtime.load("link1_hd")`` gives the usual :class:`Model`:

* ``f, g, ad, T, alpha, beta, energy, inertia`` of ``(x, p)``: the explicit SymPy results of
  :func:`derive.core.spring.linearize_spring` converted to SX (the spring law substituted: ``psi``,
  ``psi'``, ``psi''`` of ``phi = q_m - q`` appear as polynomials in ``phi``), CSE'd;
* ``T_tau, alpha_tau, beta_tau`` of ``(m, p)``, ``m = [q; dq; tau_J; dtau_J; dq_m]``: ``tau_J`` and
  ``dtau_J`` read directly, ``psi'`` and ``psi''`` at the implied deflection
  ``phi_J = psi^-1(tau_J)``, the law's Newton steps unrolled from its start
  (:func:`derive.core.spring.newton_inverse`; ``newton_start``, ``newton_steps`` of each law);
* the laws ``control_{smc,ismc,fl}``, ``control_{smc,ismc,fl}_tau``, ``control_impedance`` and
  ``control_joint_impedance`` (:mod:`derive.emit.controls`,
  the same arithmetic around this model's cores). Not emitted: ``adaptive`` (it estimates a linear
  ``K``) and ``pdg`` (its motor set-point needs ``psi^-1(G(q_d))``);
* ``spring(phi, p) -> (psi, dpsi, ddpsi)`` and ``spring_inverse(tau_J, p) -> phi_J`` (the inverse map
  the torque laws use), listed under ``springs`` in the manifest;
* ``feedforward(r, p)``, the flatness feedforward through ``psi^-1`` (:mod:`derive.emit.feedforward`).

No timestamps or paths: the bytes depend on the model and the tool versions only.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Callable, Dict, List, Optional

import casadi as ca
import numpy as np
import sympy as sp

from ..core.linearize import Linearization
from .chain_json import write_chain_json
from .controls import FULL_SENSED_KINDS, KINDS, TORQUE_KINDS, build_core, law_pair, manifest_entry
from .impedance import IMPEDANCE_KINDS, build_impedance_laws
from .feedforward import build_feedforward
from .functions import QUANTITIES, operation_count
from .parameters import drive_table, parameter_entries
from .report import controllability_lines
from .spring_chain import (build_chain_functions, c_functions as chain_c_functions, cores as chain_cores,
                           inverse_sx_function, spring_sx_function)
from .sx import SympyToSX
from .torque import TORQUE_QUANTITIES
from .writer import (HEADER, argument_layout, argument_lines, comment_block, generate_c, tool_versions,
                     write_feedforward)

__all__ = ["EMITTED_KINDS", "build_spring_functions", "write_spring_model"]

#: The laws emitted for a nonlinear-spring model, in file order.
EMITTED_KINDS = ("smc", "ismc", "fl", "smc_tau", "ismc_tau", "fl_tau") + FULL_SENSED_KINDS

_MEANING = dict(KINDS + TORQUE_KINDS + IMPEDANCE_KINDS)

#: Quantities with their meaning for this model (the spring in them).
SPRING_QUANTITIES = (
    ("f", "drift vector field f(x), (4n,); link and motor rows carry psi(q_m - q)"),
    ("g", "input vector fields g(x) = [0; 0; 0; J_m^-1], (4n, n)"),
    ("ad", "brackets [g, ad_f g, ad_f^2 g, ad_f^3 g] (paper's sign), (4n, 4n); psi', psi'' in them"),
    ("T", "linearizing coordinates [q; dq; y3; y4], y3 = (psi(phi) - h)/J_l, y4 carries psi'(phi)(dq_m - dq), (4n,)"),
    ("alpha", "alpha(x) = -L_g y4^-1 L_f y4, (n,); psi, psi', psi'' of phi = q_m - q"),
    ("beta", "beta(x) = L_g y4^-1 = J_m D(q) / psi'(q_m - q), (n, n)"),
    ("energy", "total mechanical energy (links, motors, spring potential integral of psi, gravity), scalar"),
    ("inertia", "link inertia matrix D(q), (n, n)"),
)

_TORQUE_MEANING = {
    "T_tau": "linearizing coordinates from m = [q; dq; tau_J; dtau_J; dq_m]: [q; dq; y3; y4], "
             "y3 = D^-1 (tau_J - h), y4 = D^-1 (dtau_J - h'), no spring law in them, (4n,)",
    "alpha_tau": "alpha in torque coordinates, psi', psi'' at phi_J = psi^-1(tau_J) (Newton), (n,)",
    "beta_tau": "beta in torque coordinates: J_m D(q) / psi'(phi_J), phi_J = psi^-1(tau_J), (n, n)",
}


def build_spring_functions(lin: Linearization) -> Dict[str, ca.Function]:
    """Every SX Function of the model: quantities, torque functions, ``spring``, ``spring_inverse``.

    Returns
    -------
    dict str -> casadi.Function
        Keys: the names of :data:`derive.emit.functions.QUANTITIES` (inputs ``x``, ``p``), of
        :data:`derive.emit.torque.TORQUE_QUANTITIES` (inputs ``m``, ``p``), ``"spring"`` and
        ``"spring_inverse"``.
    """
    m = lin.model
    n, n_p = m.n, len(m.params)
    x, p = ca.SX.sym("x", 4 * n), ca.SX.sym("p", n_p)
    pbind = {s: p[j] for j, s in enumerate(m.param_symbols)}
    conv = SympyToSX({**{s: x[i] for i, s in enumerate(m.state)}, **pbind})
    out: Dict[str, ca.Function] = {}
    for name, _ in QUANTITIES:
        v = conv(lin.outputs[name])
        v = ca.vec(v) if v.shape[1] == 1 and name != "energy" else v
        out[name] = ca.Function(f"{m.name}_{name}", [x, p], [ca.cse(v)], ["x", "p"], [name])

    ms = ca.SX.sym("m", 5 * n)
    inverse = inverse_sx_function(m)
    phiJ = inverse(ms[2 * n:3 * n], p)
    tconv = SympyToSX({**{s: ms[i] for i, s in enumerate(lin.outputs["measurement"])}, **pbind,
                       **{s: phiJ[i] for i, s in enumerate(lin.outputs["implied"])}})
    for name, _ in TORQUE_QUANTITIES:
        v = tconv(lin.outputs[name])
        v = ca.vec(v) if v.shape[1] == 1 else v
        out[name] = ca.Function(f"{m.name}_{name}", [ms, p], [ca.cse(v)], ["m", "p"], [name])

    out["spring"], out["spring_inverse"] = spring_sx_function(m), inverse
    return out


def build_spring_laws(lin: Linearization, fns: Dict[str, ca.Function], feedforward: ca.Function,
                      cores: Optional[Dict[str, ca.Function]] = None) -> Dict[str, ca.Function]:
    """``control_core``, ``control_core_tau`` and the laws of :data:`EMITTED_KINDS` (with ``_zdot``);
    ``feedforward`` is the model's ``<model>_feedforward``, which the impedance law calls.

    ``cores``: the two cores, if the caller built them (several joints, :func:`derive.emit.spring_chain.cores`);
    else each is the model's Functions inlined and CSE'd together.
    """
    m = lin.model
    n, n_p = m.n, len(m.params)
    if cores is None:
        ms, p = ca.SX.sym("m", 5 * n), ca.SX.sym("p_hat", n_p)
        cores = {"control_core": build_core(m, fns),
                 "control_core_tau": ca.Function(
                     f"{m.name}_control_core_tau", [ms, p],
                     ca.cse([fns["T_tau"](ms, p), fns["alpha_tau"](ms, p), fns["beta_tau"](ms, p)]),
                     ["m", "p_hat"], ["y_hat", "alpha", "beta"])}
    core, core_tau = cores["control_core"], cores["control_core_tau"]
    out = {"control_core": core, "control_core_tau": core_tau}
    for kind in EMITTED_KINDS[:-len(FULL_SENSED_KINDS)]:
        tau = kind.endswith("_tau")
        out.update(law_pair(m, kind, core_tau if tau else core, (5 if tau else 4) * n, "m" if tau else "x", None))
    out.update(build_impedance_laws(m, feedforward))
    return out


def _ops(fn: ca.Function) -> int:
    return operation_count(fn.expand() if fn.is_a("MXFunction") else fn)


def _meaning(name: str) -> str:
    if name == "control_core":
        return "y_hat = T(x; p_hat), alpha(x; p_hat), beta(x; p_hat): the model part of every state law"
    if name == "control_core_tau":
        return "y_hat, alpha, beta of the torque measurement m (5n): the model part of every torque-sensed law"
    if name == "spring":
        return "the spring law: psi(phi), psi'(phi), psi''(phi) per joint (N m, N m/rad, N m/rad^2)"
    if name == "spring_inverse":
        return ("the implied deflection phi_J = psi^-1(tau_J) per joint (Newton steps from the law's start: "
                "manifest springs.inverse)")
    if name in _TORQUE_MEANING:
        return _TORQUE_MEANING[name]
    if name.endswith("_zdot"):
        return f"controller-state derivative of {name[len('control_'):-len('_zdot')]} under a held torque"
    return f"control law {name[len('control_'):]}: {_MEANING[name[len('control_'):]]}"


def _law_lines() -> List[str]:
    return [
        "control laws: <model>_control_<kind>(x, z, r, p, gains) -> (u, s, z_dot, u_cmd, y_hat), kinds smc ismc fl;",
        "  <model>_control_<kind>_tau(m, z, r, p, gains), m = [q; dq; tau_J; dtau_J; dq_m] (5n), tau_J = psi(q_m - q);",
        "  <model>_control_impedance, _joint_impedance(m, z, r, p, gains), m = [q; dq; q_m; dq_m; tau_J; dtau_J] (6n);",
        "  layouts of z and gains as link1's (manifest.json, controls); adaptive and pdg are not emitted.",
    ]


def write_spring_model(lin: Linearization, outdir: Path,
                       progress: Optional[Callable[[str], None]] = None) -> Dict[str, object]:
    """Emit every file of a nonlinear-spring model into ``outdir`` (see the module docstring); returns the manifest."""
    m = lin.model
    progress = progress or (lambda stage: None)
    outdir.mkdir(parents=True, exist_ok=True)
    chain = m.n > 1  # several joints: built from the inverse dynamics (derive/emit/spring_chain.py)
    progress("CasADi functions")
    fns = build_chain_functions(m) if chain else build_spring_functions(lin)
    parts = fns.pop("_parts", None)
    progress("control laws")
    ff_fn = build_feedforward(m, {k: fns[k] for k in ("spring", "spring_inverse")})
    laws = build_spring_laws(lin, fns, ff_fn, chain_cores(m, parts, ca.SX) if chain else None)
    versions = tool_versions()
    everything = {**fns, **laws}
    ops = {name: _ops(fn) for name, fn in everything.items()}
    sizes: Dict[str, int] = {}
    progress(".casadi files")
    for name, fn in everything.items():
        lines = [HEADER, f"model: {m.name}; function: {fn.name()} -- {_meaning(name) if name not in dict(SPRING_QUANTITIES) else dict(SPRING_QUANTITIES)[name]}",
                 f"tools: casadi {versions['casadi']}, sympy {versions['sympy']}", *argument_lines(lin)]
        if name.startswith("control_"):
            lines += _law_lines()
        text = comment_block(lines + [f"operations: {ops[name]}"], "# ") + fn.serialize() + "\n"
        (outdir / f"{name}.casadi").write_text(text)
        sizes[name] = len(text.encode())
    ff_fn, ops["feedforward"], ff_entry = write_feedforward(m, outdir, argument_lines(lin), versions, ff_fn)
    progress("C sources")
    c_fns = {**everything, "feedforward": ff_fn}
    if chain:  # the C file's twins call the kernel, spring and friction Functions instead of inlining them
        c_fns = {**everything, **chain_c_functions(m, parts),
                 **build_spring_laws(lin, fns, ff_fn, chain_cores(m, parts, ca.MX)), "feedforward": ff_fn}
    sources = _write_c(lin, outdir, c_fns, ops, versions)

    def entry(name, inputs, **extra):
        return {"casadi_file": f"{name}.casadi", "c_name": f"{m.name}_{name}", "meaning": _meaning(name),
                "inputs": inputs, **extra, "operations": ops[name], "casadi_bytes": sizes[name]}

    controls = _control_entries(m, laws, ops, entry)
    drives = drive_table(m)
    manifest = {
        "header": HEADER, "model": m.name, "description": m.description,
        **({"source": m.source} if m.source is not None else {}),  # URDF-built models only
        **(m.robot_facts or {}),  # "limits" and "task" of the robot's files
        "n": m.n, "nx": 4 * m.n,
        "parameters": parameter_entries(m, drives), "drives": drives,
        "arguments": argument_layout(lin),
        "functions": {name: {"casadi_file": f"{name}.casadi", "c_name": f"{m.name}_{name}", "meaning": meaning,
                             "shape": list(fns[name].size_out(0)), "operations": ops[name],
                             "casadi_bytes": sizes[name]} for name, meaning in SPRING_QUANTITIES},
        "controls": controls,
        "control_core": entry("control_core", ["x", "p_hat"], outputs=["y_hat", "alpha", "beta"],
                              shapes_out=[list(laws["control_core"].size_out(i)) for i in range(3)]),
        "torque_functions": {name: entry(name, ["m", "p"], shape=list(fns[name].size_out(0)))
                             for name, _ in TORQUE_QUANTITIES},
        "control_core_tau": entry("control_core_tau", ["m", "p_hat"], outputs=["y_hat", "alpha", "beta"],
                                  shapes_out=[list(laws["control_core_tau"].size_out(i)) for i in range(3)]),
        "measurement": {"m": "[q; dq; tau_J; dtau_J; dq_m] (5n): link position and rate, link-side joint torque "
                             "tau_J = psi(q_m - q) and its rate (measured), motor rate", "size": 5 * m.n},
        "springs": {
            "joints": [{"joint": s.joint, "law": s.kind, "psi": _psi_text(s),
                        "phi": "q_m - q", "parameters": [str(c) for c in s.parameters],
                        "deflection_range": [-s.deflection_range, s.deflection_range]} for s in m.springs],
            "inverse": {"method": "newton", "joints": [{"joint": s.joint, "steps": s.newton_steps,
                                                        "start": _start_text(s)} for s in m.springs]},
            "functions": {name: entry(name, inputs) for name, inputs in
                          (("spring", ["phi", "p"]), ("spring_inverse", ["tau_J", "p"]))},
        },
        "feedforward": ff_entry,
        "c_sources": {fname: len((outdir / fname).read_bytes()) for fname in sorted(sources)},
        "tools": versions,
        "derivation_seconds": "not stored here (would break byte-identity); see build/derive-timings.json",
    }
    write_chain_json(m, outdir)  # the rigid-body tree and the spring law, for the MJCF export
    progress("report")
    (outdir / "REPORT.md").write_text(_chain_report(m, fns, ops) if chain else _report(lin, ops))
    lines = json.dumps(manifest, indent=2).split("\n")
    (outdir / "manifest.json").write_text("\n".join(["{" + lines[1].strip()] + lines[2:]) + "\n")
    return manifest


def _write_c(lin: Linearization, outdir: Path, c_fns: Dict[str, ca.Function], ops: Dict[str, int],
             versions: Dict[str, str]) -> List[str]:
    """``<model>.c`` and ``<model>.h`` of ``c_fns`` with the header comment; returns their names."""
    m = lin.model
    with tempfile.TemporaryDirectory() as tmp:
        sources = generate_c(m.name, c_fns, Path(tmp))
    c_header = comment_block(
        [HEADER, f"model: {m.name} -- {m.description}", f"tools: casadi {versions['casadi']}, sympy {versions['sympy']}",
         *argument_lines(lin), *_law_lines(),
         "operations: " + ", ".join(f"{m.name}_{k} {v}" for k, v in ops.items())], " * ")
    for fname, body in sources.items():
        (outdir / fname).write_text("/* " + c_header[3:] + " */\n" + body)
    return list(sources)


def _start_text(spring) -> str:
    """Where a law's Newton inverse starts, in words (manifest)."""
    if spring.kind == "three_segment":
        return "the inverse of the datasheet's piecewise line (exact outside the blends)"
    return f"tau_J / {spring.start_stiffness}"


def _psi_text(spring) -> str:
    """The manifest's one-line statement of a spring law (its description without ``psi(phi) =``)."""
    return spring.describe().split("= ", 1)[-1]


def _control_entries(m, laws, ops, entry) -> Dict[str, dict]:
    """The manifest's ``controls``: one entry per emitted law (its zdot Function when stateful)."""
    controls = {}
    for kind in EMITTED_KINDS:
        first = "m" if kind.endswith("_tau") or kind in FULL_SENSED_KINDS else "x"
        e = entry(f"control_{kind}", [first, "z", "r", "p", "gains"], outputs=["u", "s", "z_dot", "u_cmd", "y_hat"])
        if f"control_{kind}_zdot" in laws:
            z = f"control_{kind}_zdot"
            e["zdot"] = {"casadi_file": f"{z}.casadi", "c_name": f"{m.name}_{z}",
                         "inputs": [first, "z", "r", "p", "gains", "u_cmd", "u"], "operations": ops[z]}
        e.update(manifest_entry(kind, m.n))
        if kind.endswith("_tau"):
            e["measurement"]["meaning"] = ("first argument is the torque measurement m (5n), not the state x; "
                                           "tau_J = psi(q_m - q), dtau_J its rate, both measured")
        controls[kind] = e
    return controls


def _chain_report(m, fns: Dict[str, ca.Function], ops: Dict[str, int]) -> str:
    """``REPORT.md`` of a several-joint drive model: parameters, springs, friction, the rank test, op counts."""
    k = {p.name: p.default for p in m.params}
    lines = [f"<!-- {HEADER} -->", f"# {m.name}", "", m.description, "",
             "## Parameters", "", "| name | default | unit | meaning |", "|---|---|---|---|"]
    lines += [f"| `{p.name}` | {p.default:g} | {p.unit} | {p.meaning} |" for p in m.params]
    lines += ["", "## Springs (`phi = q_m - q`)", "", "| joint | law | declared range (rad) | psi' on it (N m/rad) |",
              "|---|---|---|---|"]
    for s in m.springs:
        lo, hi = s.stiffness_bounds(k)
        lines.append(f"| {s.joint} | `{s.describe()}` | {s.deflection_range:g} | [{lo:g}, {hi:g}] |")
    if m.frictions:
        lines += ["", "## Motor friction", "", "At the link-side motor velocity `v = dq_m`, beside `B_m dq_m`; "
                  "`alpha` and `alpha_tau` add the nominal `F(dq_m)` (a feedforward).", ""]
        lines += [f"- joint {fr.joint}: `{fr.describe()}`" for fr in m.frictions]
    lines += ["", "## Derivation", "",
              "`D^-1` stays implicit: `y3, y4` and `w = D'' y3 + 2 D' y4 + h''` come from the time derivatives "
              "of the inverse dynamics (the model's kernel) at the spring torque `s = psi(phi)` and its rate "
              "`psi'(phi) dphi`; `beta = J_m psi'(phi)^-1 D(q)`, "
              "`alpha = psi + B_m dq_m + F + J_m y3 + J_m psi'^-1 (w - psi'' dphi^2)`; the torque-sensed laws read "
              "`tau_J`, `dtau_J` and take `psi'`, `psi''` at `phi_J = psi^-1(tau_J)`.", "",
              "## The paper's feedback-linearizability test, numerically", ""]
    ranges = [s.deflection_range for s in sorted(m.springs, key=lambda s: s.joint)]
    lines += controllability_lines(fns, m.n, np.array([p.default for p in m.params]), deflection=ranges)
    lines += ["", "## Operations", "", "| function | operations |", "|---|---|"]
    lines += [f"| `{m.name}_{name}` | {n} |" for name, n in ops.items()]
    return "\n".join(lines) + "\n"


def _report(lin: Linearization, ops: Dict[str, int]) -> str:
    """``REPORT.md``: the spring, the derived expressions (abstract psi), the paper's test, op counts."""
    m = lin.model
    a = lin.outputs["abstract"]
    chk = lin.outputs["check"]
    spring = m.springs[0]
    tex = lambda e: sp.latex(e)  # noqa: E731
    lines = [f"<!-- {HEADER} -->", f"# {m.name}", "", m.description, "",
             "## Parameters", "", "| name | default | unit | meaning |", "|---|---|---|---|"]
    lines += [f"| `{p.name}` | {p.default:g} | {p.unit} | {p.meaning} |" for p in m.params]
    r = spring.deflection_range
    k = {p.name: p.default for p in m.params}
    lo, hi = spring.stiffness_bounds(k)
    lines += ["", "## Spring", ""]
    if spring.kind == "cubic":
        lines += [f"`{spring.describe()}`, `phi = q_m - q`, declared range `|phi| <= {r:g} rad`. At the defaults "
                  f"`psi'(0) = {k['k1']:g}`, `psi'(0.1) = {k['k1'] + 3 * k['k3'] * 0.01:g}`, "
                  f"`psi'({r:g}) = {k['k1'] + 3 * k['k3'] * r * r:g}` N m/rad.", ""]
    else:
        lines += [f"`{spring.describe()}`, `phi = q_m - q`, declared range `|phi| <= {r:g} rad`. At the defaults "
                  f"`psi'` runs over [{lo:g}, {hi:g}] N m/rad on the range.", ""]
    for fr in m.frictions or ():
        lines += ["## Motor friction", "",
                  f"`{fr.describe()}` at the link-side motor velocity `v = dq_m`, beside `B_m dq_m`; `alpha` and "
                  "`alpha_tau` add the nominal `F(dq_m)` (a feedforward; nominal `F_c = F_s = 0` turns it off). "
                  "Derived with `F` abstract (`F_1 = F`, `F_1_d1 = F'`, ...), the law substituted at emission.", ""]
    lines += ["## Derived (psi_1 = psi, psi_1_d1 = psi', psi_1_d2 = psi'' of phi; F_1 = F of dq_m)", ""]
    for name in ("f", "T", "alpha", "beta", "ad", "T_tau", "alpha_tau", "beta_tau"):
        lines += [f"- `{name}`: $" + tex(a[name]) + "$"]
    lines += ["", "## The paper's feedback-linearizability test", "",
              "$\\det[g, ad_f g, ad_f^2 g, ad_f^3 g] = " + tex(chk["controllability"]) + "$: rank 4 exactly "
              "where $\\psi' \\ne 0$, i.e. on the whole declared range ($\\psi' > 0$ there).", "",
              "Involutivity of span$\\{g, ad_f g, ad_f^2 g\\}$: $\\det[g, ad_f g, ad_f^2 g, [v_i, v_j]]$ = "
              + ", ".join(f"{e} for $(v_{i}, v_{j})$" for (i, j), e in chk["involutive"])
              + " (every bracket lies in the span, for any $\\psi$).", "",
              "## Operations", "", "| function | operations |", "|---|---|"]
    lines += [f"| `{m.name}_{name}` | {n} |" for name, n in ops.items()]
    return "\n".join(lines) + "\n"
