"""The control laws, built in CasADi SX from a model's own ``T``, ``alpha`` and ``beta``.

One definition of each law, emitted with the model (``.casadi`` files and
``<model>.c/.h``) and used by every runtime path (NumPy, fused CasADi,
compiled, SIMD batch) and by the real-time C example. Every law has the
signature::

    <model>_control_<kind>(x, z, r, p, gains) -> (u, s, z_dot, u_cmd, y_hat)

* ``x`` (4n): plant state ``[q; dq; q_m; dq_m]`` (measured);
* ``z`` (:func:`state_layout`): controller state (empty for ``smc``, ``fl``);
* ``r`` (5n): reference and its four derivatives, rows stacked
  ``[y_d; y_d'; y_d''; y_d'''; y_d'''']`` (n each);
* ``p``: NOMINAL parameters in ``param_names`` order (the law's model);
* ``gains`` (:func:`gains_layout`): every tuning value, so retuning never
  needs a re-derive; flags are 0 or 1.

Outputs: ``u`` (n) applied torque (after the optional limit), ``s`` (n) the
sliding variable, ``z_dot`` the controller-state derivative at this sample,
``u_cmd`` (n) the torque before the limit, ``y_hat`` (4n) = ``T(x; p_hat)``.

The law (per joint, docs/design.md and README "Controllers")::

    y_hat = T(x; p_hat)                 p_hat = p, or with K replaced by clip(K_hat) (adaptive)
    e_i   = y_hat_i - r_i               i = 1..4
    s     = c1 e1 + c2 e2 + c3 e3 + e4              (smc, fl)
          = c0 z + c1 e1 + c2 e2 + c3 e3 + e4      (ismc, adaptive; z' = e1)
    nu    = r_5 - (c1 e2 + c2 e3 + c3 e4 [+ c0 e1]) - k_s psi(s) - k_lin s
    psi   = sign(s) if gains.sign else sat(s / delta)             (none for fl)
    u_cmd = alpha(x; p_hat) + B nu,      B = beta_hat if gains.use_beta_hat else beta(x; p_hat)
    u     = clip(u_cmd, -u_max, u_max) if gains.limit else u_cmd

The controller state moves under the torque held over the sample, so the
simulators also need ``z'`` at RK4 stage points with the sample's ``u_cmd``
and ``u``: ``<model>_control_<kind>_zdot(x, z, r, p, gains, u_cmd, u) -> z_dot``
(stateful kinds only) is that part of the law alone; the law's own ``z_dot``
is it evaluated with the law's ``u_cmd``, ``u``.
"""

from __future__ import annotations

from typing import Dict, List, Tuple

import casadi as ca

from .impedance import (FULL_MEASUREMENT, IMPEDANCE_KINDS, build_impedance_laws, impedance_gains_layout,
                        impedance_manifest, impedance_state_layout, split_blocks)
from .torque import pdg_gains_layout

#: Emitted laws, in file order, with their meaning.
KINDS: Tuple[Tuple[str, str], ...] = (
    ("smc", "paper's sliding-mode law (eqs 10-15), psi = sat(s/delta) or sign(s) (gains.sign)"),
    ("ismc", "integral sliding-mode law, z' = e1, conditional-integration anti-windup"),
    ("fl", "plain feedback linearization, nu = y_d'''' - (c1 e2 + c2 e3 + c3 e4) - k_lin s"),
    ("adaptive", "integral sliding-mode law with an online least-squares stiffness estimate K_hat"),
)

#: Torque-sensed laws (first argument ``m = [q; dq; tau_J; dtau_J; dq_m]``, 5n), in file order:
#: the state law of the same base kind with ``<model>_control_core_tau`` as its model part.
TORQUE_KINDS: Tuple[Tuple[str, str], ...] = (
    ("smc_tau", "torque-sensed smc: the smc law on T_tau, alpha_tau, beta_tau of m = [q; dq; tau_J; dtau_J; dq_m]"),
    ("ismc_tau", "torque-sensed ismc: the ismc law on T_tau, alpha_tau, beta_tau of m"),
    ("fl_tau", "torque-sensed fl: the fl law on T_tau, alpha_tau, beta_tau of m"),
)

#: The regulation law (motor PD + gravity compensation, Tomei), :func:`derive.emit.torque.build_pdg`.
PDG_KIND: Tuple[str, str] = (
    "pdg", "motor PD + gravity compensation (regulation to q_d = r[0:n]): "
           "u = k_p (q_d + K^-1 G(q_d) - q_m) - k_d dq_m + G(q_d); reads only q_m, dq_m of x")

#: Every emitted law, in file order: ``(kind, meaning)`` (the impedance laws: :mod:`derive.emit.impedance`).
ALL_KINDS: Tuple[Tuple[str, str], ...] = KINDS + TORQUE_KINDS + (PDG_KIND,) + IMPEDANCE_KINDS

#: The kinds whose first argument is the full measurement ``[q; dq; q_m; dq_m; tau_J; dtau_J]`` (6n).
FULL_SENSED_KINDS = tuple(kind for kind, _ in IMPEDANCE_KINDS)


def base_kind(kind: str) -> str:
    """The state law a torque-sensed kind shares its arithmetic, gains and ``z`` with (``ismc_tau`` -> ``ismc``)."""
    return kind[:-4] if kind.endswith("_tau") else kind


#: Names of the blocks of the adaptive estimator state, in order (after z_int).
ESTIMATOR_BLOCKS = ("K_hat", "u_f", "phi_f", "w_f", "P")


def gains_layout(kind: str, n: int) -> List[Tuple[str, int, str]]:
    """Blocks of the ``gains`` vector of ``control_<kind>``: ``(name, size, meaning)`` in order.

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`.
    n : int
        Number of joints.

    Returns
    -------
    list of (str, int, str)
    """
    if kind == "pdg":
        return pdg_gains_layout(n)
    if kind in FULL_SENSED_KINDS:
        return impedance_gains_layout(kind, n)
    kind = base_kind(kind)
    integral = kind in ("ismc", "adaptive")
    out = [("c", 4 if integral else 3,
            "surface coefficients, lowest first: [c0, c1, c2, c3]" if integral else
            "surface coefficients, lowest first: [c1, c2, c3]")]
    if kind != "fl":
        out += [("k_s", n, "switching gain per joint (rad/s^4), >= 0"),
                ("delta", n, "boundary-layer width per joint, > 0 (used when sign = 0)"),
                ("sign", 1, "1: psi = sign(s) (eq 15); 0: psi = sat(s / delta)")]
    out += [("k_lin", n, "linear feedback on s per joint (1/s), >= 0"),
            ("u_max", n, "torque limit per joint (N m), > 0 (used when limit = 1)"),
            ("limit", 1, "1: u = clip(u_cmd, -u_max, u_max); 0: u = u_cmd")]
    if integral:
        out += [("anti_windup", 1, "1: freeze z_i while u_cmd_i is beyond u_max_i and e1_i pushes further")]
    out += [("use_beta_hat", 1, "1: B = beta_hat; 0: B = beta(x; p_hat)"),
            ("beta_hat", n * n, "constant beta estimate, (n, n) column-major")]
    if kind == "adaptive":
        out += [("K_min", n, "stiffness lower bound per joint (N m/rad)"),
                ("K_max", n, "stiffness upper bound per joint (N m/rad)"),
                ("filter_rate", 1, "regressor filter bandwidth a of a/(s + a) (1/s)")]
    return out


def state_layout(kind: str, n: int) -> List[Tuple[str, int, str]]:
    """Blocks of the controller state ``z`` of ``control_<kind>``: ``(name, size, meaning)``."""
    if kind in FULL_SENSED_KINDS:
        return impedance_state_layout(kind, n)
    kind = base_kind(kind)
    if kind == "ismc":
        return [("z_int", n, "integral of e1 = q - y_d (rad s)")]
    if kind == "adaptive":
        return [("z_int", n, "integral of e1 = q - y_d (rad s)"),
                ("K_hat", n, "stiffness estimate (N m/rad)"),
                ("u_f", n, "filtered applied torque"),
                ("phi_f", n, "filtered deflection q_m - q"),
                ("w_f", n, "filtered motor rate dq_m"),
                ("P", n, "least-squares covariance")]
    return []


def _stiffness_indices(model) -> Tuple[List[int], List[int], List[int]]:
    """Indices in ``p`` of each joint's K, J_m and B_m (each must be a plain parameter)."""
    syms = list(model.param_symbols)
    out = []
    for what, exprs in (("K", model.K), ("J_m", model.Jm), ("B_m", model.Bm)):
        idx = []
        for i, e in enumerate(exprs):
            if e not in syms:
                raise ValueError(f"model {model.name}: {what} of joint {i + 1} is {e}, not a parameter; "
                                 "the adaptive law needs it as a plain parameter")
            idx.append(syms.index(e))
        out.append(idx)
    return tuple(out)


def _sat(v):
    return ca.fmin(ca.fmax(v, -1.0), 1.0)


def _zdot(kind, n, x, z, r, p, g, u_cmd, u, idx) -> ca.SX:
    """Controller-state derivative under the held ``u_cmd``, ``u`` (the one definition)."""
    T = type(x)  # SX or MX: the same definition builds both
    if kind not in ("ismc", "adaptive"):
        return T(0, 1)
    e1 = x[:n] - r[:n]
    um = g["u_max"]
    winding = g["limit"] * g["anti_windup"] * ((u_cmd > um) * (e1 < 0) + (u_cmd < -um) * (e1 > 0))
    dz_int = ca.if_else(winding, T.zeros(n), e1)
    if kind == "ismc":
        return dz_int
    zb = split_blocks(z, state_layout(kind, n))
    iK, iJ, iB = idx
    J_m = ca.vertcat(*[p[i] for i in iJ])
    B_m = ca.vertcat(*[p[i] for i in iB])
    a = g["filter_rate"]
    lo, hi = g["K_min"], g["K_max"]
    q_l, q_m, dq_m = x[0:n], x[2 * n:3 * n], x[3 * n:4 * n]
    K_hat, u_f, phi_f, w_f, P = (zb[b] for b in ESTIMATOR_BLOCKS)
    y_f = u_f - J_m * a * (dq_m - w_f) - B_m * w_f
    eps = y_f - ca.fmin(ca.fmax(K_hat, lo), hi) * phi_f
    upd = P * phi_f * eps
    outward = (K_hat >= hi) * (upd > 0) + (K_hat <= lo) * (upd < 0)
    return ca.vertcat(dz_int,
                      upd * (1 - outward),
                      a * (u - u_f),
                      a * ((q_m - q_l) - phi_f),
                      a * (dq_m - w_f),
                      -(P * P) * (phi_f * phi_f))


def _law(kind, n, core, x, z, r, p, g, idx):
    integral = kind in ("ismc", "adaptive")
    blk = lambda v, i: v[i * n:(i + 1) * n]  # noqa: E731
    if kind == "adaptive":
        zb = split_blocks(z, state_layout(kind, n))
        K_use = ca.fmin(ca.fmax(zb["K_hat"], g["K_min"]), g["K_max"])
        entries = [p[j] for j in range(p.shape[0])]
        for i, j in enumerate(idx[0]):
            entries[j] = K_use[i]
        p_hat = ca.vertcat(*entries)
    else:
        p_hat = p
    y_hat, alpha, beta = core(x, p_hat)
    e = [blk(y_hat, i) - blk(r, i) for i in range(4)]
    chain = ([z[:n]] if integral else []) + e
    c = g["c"]
    m = c.shape[0]
    s = c[0] * chain[0]
    linear = c[0] * chain[1]
    for j in range(1, m):
        s = s + c[j] * chain[j]
        linear = linear + c[j] * chain[j + 1]
    s = s + chain[m]
    nu = blk(r, 4) - linear
    if kind != "fl":
        psi = ca.if_else(g["sign"], ca.sign(s), _sat(s / g["delta"]))
        nu = nu - g["k_s"] * psi
    nu = nu - g["k_lin"] * s
    B = ca.if_else(g["use_beta_hat"], ca.reshape(g["beta_hat"], n, n),
                   ca.reshape(beta, n, n))
    u_cmd = alpha + ca.mtimes(B, nu)
    um = g["u_max"]
    u = ca.if_else(g["limit"], ca.fmin(ca.fmax(u_cmd, -um), um), u_cmd)
    return u, s, u_cmd, y_hat


def build_core(model, functions: Dict[str, ca.Function], body=None) -> ca.Function:
    """``<model>_control_core(x, p_hat) -> (y_hat, alpha, beta)``: the model part every law shares.

    One SX Function, ``T``, ``alpha`` and ``beta`` inlined and jointly CSE'd; the laws
    call it. ``beta`` is ``(n, n)`` as ``<model>_beta``. ``body(x, p) -> (y_hat, alpha, beta)``,
    if given, computes the three in one go (one kernel call, :mod:`derive.emit.dynamics`)
    instead of inlining ``T``, ``alpha`` and ``beta`` separately.
    """
    x = ca.SX.sym("x", 4 * model.n)
    p = ca.SX.sym("p_hat", len(model.params))
    outs = ca.cse(list(body(x, p)) if body is not None else
                  [functions["T"](x, p), functions["alpha"](x, p), functions["beta"](x, p)])
    return ca.Function(f"{model.name}_control_core", [x, p], outs,
                       ["x", "p_hat"], ["y_hat", "alpha", "beta"])


def law_pair(model, kind: str, core: ca.Function, n_meas: int, first: str, idx) -> Dict[str, ca.Function]:
    """``control_<kind>`` (MX, calling ``core`` once) and, when stateful, ``control_<kind>_zdot`` (SX).

    ``first`` names the first argument (``x``, 4n, or ``m``, 5n); ``kind`` may be a torque
    kind, whose arithmetic, gains and ``z`` are those of :func:`base_kind`.
    """
    n = model.n
    n_par = len(model.params)
    base = base_kind(kind)
    glay, zlay = gains_layout(kind, n), state_layout(kind, n)
    nz, ng = sum(b[1] for b in zlay), sum(b[1] for b in glay)
    x, z, r = ca.MX.sym(first, n_meas), ca.MX.sym("z", nz), ca.MX.sym("r", 5 * n)
    p, gains = ca.MX.sym("p", n_par), ca.MX.sym("gains", ng)
    g = split_blocks(gains, glay)
    u, s, u_cmd, y_hat = _law(base, n, core, x, z, r, p, g, idx)
    z_dot = _zdot(base, n, x, z, r, p, g, u_cmd, u, idx)
    out = {f"control_{kind}": ca.Function(
        f"{model.name}_control_{kind}", [x, z, r, p, gains], [u, s, z_dot, u_cmd, y_hat],
        [first, "z", "r", "p", "gains"], ["u", "s", "z_dot", "u_cmd", "y_hat"])}
    if zlay:
        xs, zs, rs = ca.SX.sym(first, n_meas), ca.SX.sym("z", nz), ca.SX.sym("r", 5 * n)
        ps, gs = ca.SX.sym("p", n_par), ca.SX.sym("gains", ng)
        uc, uu = ca.SX.sym("u_cmd", n), ca.SX.sym("u", n)
        zd = ca.cse(_zdot(base, n, xs, zs, rs, ps, split_blocks(gs, glay), uc, uu, idx))
        out[f"control_{kind}_zdot"] = ca.Function(
            f"{model.name}_control_{kind}_zdot", [xs, zs, rs, ps, gs, uc, uu], [zd],
            [first, "z", "r", "p", "gains", "u_cmd", "u"], ["z_dot"])
    return out


def build_controls(model, functions: Dict[str, ca.Function],
                   torque: Dict[str, ca.Function] = None, core: ca.Function = None,
                   core_body=None, feedforward: ca.Function = None) -> Dict[str, ca.Function]:
    """Every law of :data:`ALL_KINDS` (and the ``_zdot`` parts of stateful ones), and their shared cores.

    Parameters
    ----------
    model : derive.core.model_base.FlexibleJointModel
    functions : dict str -> casadi.Function
        The model's SX Functions (``T``, ``alpha``, ``beta`` are used, inlined into the core).
    torque : dict str -> casadi.Function, optional
        ``control_core_tau`` and ``control_pdg`` (:mod:`derive.emit.torque`); without it only
        the state laws of :data:`KINDS` are built.

    Returns
    -------
    dict str -> casadi.Function
        ``"control_core"`` -> ``<model>_control_core`` (:func:`build_core`, SX);
        ``"control_<kind>"`` -> ``<model>_control_<kind>``: an MX Function calling the core
        once, with the law's own arithmetic around the call (call it with SX arguments, or
        ``expand()`` it, to inline everything); for ``ismc`` and ``adaptive``,
        ``"control_<kind>_zdot"`` -> ``<model>_control_<kind>_zdot`` (SX, no model part).
        With ``torque``: ``"control_core_tau"``, the laws of :data:`TORQUE_KINDS` (first
        argument ``m``, 5n, calling ``control_core_tau``; ``ismc_tau`` with its ``_zdot``)
        and ``"control_pdg"``.
    core : casadi.Function, optional
        The ``control_core`` the laws call instead of :func:`build_core` (the C file's MX
        twin, :func:`derive.emit.writer.c_functions`).
    core_body : callable, optional
        ``body`` of :func:`build_core`.
    feedforward : casadi.Function, optional
        The model's ``<model>_feedforward``: with it, the laws of
        :data:`~derive.emit.impedance.IMPEDANCE_KINDS` and their ``_zdot``
        (:func:`derive.emit.impedance.build_impedance_laws`).
    """
    n = model.n
    idx = _stiffness_indices(model)
    core = build_core(model, functions, core_body) if core is None else core
    out: Dict[str, ca.Function] = {"control_core": core}
    for kind, _ in KINDS:
        out.update(law_pair(model, kind, core, 4 * n, "x", idx))
    if torque is not None:
        out["control_core_tau"] = torque["control_core_tau"]
        for kind, _ in TORQUE_KINDS:
            out.update(law_pair(model, kind, torque["control_core_tau"], 5 * n, "m", idx))
        out["control_pdg"] = torque["control_pdg"]
    if feedforward is not None:
        out.update(build_impedance_laws(model, feedforward))
    return out


def layout_lines(n: int) -> List[str]:
    """Comment lines documenting the arguments of the control laws (for the headers)."""
    lines = [
        "control laws: <model>_control_<kind>(x, z, r, p, gains) -> (u, s, z_dot, u_cmd, y_hat)",
        "  x: plant state (4n) as above; p: NOMINAL parameters (the law's model) as above",
        "  r: reference and 4 derivatives, rows stacked (5n): [y_d; y_d'; y_d''; y_d'''; y_d'''']",
        "  u: applied torque (n); s: sliding variable (n); z_dot: controller-state derivative;",
        "  u_cmd: torque before the limit (n); y_hat: T(x; p_hat) (4n). Flags are 0.0 or 1.0.",
        "  <model>_control_<kind>_zdot(x, z, r, p, gains, u_cmd, u) -> z_dot: the state part alone",
        "  (stateful kinds), for integrating z under a held torque.",
        "  <model>_control_core(x, p_hat) -> (y_hat (4n), alpha (n), beta (n, n) column-major): the model",
        "  part every law calls (p_hat in p's layout: p, or K replaced by clip(K_hat) for adaptive).",
    ]
    lines += [
        "  torque-sensed laws <model>_control_<kind>_tau(m, z, r, p, gains) (smc, ismc, fl): first argument",
        "  m = [q; dq; tau_J; dtau_J; dq_m] (5n), tau_J = K (q_m - q) measured; z, gains, outputs as control_<kind>;",
        "  they call <model>_control_core_tau(m, p_hat) -> (y_hat (4n), alpha (n), beta (n, n)).",
        "  <model>_control_pdg(x, z, r, p, gains): regulation to q_d = r[0:n]; z empty; s = q_md - q_m",
        "  (motor set-point error); y_hat = [q; dq; 0; 0] (placeholder); u reads only q_m, dq_m.",
        f"  <model>_control_impedance, _joint_impedance(m, z, r, p, gains): m = {FULL_MEASUREMENT} (6n);",
        "  impedance calls <model>_feedforward(r, p), s = theta_d - q_m; joint_impedance outputs the link-side",
        "  torque without gravity, s = q_d - q; y_hat = [q; dq; 0; 0] (placeholder).",
    ]
    for kind, meaning in ALL_KINDS:
        lines.append(f"  control_{kind}: {meaning}")
        zl = state_layout(kind, n)
        lines.append("    z: " + (_offsets(zl) if zl else "(empty)"))
        lines.append("    gains: " + _offsets(gains_layout(kind, n)))
    return lines


def _offsets(layout) -> str:
    parts, k = [], 0
    for name, size, _ in layout:
        parts.append(f"{k}:{name}" if size == 1 else f"{k}-{k + size - 1}:{name}")
        k += size
    return " ".join(parts)


def manifest_entry(kind: str, n: int) -> Dict[str, object]:
    """The manifest's description of ``control_<kind>``'s ``z`` and ``gains`` layouts."""
    def table(layout):
        rows, k = [], 0
        for name, size, meaning in layout:
            rows.append({"name": name, "offset": k, "size": size, "meaning": meaning})
            k += size
        return rows
    entry: Dict[str, object] = {"z": table(state_layout(kind, n)), "gains": table(gains_layout(kind, n))}
    if kind.endswith("_tau"):
        entry["measurement"] = {"argument": "m", "size": 5 * n, "layout": "[q; dq; tau_J; dtau_J; dq_m]",
                                "meaning": "first argument is the torque measurement m (5n), not the state x; "
                                           "tau_J = K (q_m - q), dtau_J its rate, both measured",
                                "state_law": base_kind(kind)}
    if kind in FULL_SENSED_KINDS:
        entry.update(impedance_manifest(kind, n))
    if kind == "pdg":
        entry["regulation"] = {"reads": "q_m, dq_m of x (motor side only)", "set_point": "r[0:n]",
                               "s": "q_md - q_m, motor set-point error (rad)",
                               "y_hat": "[q; dq; 0; 0], a placeholder for the linearizing coordinates"}
    return entry
