"""Real drives on the Panda: ``panda_hd``'s datasheet springs and motor friction, the laws compared in Monte Carlo.

``panda_hd`` is the Panda on harmonic drives (three-segment datasheet springs, size 25 on joints 1-4 and
size 14 on 5-7, Coulomb/Stribeck motor friction; derive/robots/panda_hd). Every law runs in the sampled
loop of the shipped Panda design (``fjm_runtime/control/designed/panda_ismc_tau_1000hz_d1.json``: 1 kHz,
one sample of delay with prediction, the ``panda`` sensor preset, the demo's ready-pose sines, 10 s, its
torque-sensed ismc gains and the URDF effort limits) on TRUE drives drawn around the datasheet
(:func:`true_rows`: per joint the three stiffnesses x U(0.8, 1.2) together, the torque breakpoints x
U(0.8, 1.2), friction x U(0.5, 1.5), rotor x U(0.8, 1.2), payload U(0, 1) kg), and is judged by the
design thresholds (:class:`fjm_runtime.analysis.search.thresholds.Thresholds` defaults). The laws
(:data:`LAWS`), all with the same gains and NOMINAL parameters, the plant always the TRUE ``panda_hd``:

* ``curve + friction FF``: ``panda_hd``'s torque-sensed ismc at the datasheet values (the law derived for
  the nonlinear springs, compensating the nominal friction);
* ``curve + friction FF, panda_hd's own design``: the same law with the gains ``fjm design`` found for
  ``panda_hd`` (``fjm_runtime/control/designed/panda_hd_ismc_tau_1000hz_d1.json``, params
  ``examples/panda_hd_drives.toml``), the only row not on the Panda design's gains;
* ``curve, no friction FF``: the same law told ``F_c = F_s = 0``;
* ``linear K_1 + friction FF``: the same law told a linear spring at the first segment (``K_2 = K_3 = K_1``);
* ``panda (linear K) law``: the shipped design as it is, on the linear model ``panda`` (``K`` = 1e4 / 3e3),
  its predictor's ``q_m = q + tau_J / K``;
* ``PD + gravity``: ``panda``'s pdg law (motor PD about the set-point that holds gravity on linear springs)
  with :data:`PDG_GAINS`.

:func:`compare` is shared by ``examples/panda_drives.py`` (the 200-draw acceptance run) and the demo's
section :func:`panda_drives_section` (fewer draws).
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np

from ..drives import joint_coefficients, role_names
from .plots import write_figure

#: The compared laws: (label, model the law is built on, nominal edits of panda_hd's datasheet values, kind).
LAWS = (("curve + friction FF", "panda_hd", {}, "ismc"),
        ("curve + friction FF, panda_hd's own design", "panda_hd", {}, "ismc_hd"),
        ("curve, no friction FF", "panda_hd", {"F_c": 0.0, "F_s": 0.0}, "ismc"),
        ("linear K_1 + friction FF", "panda_hd", {"K_2": "K_1", "K_3": "K_1"}, "ismc"),
        ("panda (linear K) law", "panda", None, "ismc"),
        ("PD + gravity", "panda", None, "pdg"))

#: PD + gravity gains (motor side): k_p = 0.3 K of ``panda`` (3000 / 900 N m/rad), k_d = 2 sqrt(k_p J_m)
#: (critical damping of the rotor on k_p alone: 60 / 19 N m s/rad). No design stands behind them: the
#: baseline a user would write first.
PDG_GAINS = {"k_p": [3000.0] * 4 + [900.0] * 3, "k_d": [60.0] * 4 + [19.0] * 3}

#: The shipped design whose loop and gains every law uses.
DESIGN = ("panda", "ismc", "torque", 1000.0, 1)


def true_rows(model, draws: int, seed: int = 28) -> np.ndarray:
    """``draws`` TRUE parameter rows (``model.param_names`` order) around ``panda_hd``'s datasheet values.

    Per joint ``j``: ``K_1_j, K_2_j, K_3_j`` times one factor U(0.8, 1.2) (the curve keeps its order),
    ``T_1_j, T_2_j`` times another, ``F_c_j, F_s_j`` times U(0.5, 1.5), ``Jm<j>`` times U(0.8, 1.2); the
    payload ``m_load`` U(0, 1) kg. The blend width stays (within its limits at these factors).
    """
    rng = np.random.default_rng(seed)
    d = model.default_params
    n = model.n
    rows = []
    for _ in range(draws):
        p = dict(d)
        k, t, f, j = (rng.uniform(lo, hi, n) for lo, hi in ((0.8, 1.2), (0.8, 1.2), (0.5, 1.5), (0.8, 1.2)))
        for i, jm in enumerate(role_names(model, "rotor_inertia")):
            names = joint_coefficients(model, i)
            for factor, coefficients in ((k, ("K_1", "K_2", "K_3")), (t, ("T_1", "T_2")), (f, ("F_c", "F_s"))):
                p.update({names[c]: factor[i] * d[names[c]] for c in coefficients})
            p[jm] = j[i] * d[jm]
        p["m_load"] = rng.uniform(0.0, 1.0)
        rows.append(model.params_array(p))
    return np.array(rows)


def _nominal(hd, base, edits: Optional[dict]) -> Tuple[object, dict]:
    """``(model, nominal parameters)`` of a law: ``panda_hd`` with ``edits`` per joint, or ``panda``'s defaults."""
    if edits is None:
        from .. import load
        m = load("panda")
        return m, dict(m.default_params)
    d = dict(hd.default_params)
    for i in range(hd.n):
        names = joint_coefficients(hd, i)
        for k, v in edits.items():
            d[names[k]] = d[names[v]] if isinstance(v, str) else v
    return hd, d


def _controller(kind: str, model, nominal: dict, gains: dict, u_max):
    from ..control.factory import make_controller
    if kind == "pdg":
        return make_controller("pdg", model, nominal, u_max=u_max, **PDG_GAINS)
    if kind == "ismc_hd":  # panda_hd's own design
        from ..control.design import Design
        return make_controller("ismc", model, nominal, sensing="torque", u_max=u_max,
                               **Design.shipped("panda_hd", "ismc", "torque", 1000.0, 1).law_gains())
    return make_controller(kind, model, nominal, sensing="torque", u_max=u_max, **gains)


def _design_loop():
    """``(panda_hd, design, gains, u_max, reference, loop settings)`` of :data:`DESIGN`'s loop: its gains
    and limits, the demo's ready-pose sines from rest, 1 kHz, one sample of delay with prediction, ``panda``
    sensor (``loop``: the keywords :func:`simulate` and :func:`simulate_batch` share)."""
    from .. import load
    from ..control.design import Design
    from ..sim.sensor import SensorModel
    from . import panda as P
    hd = load("panda_hd")
    design = Design.shipped(*DESIGN)
    ref = P.reference(hd.n)
    loop = {"dt": 1e-3, "x0": P.rest_state(hd, ref(0.0)[0], None), "delay_samples": 1, "predict": True,
            "sensor": SensorModel.panda()}
    return hd, design, design.law_gains(), np.asarray(design.gains["u_max"], dtype=float), ref, loop


def compare(draws: int, duration: float = 10.0, seed: int = 28, progress=None) -> Dict[str, dict]:
    """Every law of :data:`LAWS` on the TRUE drives of :func:`true_rows`, one batch per law.

    Returns
    -------
    dict
        label -> ``{"rms", "jitter", "at_limit"}`` (per draw: the worst joint; jitter over joints 1-4, N m),
        ``"diverged"`` (count), ``"passed"`` (draws meeting every threshold), ``"rms_joint"`` (worst per joint),
        ``"model"``, ``"kind"``, ``"seconds"``; and the settings under ``"_settings"``.
    """
    from ..analysis.search.thresholds import Thresholds
    from ..batch.runner import simulate_batch
    hd, design, gains, u_max, ref, loop = _design_loop()
    rows = true_rows(hd, draws, seed)
    thr = Thresholds()
    jj = thr.joints(hd.n)
    out: Dict[str, dict] = {"_settings": {"draws": draws, "duration": duration, "seed": seed,
                                          "design": design.file, "thresholds": thr.as_dict(hd.n)}}
    for label, base, edits, kind in LAWS:
        if progress:
            progress(f"panda_hd real drives: {label}, {draws} drives")
        model, nominal = _nominal(hd, base, edits)
        ctrl = _controller(kind, model, nominal, gains, u_max)
        t0 = time.perf_counter()
        b = simulate_batch(hd, ctrl, ref, rows, duration=duration, seeds=seed + np.arange(draws), **loop)
        jm = {k: np.asarray(v, dtype=float) for k, v in b.joint_metrics.items()}
        div = np.asarray(b.diverged, dtype=bool)
        rms, jit, lim = jm["rms_second_half"].max(axis=1), jm["torque_jitter"][:, jj].max(axis=1), \
            jm["time_at_limit"].max(axis=1)
        ok = (~div) & (rms <= thr.max_rms) & (jit <= thr.max_jitter) & (lim <= thr.max_at_limit)
        out[label] = {"rms": rms.tolist(), "jitter": jit.tolist(), "at_limit": lim.tolist(),
                      "diverged": int(div.sum()), "passed": int(ok.sum()), "model": model.name, "kind": kind,
                      "rms_joint": np.where(div[:, None], np.inf, jm["rms_second_half"]).max(axis=0).tolist(),
                      "seconds": time.perf_counter() - t0}
    return out


def table(rows: Dict[str, dict]) -> List[str]:
    """The markdown table of :func:`compare` (worst over the draws; NaN/inf where a run diverged)."""
    s = rows["_settings"]
    t = s["thresholds"]
    head = [f"| law (nominal: the datasheet; the plant: TRUE panda_hd) | passed (of {s['draws']}) | diverged "
            f"| worst RMS e1 (rad, <= {t['max_rms']:g}) | median RMS | worst jitter j1-4 (N m, <= {t['max_jitter']:g}) "
            f"| worst at limit (<= {100 * t['max_at_limit']:g} %) |", "|---|---|---|---|---|---|---|"]
    body = []
    for label, r in rows.items():
        if label.startswith("_"):
            continue
        rms = np.asarray(r["rms"])
        body.append(f"| {label} | {r['passed']} | {r['diverged']} | {np.nanmax(rms):.3g} | {np.nanmedian(rms):.3g} "
                    f"| {np.nanmax(r['jitter']):.3g} | {100 * np.nanmax(r['at_limit']):.2f} % |")
    return head + body


def single_runs(duration: float, labels=("curve + friction FF", "panda (linear K) law")) -> Dict[str, object]:
    """The nominal drive (datasheet values, no payload) under the named laws, with trajectories (for the figure)."""
    from ..sim.simulate import simulate
    hd, _, gains, u_max, ref, loop = _design_loop()
    out = {}
    for label, base, edits, kind in LAWS:
        if label in labels:
            model, nominal = _nominal(hd, base, edits)
            out[label] = simulate(hd, _controller(kind, model, nominal, gains, u_max), ref, duration=duration, **loop)
    return out


def plot(runs: Dict[str, object], path: Path) -> Path:
    """Spring curves of joints 4 and 6 with the nominal run's deflections marked; |e1| per joint of each law."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from .. import load
    hd = load("panda_hd")
    n, pv, d = hd.n, hd.params_array(hd.default_params), hd.default_params
    fig, ax = plt.subplots(1, 1 + len(runs), figsize=(5 + 5 * len(runs), 3.8))
    phi = np.linspace(-6e-3, 6e-3, 601)
    psi = np.array([np.asarray(hd.spring_functions["spring"](np.full(n, v), pv)[0]).ravel() for v in phi])
    first = next(iter(runs.values()))
    defl = first.x[:, 2 * n:3 * n] - first.x[:, :n]
    for j, c in ((3, "C0"), (5, "C1")):  # the two joints whose runs work past their first breakpoint
        K_1 = d[joint_coefficients(hd, j)["K_1"]]
        ax[0].plot(1e3 * phi, psi[:, j], c, label=f"joint {j + 1} (K_1 {K_1:.3g} N m/rad)")
        ax[0].axvspan(1e3 * defl[:, j].min(), 1e3 * defl[:, j].max(), color=c, alpha=0.15)
    ax[0].set(xlabel="deflection q_m - q (mrad)", ylabel="tau_J (N m)", title="panda_hd springs (shaded: the run)")
    ax[0].legend(fontsize=8)
    for a, (label, r) in zip(ax[1:], runs.items()):
        for j in range(n):
            a.semilogy(r.t.ravel(), np.abs(r.e1[:, j]) + 1e-9, lw=0.7, label=f"joint {j + 1}")
        a.set(xlabel="t (s)", ylabel="|e1| (rad)", title=label, ylim=(1e-7, 1e-1))
        a.legend(fontsize=6, ncol=2)
    return write_figure(fig, path, tight=True)


def panda_drives_section(ctx) -> Tuple[List[str], list]:
    """The section of ``make demo``: ``panda_drives.png`` and the markdown lines."""
    t0 = time.perf_counter()
    draws, duration = (2, 2.0) if ctx.quick else (16, 10.0)
    rows = compare(draws, duration, progress=ctx.progress)
    fig = plot(single_runs(duration), ctx.out / "panda_drives.png")
    ctx.results["panda_drives"] = {k: {"passed": r["passed"], "worst_rms": max(r["rms"])}
                                   for k, r in rows.items() if not k.startswith("_")}
    md = ["## Real drives on the Panda (`panda_hd`)", "",
          "The Panda on harmonic drives (three-segment datasheet springs, Coulomb/Stribeck motor friction) in the "
          "loop of the shipped Panda design (1 kHz, one sample of delay with prediction, the `panda` sensor "
          f"preset, its gains and effort limits), {draws} TRUE drives off the datasheet (stiffness x0.8..1.2, "
          "breakpoints x0.8..1.2, friction x0.5..1.5, rotors x0.8..1.2, payload 0..1 kg), "
          f"{duration:g} s of the ready-pose sines, judged by the design thresholds:", "",
          *table(rows), "",
          "`examples/panda_drives.py` runs the 200-draw version (docs/real-drives.md). "
          + ("QUICK MODE: a smoke test, not the documented numbers. " if ctx.quick else "")
          + f"Figure: `{fig.name}` (two joints' curves with the nominal run's deflections, |e1| per joint). "
          f"{time.perf_counter() - t0:.0f} s.", ""]
    return md, [fig]
