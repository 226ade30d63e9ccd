"""The demo's real-arm section: the Panda at 1 kHz with delay, sensor noise and unknown K, J_m, payload.

Conditions of a real torque-controlled arm: the controller runs at :data:`RATE` (1 kHz) with a
computation delay of :data:`DELAY` sample, reads noisy sensors (:meth:`SensorModel.panda_white`), and
knows only the NOMINAL parameters; the TRUE plant (integrated on substeps, zero-order hold) has
per-joint stiffness ``K = K_nom x U[0.7, 1.3]``, motor inertia ``J_m x U[0.8, 1.2]`` and an unknown
payload of 0-1 kg (:func:`draws`: :data:`N_RANDOM` random draws plus three corner draws). Four
controllers run side by side on the same draws and noise seeds (:data:`CONTROLLERS`): the
state-feedback integral SMC, the torque-sensed integral SMC without and with delay
compensation (prediction), and the motor PD + gravity compensation (a regulation law; here its
set point is the moving reference). :func:`real_arm_section` writes the figure and the table.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np

from ..analysis.certificates.certify_tau import gamma_tolerance
from ..control import defaults
from ..control.design import Design
from ..control.factory import make_controller
from ..drives import role_names
from ..sim.metrics import rms_second_half, time_at_limit, torque_jitter
from ..sim.sensor import SensorModel
from ..sim.rest import rest_state
from ..sim.simulate import simulate
from ..sim.step import SimulationDivergedError
from .panda import AMPLITUDE, DIVERGED_ERROR, PANDA_EFFORT, READY, reference
from .plots import write_figure

RATE = 1000.0          # Hz, the Panda's control rate
DELAY = 1              # samples of computation delay
DURATION = 5.0         # s per run (the documented numbers)
N_RANDOM = 20          # random draws (plus the three corners)
QUICK_DRAWS = 2        # quick mode (smoke test): one random draw and the all-0.7 corner, casadi backend
QUICK_DURATION = 1.0
SEED = 2026

#: label -> (kind, sensing, predict)
CONTROLLERS = {
    "state-feedback ismc": ("ismc", "state", False),
    "torque-sensed ismc": ("ismc", "torque", False),
    "torque-sensed ismc + prediction": ("ismc", "torque", True),
    "motor PD + gravity": ("pdg", "state", False),
}

#: Motor PD + gravity gains (stated, not tuned): k_p about 0.1 K_nom per joint, k_d = 2 sqrt(k_p J_m).
PDG_GAINS = {"k_p": (1000.0,) * 4 + (300.0,) * 3, "k_d": (35.0,) * 4 + (11.0,) * 3}


def ismc_gains(rate: float = RATE, delay: int = DELAY) -> Tuple[dict, str]:
    """``(gains, source)`` of the integral SMC: the designed gains for (panda, ismc, torque, rate, delay)
    when they are shipped (:meth:`Design.shipped`), else the hand-found starting point."""
    design = Design.shipped("panda", "ismc", "torque", rate, delay)
    if design:  # the limit is the arm's own PANDA_EFFORT, set in controller()
        return design.law_gains(), f"designed gains (`fjm design`, panda, ismc, torque, {rate:g} Hz, delay {delay})"
    return (dict(defaults.PANDA_ISMC_TAU_START),
            "hand-found gains (quadruple pole 80 1/s, k_lin 400 1/s, k_s 2000, delta 10), NOT the result of a search")


def draws(model, n_random: int = N_RANDOM, seed: int = SEED) -> List[dict]:
    """The TRUE plants: ``[{label, params (dict), K_ratio (n,), Jm_ratio (n,), seed}]``, ``n_random`` random ones then the corners.

    Random: ``K_i = K_nom,i x U[0.7, 1.3]``, ``J_m,i x U[0.8, 1.2]`` per joint, ``m_load ~ U[0, 1]`` kg.
    Corners: all 0.7 with ``J_m x 0.8``, all 1.3 with ``J_m x 1.2``, alternating 0.7/1.3 with
    ``J_m x 0.8``; each with the 1 kg payload.
    """
    n = int(model.n)
    p0 = model.default_params
    rng = np.random.default_rng(seed)

    def plant(kf, jf, load):
        p = dict(p0)
        p.update({k: p0[k] * kf[i] for i, k in enumerate(role_names(model, "stiffness"))})
        p.update({j: p0[j] * jf[i] for i, j in enumerate(role_names(model, "rotor_inertia"))})
        p["m_load"] = float(load)
        return p, np.asarray(kf, dtype=float), np.asarray(jf, dtype=float)

    specs = [(f"random {k + 1}", rng.uniform(0.7, 1.3, n), rng.uniform(0.8, 1.2, n), rng.uniform(0.0, 1.0))
             for k in range(n_random)]
    alt = np.where(np.arange(n) % 2 == 0, 0.7, 1.3)
    specs += [("K x 0.7, J_m x 0.8, 1 kg", np.full(n, 0.7), np.full(n, 0.8), 1.0),
              ("K x 1.3, J_m x 1.2, 1 kg", np.full(n, 1.3), np.full(n, 1.2), 1.0),
              ("K alternating 0.7/1.3, J_m x 0.8, 1 kg", alt, np.full(n, 0.8), 1.0)]
    out = []
    for k, (label, kf, jf, load) in enumerate(specs):
        p, kr, jr = plant(kf, jf, load)
        out.append({"label": label, "params": p, "K_ratio": kr, "Jm_ratio": jr, "seed": seed + k})
    return out


def controller(label: str, model, gains: dict):
    """``(controller, predict)`` of one of :data:`CONTROLLERS` on the NOMINAL parameters, torque-limited."""
    kind, sensing, predict = CONTROLLERS[label]
    u_max = np.asarray(PANDA_EFFORT, dtype=float)
    if kind == "pdg":
        return make_controller("pdg", model, model.default_params, u_max=u_max, **PDG_GAINS), False
    return make_controller(kind, model, model.default_params, sensing=sensing, u_max=u_max, **gains), predict


def run_all(model, cases: List[dict], duration: float, gains: dict,
            progress: Optional[Callable[[str], None]] = None, backend: str = "compiled") -> Dict[str, list]:
    """``{controller label: [SimulationResult or SimulationDivergedError per draw]}``."""
    ref = reference(model.n)
    out: Dict[str, list] = {}
    for label in CONTROLLERS:
        ctrl, predict = controller(label, model, gains)
        out[label] = []
        for d in cases:
            if progress:
                progress(f"real arm: {label}, {d['label']}")
            x0 = rest_state(model, ref(0.0)[0], d["params"])
            try:
                r = simulate(model, ctrl, ref, duration=duration, dt=1.0 / RATE, true_params=d["params"], x0=x0,
                             backend=backend, sensor=SensorModel.panda_white(seed=d["seed"]), delay_samples=DELAY,
                             predict=predict)
            except SimulationDivergedError as exc:
                r = exc
            out[label].append(r)
    return out


def diverged(r) -> bool:
    """Stopped by the integrator, or some joint's error beyond :data:`DIVERGED_ERROR` rad."""
    return isinstance(r, SimulationDivergedError) or bool(np.any(np.abs(r.e1) > DIVERGED_ERROR))


def summary_rows(results: Dict[str, list]) -> Dict[str, dict]:
    """Per controller: ``diverged`` (count), ``runs``, ``rms`` (worst-joint second-half RMS, worst draw, rad),
    ``at_limit`` (fraction of samples at a torque limit, worst joint and draw), ``jitter_14`` and
    ``jitter_57`` (torque jitter, N m, worst joint of joints 1-4 / 5-7, worst draw) over the finished runs."""
    out = {}
    for label, runs in results.items():
        ok = [r for r in runs if not diverged(r)]
        row = {"runs": len(runs), "diverged": len(runs) - len(ok), "rms": np.nan, "at_limit": np.nan,
               "jitter_14": np.nan, "jitter_57": np.nan}
        if ok:
            lim = np.asarray(PANDA_EFFORT)
            jit = np.array([torque_jitter(r) for r in ok])
            row.update(rms=max(float(np.max(rms_second_half(r))) for r in ok),
                       at_limit=max(float(np.max(time_at_limit(r, lim))) for r in ok),
                       jitter_14=float(np.max(jit[:, :4])), jitter_57=float(np.max(jit[:, 4:])))
        out[label] = row
    return out


def _fmt(v: float) -> str:
    if not np.isfinite(v):
        return "-"
    return f"{v:.2e}" if (v != 0 and (abs(v) < 1e-2 or abs(v) >= 1e3)) else f"{v:.3g}"


def table(rows: Dict[str, dict]) -> List[str]:
    """Markdown table of :func:`summary_rows` (failures first-class: the diverged count is a column)."""
    lines = ["| controller | diverged / runs | worst-joint RMS e1, 2nd half (rad, worst draw) | "
             "time at a torque limit (worst joint, worst draw) | torque jitter joints 1-4 / 5-7 (N m) |",
             "|---|---|---|---|---|"]
    for label, r in rows.items():
        lim = "-" if not np.isfinite(r["at_limit"]) else f"{100 * r['at_limit']:.1f} %"
        lines.append(f"| {label} | {r['diverged']} / {r['runs']} | {_fmt(r['rms'])} | {lim} | "
                     f"{_fmt(r['jitter_14'])} / {_fmt(r['jitter_57'])} |")
    return lines


def plot(results: Dict[str, list], path: Path) -> Path:
    """Per controller (rows): worst-joint ``abs(e1)`` of every draw (log, divergences marked x) and the
    largest ``abs(u)`` of joints 1-4 and 5-7 with the URDF effort limits drawn."""
    from ..sim.plot import pyplot
    plt = pyplot()
    labels = list(results)
    fig, axes = plt.subplots(len(labels), 3, figsize=(13, 2.3 * len(labels) + 1.0), squeeze=False, sharex=True,
                             layout="constrained")
    limits = ((slice(0, 4), PANDA_EFFORT[0], "joints 1-4"), (slice(4, 7), PANDA_EFFORT[4], "joints 5-7"))
    for j, label in enumerate(labels):
        n_div = 0
        for r in results[label]:
            if isinstance(r, SimulationDivergedError):
                axes[j, 0].axvline(r.t, color="r", lw=0.8)
                n_div += 1
                continue
            err = np.maximum(np.max(np.abs(r.e1), axis=1), 1e-12)
            bad = diverged(r)
            n_div += bad
            axes[j, 0].semilogy(r.t, err, color="r" if bad else "C0", lw=0.6, alpha=0.6)
            for k, (sl, _lim, _lab) in enumerate(limits):
                axes[j, k + 1].plot(r.t, np.max(np.abs(r.u[:, sl]), axis=1), color="r" if bad else "C0", lw=0.5,
                                    alpha=0.5)
        axes[j, 0].set_ylabel(f"{label}\nmax abs(e1) (rad)", fontsize=8)
        axes[j, 0].set_ylim(1e-6, 10)
        axes[j, 0].set_title(f"worst-joint error, {len(results[label])} draws ({n_div} diverged, red)", fontsize=9)
        for k, (sl, lim, lab) in enumerate(limits):
            axes[j, k + 1].axhline(lim, color="k", ls=(0, (4, 2)), lw=1.2, zorder=10)
            axes[j, k + 1].set_ylim(0, 1.15 * lim)
            axes[j, k + 1].set_title(f"max abs(u), {lab} (dashed: limit {lim:g} N m)", fontsize=9)
    for a in axes[-1]:
        a.set_xlabel("t (s)")
    fig.suptitle(f"Panda at {RATE:g} Hz, {DELAY}-sample delay, sensor noise, K x U[0.7, 1.3], J_m x U[0.8, 1.2], "
                 "0-1 kg payload", fontsize=10)
    return write_figure(fig, path, dpi=100)


def certificate_note(model) -> str:
    """Why ``fjm tune panda --sensing torque`` finds no gain for +-30 %, in numbers from
    :func:`~fjm_runtime.analysis.certificates.certify_tau.gamma_tolerance` on this section's workspace."""
    tol = gamma_tolerance(model, AMPLITUDE, q_center=READY)
    r = np.asarray(tol["r_max"])
    bad = [i + 1 for i in range(r.size) if r[i] < 0.3]
    return ("Certificate: with torque sensing the input gain of s_i' is G = D^-1 Gamma D (Gamma = K K_nom^-1 "
            "J_m^-1 J_m,nom), and the per-joint reaching condition of `fjm tune --sensing torque` needs G_ii > 0, "
            "i.e. stiffness ratios within 1 +- r_i, r_i = 1 / sup_q sum_k |(D^-1)_ik D_ki|. On this workspace "
            f"(ready pose +- the sine amplitudes, J_m exact) r = {np.round(r, 3).tolist()} for joints 1..7: the "
            f"+-30 % box is out of reach of that certificate on joint(s) {bad or 'none'} for any k_s (a limit of the "
            "per-joint sufficient condition under the coupling through D, not a divergence: compare the runs).")


def real_arm_section(ctx) -> Tuple[List[str], list]:
    """The section of ``make demo``: runs, ``real_arm.png``, ``real_arm.csv`` and the markdown lines."""
    from .. import load
    t0 = time.perf_counter()
    m = load("panda")
    n_random, duration = (QUICK_DRAWS - 1, QUICK_DURATION) if ctx.quick else (N_RANDOM, DURATION)
    cases = draws(m, n_random)
    if ctx.quick:
        cases = cases[:n_random] + cases[-3:-2]
    gains, source = ismc_gains()
    res = run_all(m, cases, duration, gains, ctx.progress, backend="casadi" if ctx.quick else "compiled")
    ctx.results["real_arm"] = rows = summary_rows(res)
    fig = plot(res, ctx.out / "real_arm.png")
    (ctx.out / "real_arm.csv").write_text(_csv(res, cases))
    md = ["## The Panda in the conditions of a real arm", "",
          f"{RATE:g} Hz control, {DELAY}-sample computation delay, the Panda sensor model (noise on q, dq, q_m, "
          "dq_m, tau_J; dtau_J a filtered difference of tau_J), plant on substeps with zero-order hold, torques "
          f"saturated at the URDF efforts {list(PANDA_EFFORT)} N m. TRUE plants: {len(cases)} draws "
          f"({n_random} random: K x U[0.7, 1.3], J_m x U[0.8, 1.2] per joint, payload U[0, 1] kg; plus the corners "
          "listed in `real_arm.csv`); every controller knows only the NOMINAL parameters and sees the same draws "
          f"and noise seeds. {duration:g} s of the joint-space sines per run. Integral SMC gains: {source}; the "
          "state-feedback law uses the same gains. Motor PD + gravity: k_p = "
          f"{list(PDG_GAINS['k_p'])} N m/rad, k_d = {list(PDG_GAINS['k_d'])} N m s/rad (stated, a regulation "
          "law following the moving set point).", "", *table(rows), "",
          "Diverged: stopped by the integrator or an error beyond pi rad. Jitter: standard deviation of u minus "
          "its 20 ms moving mean. " + certificate_note(m) + " " + ("QUICK MODE: a smoke test, not the documented numbers. " if ctx.quick else "")
          + f"Figure: `{fig.name}`; per draw: `real_arm.csv`. {time.perf_counter() - t0:.0f} s.", ""]
    return md, [fig]


def _csv(results: Dict[str, list], cases: List[dict]) -> str:
    """One line per controller and draw: diverged, worst-joint second-half RMS, time at limit, the draw."""
    lines = ["controller,draw,diverged,rms_second_half_worst_joint,time_at_limit_worst_joint,m_load,K_ratio,Jm_ratio"]
    lim = np.asarray(PANDA_EFFORT)
    for label, runs in results.items():
        for d, r in zip(cases, runs):
            p = d["params"]
            kr = ";".join(f"{v:.3f}" for v in d["K_ratio"])
            jr = ";".join(f"{v:.3f}" for v in d["Jm_ratio"])
            if diverged(r):
                lines.append(f"{label},{d['label']},1,,,{p['m_load']:.3f},{kr},{jr}")
                continue
            lines.append(f"{label},{d['label']},0,{np.max(rms_second_half(r)):.6g},"
                         f"{np.max(time_at_limit(r, lim)):.4f},{p['m_load']:.3f},{kr},{jr}")
    return "\n".join(lines) + "\n"
