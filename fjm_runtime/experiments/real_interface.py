"""The demo's real-interface section: which law holds on which command interface of a real arm.

The Panda at :data:`RATE` (1 kHz) with :data:`DELAY` sample of computation delay and prediction,
read through the ``franka_like`` sensor (velocities differentiated from quantized encoders, noise
and an offset on tau_J), on the two command interfaces of :mod:`fjm_runtime.sim.interface`:

``motor``
    the law commands motor torque through the 2 kHz current loop (series-elastic actuators,
    DLR-type drives, Kinova in current mode). Laws: the torque-sensed integral SMC with the shipped
    design's gains (``ismc_tau``, designed under white noise), the torque-sensed feedback
    linearization (``fl_tau``, stated pole), the motor-side impedance with torque feedback
    (``impedance``, the shipped design made under ``franka_like`` at this rate and delay) and the
    motor PD + gravity (``pdg``, the real-arm section's stated gains).
``franka``
    libfranka's layer (100 Hz command filter, 1 N m per tick, gravity added by the robot, its inner
    torque loop): the joint impedance (``joint_impedance``, the shipped design made on this interface
    under ``franka_like``), the one law here made for a
    desired link-side torque (a motor-torque law's output sent as ``tau_d`` means nothing).

Every law knows only the NOMINAL parameters and runs the same TRUE plants (:func:`plants`: the nominal
one, :data:`N_RANDOM` random draws and two corners of K x0.7..1.3, J_m x0.8..1.2, 0..1 kg) with the same
noise seeds, from rest holding gravity, on the model's task. :func:`real_interface_section` writes
``real_arm_laws.png`` and the table (law, worst RMS, jitter on joints 1-4, time at the torque and the
rate limit, diverged).
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np

from ..control.design import Design, task_start
from ..control.factory import make_controller
from ..sim.metrics import time_at_limit, time_at_rate_limit, torque_jitter
from ..sim.sensor import SensorModel
from ..sim.simulate import simulate
from ..sim.step import SimulationDivergedError
from .panda import DIVERGED_ERROR
from .plots import write_figure
from .real_arm import PDG_GAINS, draws, diverged as real_arm_diverged
from .shipped_designs import table as shipped_table

RATE = 1000.0          # Hz, the Panda's control rate
DELAY = 1              # samples of computation delay (predicted with the nominal model)
DURATION = 3.0         # s per run (the documented numbers)
QUICK_DURATION = 0.3   # s per run in quick mode (a smoke test, casadi backend)
N_RANDOM = 4           # random draws besides the nominal plant and the two corners
SEED = 2037
#: Pole of the torque-sensed feedback linearization, rad/s (stated: the order of the ismc design's
#: quadruple pole halved, the pole at which a one-joint check of this law held under franka_like sensing).
FL_LAM = 40.0

#: label -> (law, interface): the laws made for each interface, in the table's order.
LAWS = {
    "ismc_tau (shipped design)": ("ismc", "motor"),
    "fl_tau": ("fl", "motor"),
    "impedance (shipped design)": ("impedance", "motor"),
    "pdg": ("pdg", "motor"),
    "joint_impedance (shipped design)": ("joint_impedance", "franka"),
}


def plants(model, n_random: int = N_RANDOM, seed: int = SEED) -> List[dict]:
    """The TRUE plants: ``[{label, params, seed}]``: the nominal one, ``n_random`` random draws of
    :func:`fjm_runtime.experiments.real_arm.draws` (K x U[0.7, 1.3], J_m x U[0.8, 1.2] per joint, payload
    U[0, 1] kg), then its corners K x0.7, J_m x0.8 and K x1.3, J_m x1.2, each with 1 kg."""
    drawn = draws(model, n_random, seed + 1)
    return [{"label": "nominal", "params": dict(model.default_params), "seed": seed}] + drawn[:n_random + 2]


def controller(label: str, model):
    """``(controller, interface name)`` of one of :data:`LAWS` on the NOMINAL parameters, limited at the
    model's efforts."""
    kind, interface = LAWS[label]
    p_nom = model.params_array(None)
    u_max = np.asarray(model.limits.effort, dtype=float)
    if kind == "ismc":
        design = Design.shipped(model.name, "ismc", "torque", RATE, DELAY)
        return make_controller("ismc", model, p_nom, sensing="torque", u_max=u_max, **design.law_gains()), interface
    if kind == "fl":
        return make_controller("fl", model, p_nom, sensing="torque", lam=FL_LAM, u_max=u_max), interface
    if kind == "pdg":
        return make_controller("pdg", model, p_nom, u_max=u_max, **PDG_GAINS), interface
    design = Design.shipped(model.name, kind, "full", RATE, DELAY)  # made under franka_like on `interface`
    return design.controller(model), interface


def run_all(model, cases: List[dict], duration: float, progress: Optional[Callable[[str], None]] = None,
            backend: str = "compiled") -> Dict[str, list]:
    """``{law label: [SimulationResult or SimulationDivergedError per plant of cases]}``."""
    ref = model.task.reference()
    x0 = task_start(model, ref, "holding gravity", model.params_array(None))
    out: Dict[str, list] = {}
    for label in LAWS:
        ctrl, interface = controller(label, model)
        out[label] = []
        for case in cases:
            if progress:
                progress(f"real interfaces: {label} on {interface}, {case['label']}")
            try:
                r = simulate(model, ctrl, ref, duration=duration, dt=1.0 / RATE, true_params=case["params"], x0=x0,
                             backend=backend, sensor=SensorModel.franka_like(seed=case["seed"]),
                             delay_samples=DELAY, predict=True, interface=interface)
            except SimulationDivergedError as exc:
                r = exc
            out[label].append(r)
    return out


#: The sensors of :func:`sensing_rows`: none, white noise on every signal (what the shipped design was
#: searched with), and the realistic one of the main table.
SENSORS = {"ideal": SensorModel.ideal, "panda_white": SensorModel.panda_white, "franka_like": SensorModel.franka_like}
#: The fourth-order laws that :func:`sensing_rows` runs under each of :data:`SENSORS`.
FOURTH_ORDER = ("ismc_tau (shipped design)", "fl_tau")


def sensing_rows(model, duration: float, backend: str = "compiled") -> Dict[str, dict]:
    """The fourth-order laws on the NOMINAL plant under each sensor of :data:`SENSORS` (same seed, the
    motor interface): ``{"<law>, <sensor>": row of summary_rows}`` (what the sensing alone does)."""
    ref = model.task.reference()
    x0 = task_start(model, ref, "holding gravity", model.params_array(None))
    results = {}
    for label in FOURTH_ORDER:
        ctrl, interface = controller(label, model)
        for name, preset in SENSORS.items():
            try:
                r = simulate(model, ctrl, ref, duration=duration, dt=1.0 / RATE, x0=x0, backend=backend,
                             sensor=preset(seed=SEED), delay_samples=DELAY, predict=True, interface=interface)
            except SimulationDivergedError as exc:
                r = exc
            results[f"{label}, {name}"] = [r]
    return summary_rows(model, results)


def diverged(r) -> bool:
    """:func:`fjm_runtime.experiments.real_arm.diverged` (stopped by the integrator, or some joint's error beyond
    :data:`DIVERGED_ERROR` rad), or an error that is not finite."""
    return real_arm_diverged(r) or not np.all(np.isfinite(r.e1))


def summary_rows(model, results: Dict[str, list]) -> Dict[str, dict]:
    """Per law: ``interface``, ``runs``, ``diverged`` (count), and over the finished runs (worst joint,
    worst plant): ``rms`` (RMS of ``e1`` over the run, rad), ``jitter_14`` (torque jitter of joints 1-4,
    N m), ``at_torque_limit`` and ``at_rate_limit`` (fractions of the samples); NaN when every run diverged."""
    lim = np.asarray(model.limits.effort, dtype=float)
    rows = {}
    for label, runs in results.items():
        ok = [r for r in runs if not diverged(r)]
        row = {"interface": LAWS[label.split(", ")[0]][1], "runs": len(runs), "diverged": len(runs) - len(ok), "rms": np.nan,
               "jitter_14": np.nan, "at_torque_limit": np.nan, "at_rate_limit": np.nan}
        if ok:
            row.update(rms=max(float(np.max(np.sqrt(np.mean(r.e1 ** 2, axis=0)))) for r in ok),
                       jitter_14=max(float(np.max(torque_jitter(r)[:4])) for r in ok),
                       at_torque_limit=max(float(np.max(time_at_limit(r, lim))) for r in ok),
                       at_rate_limit=max(float(np.max(time_at_rate_limit(r))) for r in ok))
        rows[label] = row
    return rows


def _num(v: float, digits: int = 3) -> str:
    return "-" if not np.isfinite(v) else f"{v:.{digits}g}"


def table(rows: Dict[str, dict]) -> List[str]:
    """Markdown table of :func:`summary_rows` (RMS in mrad, the limits in % of the samples)."""
    lines = ["| law | interface | worst RMS (mrad) | jitter joints 1-4 (N m) | at torque limit (%) | "
             "at rate limit (%) | diverged / runs |", "|---|---|---|---|---|---|---|"]
    for label, r in rows.items():
        lines.append(f"| {label} | {r['interface']} | {_num(1e3 * r['rms'])} | {_num(r['jitter_14'])} | "
                     f"{_num(100 * r['at_torque_limit'])} | {_num(100 * r['at_rate_limit'])} | "
                     f"{r['diverged']} / {r['runs']} |")
    return lines


def plot(rows: Dict[str, dict], path: Path, n_plants: int) -> Path:
    """Worst RMS per law (log scale, bars coloured by interface; a law with diverged runs hatched in red
    with its count over the finished runs' worst, one whose every run diverged drawn at the top)."""
    from ..sim.plot import pyplot
    plt = pyplot()
    labels = list(rows)
    fig, ax = plt.subplots(figsize=(8.5, 3.8), layout="constrained")
    finite = [r["rms"] for r in rows.values() if np.isfinite(r["rms"])]
    top = 10.0 * max(finite) if finite else 1.0
    for k, label in enumerate(labels):
        r = rows[label]
        value = r["rms"] if np.isfinite(r["rms"]) else top
        color = "C0" if r["interface"] == "motor" else "C2"
        ax.bar(k, value, color=color, hatch="//" if r["diverged"] else None, edgecolor="r" if r["diverged"] else color)
        note = f"{1e3 * value:.3g} mrad"
        if r["diverged"]:
            note = f"{r['diverged']}/{r['runs']} diverged" + (f"\n(others: {note})" if np.isfinite(r["rms"]) else "")
        ax.text(k, value, note, ha="center", va="bottom", fontsize=8)
    ax.set_yscale("log")
    ax.set_xticks(range(len(labels)), [f"{lb}\n({rows[lb]['interface']})" for lb in labels], fontsize=8)
    ax.set_ylabel("worst-joint RMS e1, worst plant (rad)")
    ax.set_ylim(top=30.0 * top)
    ax.set_title(f"Panda, franka_like sensing, {RATE:g} Hz, delay {DELAY} with prediction, {n_plants} plants\n"
                 "blue: motor interface, green: franka; hatched red: some runs diverged", fontsize=9)
    return write_figure(fig, path, dpi=100)


def real_interface_section(ctx) -> Tuple[List[str], list]:
    """The section of ``make demo``: the runs, ``real_arm_laws.png`` and the markdown lines; the rows
    are left in ``ctx.results['real_interface']``."""
    from .. import load
    t0 = time.perf_counter()
    m = load("panda")
    cases = plants(m, 1 if ctx.quick else N_RANDOM)
    if ctx.quick:
        cases = cases[:2]
    duration = QUICK_DURATION if ctx.quick else DURATION
    backend = "casadi" if ctx.quick else "compiled"
    res = run_all(m, cases, duration, ctx.progress, backend=backend)
    ctx.results["real_interface"] = rows = summary_rows(m, res)
    ctx.results["real_interface_sensing"] = by_sensor = sensing_rows(m, duration, backend)
    fig = plot(rows, ctx.out / "real_arm_laws.png", len(cases))
    wall = time.perf_counter() - t0
    md = ["## Which law on which interface (the Panda, franka_like sensing)", "",
          f"{RATE:g} Hz, {DELAY}-sample delay with prediction, `franka_like` sensing (velocities differentiated "
          "from quantized encoders, tau_J noise and offset), the task from rest holding gravity, "
          f"{duration:g} s per run. TRUE plants ({len(cases)}): " + "; ".join(c["label"] for c in cases)
          + " (random: K x U[0.7, 1.3], J_m x U[0.8, 1.2] per joint, payload U[0, 1] kg). Interface `motor`: "
          "motor torque through the 2 kHz current loop, no rate limit; `franka`: libfranka's 100 Hz filter "
          "and 1 N m per tick, gravity added by the robot, its inner torque loop (the column u is then the "
          "command after filter and limit). Laws: `ismc_tau` with the shipped design's gains "
          "(panda_ismc_tau_1000hz_d1, designed under the white `panda` sensor), `fl_tau` with its quadruple "
          f"pole at {FL_LAM:g} rad/s, `impedance` and `joint_impedance` with the shipped designs' gains "
          "(panda_impedance_1000hz_d1 on `motor`, panda_joint_impedance_1000hz_d1 on `franka`, both searched "
          f"under `franka_like` on other draws than these), `pdg` with k_p = {list(PDG_GAINS['k_p'])} N m/rad, k_d = {list(PDG_GAINS['k_d'])} "
          "N m s/rad. A motor-torque law's output sent as tau_d means nothing, so the franka interface runs "
          "only the law made for it.", "", *table(rows), "",
          "Worst RMS: the largest per-joint RMS of e1 over the run, over the plants that did not diverge. "
          "Jitter: standard deviation of u minus its 20 ms moving mean, largest of joints 1-4. Diverged: "
          f"stopped by the integrator or an error beyond {DIVERGED_ERROR:g} rad.", "",
          "What the sensing alone does to the fourth-order laws: the nominal plant, the same seed, the motor "
          "interface, under no noise (`ideal`), white noise on every signal including the velocities "
          "(`panda_white`, the shipped design's) and `franka_like`:", "", *table(by_sensor), "",
          "The shipped designs made under realistic sensing (`fjm_runtime/control/designed/`; each row read "
          "from its file: the final check and the re-check on fresh draws together, as `fjm design` prints them):",
          "", *shipped_table(), "",
          ("QUICK MODE: a smoke test, not the documented numbers. " if ctx.quick else "")
          + f"Figure: `{fig.name}`. Wall time of this section: {wall:.0f} s.", ""]
    return md, [fig]
