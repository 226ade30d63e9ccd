"""The demo's tree section: Baxter's two series-elastic arms tracking joint-space sines.

Baxter (``baxter``: head pan and two 7-joint arms, a tree of 15 elastic joints)
runs the integral sliding-mode law at 1 kHz in the sampled-data loop as a real one runs
(plant on RK4 substeps, zero-order hold, sensor noise, one sample of computation delay
with the law's prediction), once reading the full state (``sensing='state'``) and once
the joint-torque measurement ``[q; dq; tau_J; dtau_J; dq_m]`` that a series-elastic
actuator provides (``sensing='torque'``, the ``_tau`` laws). The controller knows only
the NOMINAL parameters (the defaults); the TRUE stiffness differs per joint. The task (both
arms on sines, the head holding its pan angle) and the torque limits are the model's
(``model.task``, ``model.limits.effort``: derive/robots/baxter/baxter.toml's ``[task]``
and ``[limits]`` over the URDF's efforts). The gains are those
``fjm design baxter --predict`` found for the torque-sensed law on this task when the
package ships them (:meth:`fjm_runtime.control.design.Design.shipped`), else stated ones (the same on
every joint). :func:`baxter_section` writes a figure and returns the summary table.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np

from ..control.design import Design
from ..control.factory import make_controller
from ..control.references import Reference
from ..drives import role_names
from ..sim.rest import rest_state
from ..sim.sensor import SensorModel
from ..sim.simulate import simulate
from ..sim.step import SimulationDivergedError
from .report import diverged_marker
from .plots import write_figure

#: The left arm's joints in q order (head_pan first, then the left arm, then the right).
LEFT_ARM = slice(1, 8)
RATE = 1000.0       # Hz: the control rate
DELAY = 1           # samples of computation delay, compensated by the law's prediction
#: Stated gains (every joint), used when no design is shipped.
STATED = {"lam": 10.0, "k_s": 200.0, "delta": 1.0}
CASES = {"exact": 0.0, "alternating +-20 %": 0.2}  # spread of the TRUE stiffness
SENSING = ("state", "torque")
DURATION, QUICK_DURATION = 3.0, 0.05


def reference(model) -> Reference:
    """The model's task (``model.task``: both arms on the same sines, the head still; at rest at t = 0)."""
    return model.task.reference()


def true_stiffness(model, spread: float) -> Dict[str, float]:
    """TRUE ``K_i = K_nom,i (1 + spread)`` on even q indices, ``(1 - spread)`` on odd ones."""
    return {k: model.default_params[k] * (1.0 - spread if i % 2 else 1.0 + spread)
            for i, k in enumerate(role_names(model, "stiffness"))}


def ismc_gains() -> Tuple[dict, str]:
    """``(gains, source)``: the shipped design for (baxter, ismc, torque, RATE, DELAY), else :data:`STATED`."""
    design = Design.shipped("baxter", "ismc", "torque", RATE, DELAY)
    if design:
        return (design.law_gains(),
                f"designed gains (`fjm design baxter --predict`: torque sensing, {RATE:g} Hz, delay {DELAY}, "
                f"{design.report['draws']} draws x {design.report['duration']:g} s; `{design.file}`)")
    return dict(STATED), "stated gains (the same on every joint), NOT the result of a search"


def run(model, duration: float, backend: str = "casadi",
        progress: Optional[Callable[[str], None]] = None, gains: Optional[dict] = None,
        seed: int = 0) -> Dict[str, Dict[str, object]]:
    """``{sensing: {case: SimulationResult or SimulationDivergedError}}`` (sensor noise of the Panda's model)."""
    ref = reference(model)
    gains = ismc_gains()[0] if gains is None else gains
    out: Dict[str, Dict[str, object]] = {}
    for sensing in SENSING:
        ctrl = make_controller("ismc", model, model.default_params, sensing=sensing,
                               u_max=np.array(model.limits.effort), **gains)
        out[sensing] = {}
        for label, spread in CASES.items():
            if progress:
                progress(f"baxter ismc, sensing {sensing}, true K {label}")
            p_true = true_stiffness(model, spread)
            try:
                out[sensing][label] = simulate(model, ctrl, ref, duration=duration, dt=1.0 / RATE,
                                               true_params=p_true, x0=rest_state(model, ref(0.0)[0], p_true),
                                               backend=backend, sensor=SensorModel.panda_white(seed=seed),
                                               delay_samples=DELAY, predict=True)
            except SimulationDivergedError as exc:
                out[sensing][label] = exc
    return out


def table(results) -> List[str]:
    """Markdown rows: worst-joint RMS and final error per arm, peak torques."""
    lines = ["| measurement | true stiffness | RMS e1 left arm (rad, worst joint) | RMS e1 right arm | "
             "final abs(e1) (rad, worst joint) | peak abs(u) s0-e1 / w0-w2 (N m) |", "|---|---|---|---|---|---|"]
    for sensing, per in results.items():
        for label, r in per.items():
            if isinstance(r, SimulationDivergedError) or not np.all(np.abs(r.e1) < np.pi):
                t = r.t if isinstance(r, SimulationDivergedError) else r.t[np.argmax(np.any(np.abs(r.e1) >= np.pi, 1))]
                lines.append(f"| {sensing} | {label} | {diverged_marker(float(t))} | | | |")
                continue
            rms = np.sqrt(np.mean(r.e1 ** 2, axis=0))
            peak = np.max(np.abs(r.u), axis=0)
            wrist = np.r_[5:8, 12:15]
            lines.append(f"| {sensing} | {label} | {rms[1:8].max():.2e} | {rms[8:].max():.2e} | "
                         f"{np.abs(r.e1[-1]).max():.2e} | {np.delete(peak, wrist).max():.1f} / "
                         f"{peak[wrist].max():.1f} |")
    return lines


def plot(results, path: Path) -> Path:
    """Worst-joint error per arm over time, every measurement and case."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6), sharey=True, layout="constrained")
    for (sensing, per), ls in zip(results.items(), ("--", "-")):
        for (label, r), color in zip(per.items(), ("tab:blue", "tab:red")):
            if isinstance(r, SimulationDivergedError):
                continue
            for ax, sl in zip(axes, (slice(1, 8), slice(8, 15))):
                ax.semilogy(r.t, np.maximum(np.max(np.abs(r.e1[:, sl]), axis=1), 1e-9), ls=ls, color=color,
                            lw=1.1, label=f"{sensing} sensing, K {label}")
    top = max([1e-2] + [float(np.max(np.abs(r.e1))) for per in results.values() for r in per.values()
                        if not isinstance(r, SimulationDivergedError)])
    for ax, arm in zip(axes, ("left arm", "right arm")):
        ax.set_title(f"Baxter {arm}: worst joint abs(e1)", fontsize=9.5)
        ax.set_xlabel("t (s)")
        ax.set_ylim(1e-6, min(10.0, 3 * top))
    axes[0].set_ylabel("rad")
    axes[1].legend(fontsize=8, frameon=False)
    return write_figure(fig, path)


def baxter_section(out: Path, duration: float = DURATION, progress: Optional[Callable[[str], None]] = None,
                   quick: bool = False) -> List[str]:
    """Run the Baxter experiment, write ``baxter_tracking.png`` into ``out``; returns the summary lines."""
    from .. import load
    t0 = time.perf_counter()
    m = load("baxter")
    task = m.task
    duration = min(duration, QUICK_DURATION) if quick else duration
    gains, source = ismc_gains()
    res = run(m, duration, progress=progress, gains=gains)
    fig = plot(res, Path(out) / "baxter_tracking.png")
    return ["## Tree: Baxter's two series-elastic arms (15 joints), stiffness +-20 %", "",
            f"Both arms track joint-space sines about {_arm(task.offset)} (A = {_arm(task.amplitude)} rad, omega = "
            f"{_arm(task.omega)} rad/s), the head holds its pan angle; {duration:g} s at {RATE:g} Hz (sampled-data "
            "loop, plant on RK4 substeps, zero-order hold, sensor noise of the Panda's model, "
            f"{DELAY} sample of delay with the law's prediction), CasADi backend, starting at rest holding gravity. "
            f"Integral SMC on the NOMINAL parameters, {source}: {_gains_text(gains)}; torques "
            f"saturated at {m.limits.effort.tolist()} N m. TRUE stiffness: the nominal (illustrative SEA values, "
            "derive/robots/baxter/README.md) or +20 % / -20 % on alternating joints. 'state': the law reads x; "
            "'torque': it reads [q; dq; tau_J; dtau_J; dq_m], as an SEA measures them, and has no K in its "
            "link-side part (the stiffness error becomes an input-gain error).", "",
            *table(res), "",
            f"Figure: `{fig.name}` (where the two torque-sensed curves overlap, the stiffness error does not show). "
            "The pose keeps s1's gravity load at ~19 N m of its 50 (the real Baxter adds a "
            "gravity-assist spring on s1, not modelled). "
            f"{time.perf_counter() - t0:.0f} s.", ""]


def _arm(values) -> list:
    """One arm's entries of a per-joint task array (both arms run the same)."""
    return np.asarray(values)[LEFT_ARM].tolist()


def _gains_text(gains: dict) -> str:
    """``lambda = 80, k_lin = [..], ...`` (scalars and per-joint lists, 3 significant digits)."""
    def fmt(v):
        return f"{v:.3g}" if np.ndim(v) == 0 else "[" + ", ".join(f"{x:.3g}" for x in v) + "]"
    return ", ".join(f"{'lambda' if k == 'lam' else k} = {fmt(v)}" for k, v in gains.items())


def tree_section(ctx) -> tuple:
    """The demo section (:data:`fjm_runtime.experiments.demo.SECTIONS`): ``(markdown lines, [figure])``."""
    md = baxter_section(ctx.out, ctx.duration, ctx.progress, quick=ctx.quick)
    return md, [ctx.out / "baxter_tracking.png"]
