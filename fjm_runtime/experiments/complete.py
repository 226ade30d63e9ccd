"""The demo's complete-model section: the Panda with rotor spin coupling (gear ratio N), reduced law vs compensated law.

The demo's Panda integral SMC (:mod:`fjm_runtime.experiments.panda`: its gains, reference, torque
limits and 5 kHz rate), built on the REDUCED model ``panda`` at its nominal parameters, runs on
the reduced plant and on the complete plant ``panda_complete`` (rotor spin coupling, gear ratio
N); the same law with the coupling compensated
(:class:`fjm_runtime.control.coupling.CouplingCompensatedController`, nominal complete model,
accelerations under the previous sample's torque) runs on the complete plant. The plant
parameters are the model defaults with the gear ratios of each case; the controllers' nominal
model is ``panda``'s defaults and, for the compensation, ``panda_complete``'s at N = 100.

At N = 100 both laws also run against MuJoCo (:func:`mujoco_runs`): ``panda_complete`` exported by
:func:`fjm_runtime.export.mjcf.write_mjcf` at the same plant parameters, MuJoCo's RK4 at the step
of fjm's run (``DT / substeps``), the control held over the sample
(:func:`fjm_runtime.export.bridge.run_closed_loop`). ``mujoco`` is imported there only; without
it the section says so in one line.
"""
from __future__ import annotations

import time
from pathlib import Path
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np

from ..control.coupling import CouplingCompensatedController, complete_plant
from ..sim.simulate import simulate
from ..sim.step import SimulationDivergedError
from ..sim.substeps import resolve_substeps
from . import panda as P
from .report import diverged_marker
from .plots import write_figure

#: Plant gear-ratio cases: every joint at N, or only rotor 7 coupled (N = 1e9 elsewhere).
GEAR_CASES = {"N = 100": (100.0,) * 7, "N = 300": (300.0,) * 7, "N = 1000": (1000.0,) * 7,
              "N = 3000": (3000.0,) * 7, "rotor 7 only (N7 = 100)": (1e9,) * 6 + (100.0,)}
QUICK_GEARS = ("N = 100",)
#: The gear-ratio case run against MuJoCo too (both laws); the MJCF file written to the output directory.
MUJOCO_CASE, MUJOCO_FILE = "N = 100", "panda_complete.xml"
RUNS = ("reduced law, reduced plant", "reduced law, complete plant", "compensated law, complete plant",
        "compensated law (nominal N = the plant's), complete plant")


def gear_params(ratios) -> Dict[str, float]:
    """``{'N1': .., 'N7': ..}`` of a gear-ratio case."""
    return {f"N{i + 1}": float(v) for i, v in enumerate(ratios)}


def controllers(reduced, complete, ratios=None) -> Tuple[object, object]:
    """``(reduced law, compensated law)``: the demo's ismc on ``reduced`` and the same law compensated.

    ``ratios``: the compensation's nominal gear ratios (default: the complete model's defaults).
    """
    inner = P.controller("ismc", reduced)
    nominal = None if ratios is None else gear_params(ratios)
    return inner, CouplingCompensatedController(P.controller("ismc", reduced), complete, nominal, dt=P.DT)


def _run(plant, ctrl, ref, duration, p_true, x0, backend):
    try:
        # an ideal actuator on both sides: the section compares the plants (MuJoCo's RK4 holds ctrl over its
        # stages, so a current loop's lag would differ by its quadrature, not by the plant)
        return simulate(plant, ctrl, ref, duration=duration, dt=P.DT, true_params=p_true, x0=x0, backend=backend,
                        interface="ideal")
    except SimulationDivergedError as exc:
        return exc


def setup():
    """``(reduced, complete, plant, reference, x0)``: ``panda``, ``panda_complete``, its plant, the Panda reference, rest state."""
    from .. import load
    reduced, complete = load("panda"), load("panda_complete")
    ref = P.reference(reduced.n)
    return reduced, complete, complete_plant(complete, reduced), ref, P.rest_state(reduced, ref(0.0)[0], None)


def run_all(duration: float, gears=None, backend: str = "compiled", progress=None) -> Dict[str, Dict[str, object]]:
    """``{case: {run label: SimulationResult or SimulationDivergedError}}``; the reduced plant under ``'-'``."""
    reduced, complete, plant, ref, x0 = setup()
    law, comp = controllers(reduced, complete)
    gears = GEAR_CASES if gears is None else gears
    out: Dict[str, Dict[str, object]] = {"-": {RUNS[0]: _run(reduced, law, ref, duration, None, x0, backend)}}
    for label, ratios in gears.items():
        if progress:
            progress(f"panda_complete, {label}")
        p = gear_params(ratios)
        out[label] = {RUNS[1]: _run(plant, law, ref, duration, p, x0, backend),
                      RUNS[2]: _run(plant, comp, ref, duration, p, x0, backend)}
        if any(p[k] != complete.default_params[k] for k in p):
            matched = controllers(reduced, complete, ratios)[1]
            out[label][RUNS[3]] = _run(plant, matched, ref, duration, p, x0, backend)
    return out


@dataclass
class MujocoRun:
    """One law's closed loop against MuJoCo (``N + 1`` samples, ``n`` joints).

    Attributes
    ----------
    t : numpy.ndarray, shape (N+1,)
    x : numpy.ndarray, shape (N+1, 4n)
        fjm's state ``[q; dq; q_m; dq_m]`` read from MuJoCo at each sample.
    u : numpy.ndarray, shape (N+1, n)
    e1 : numpy.ndarray, shape (N+1, n)
        ``q - q_d``.
    gap : float or None
        ``max abs(q_MuJoCo - q_fjm)`` over samples and joints against fjm's run of the same law (rad;
        None if that run diverged).
    substeps : int
        MuJoCo RK4 steps per sample (fjm's rule; the file's timestep is ``DT / substeps``).
    unstable : bool
        MuJoCo reported bad accelerations (it then resets its state).
    """

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    e1: np.ndarray
    gap: Optional[float]
    substeps: int
    unstable: bool


def mujoco_runs(out, duration: float, fjm_runs: Dict[str, object], progress=None) -> Optional[Dict[str, MujocoRun]]:
    """Both laws of :data:`MUJOCO_CASE` against ``panda_complete`` exported to MuJoCo; None without ``mujoco``.

    ``fjm_runs``: ``{run label: SimulationResult or SimulationDivergedError}`` of that case (the
    :data:`RUNS` 1 and 2 of :func:`run_all`). The MJCF is written to ``out / MUJOCO_FILE`` at the
    plant parameters of the case, MuJoCo step ``DT / substeps`` with fjm's substeps rule at ``x0``.
    """
    try:
        import mujoco
    except ImportError:
        return None
    from ..export.bridge import MujocoPlant, run_closed_loop
    from ..export.mjcf import write_mjcf
    reduced, complete, plant, ref, x0 = setup()
    p = dict(complete.default_params, **gear_params(GEAR_CASES[MUJOCO_CASE]))
    subs = resolve_substeps(None, plant, x0, plant.params_array(p), P.DT)
    path = write_mjcf(complete, Path(out) / MUJOCO_FILE, p, complete=True, timestep=P.DT / subs)
    n, out_runs = reduced.n, {}
    for label, law in zip(RUNS[1:3], controllers(reduced, complete)):
        if progress:
            progress(f"MuJoCo {path.name}, {label.split(',')[0]}")
        mp = MujocoPlant(complete, path, p)
        t, X, U = run_closed_loop(mp, law, ref, duration=duration, dt=P.DT, substeps=subs, x0=x0, interface="ideal")
        e1 = X[:, :n] - np.array([np.asarray(ref(tk), dtype=float)[0] for tk in t])
        r = fjm_runs.get(label)
        gap = (float(np.max(np.abs(X[:, :n] - r.x[:, :n])))
               if r is not None and not isinstance(r, SimulationDivergedError) and r.x.shape == X.shape else None)
        bad = int(mp.data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number) > 0
        out_runs[label] = MujocoRun(t, X, U, e1, gap, subs, bad)
    return out_runs


def worst_second_half(r) -> Tuple[float, int]:
    """``(RMS of e1 over t >= t_end / 2, its joint (1-based))`` of the worst joint."""
    e = r.e1[r.t >= 0.5 * r.t[-1]]
    rms = np.sqrt(np.mean(e ** 2, axis=0))
    return float(rms.max()), int(rms.argmax()) + 1


def cells(r) -> str:
    """Table cells: worst-joint 2nd-half RMS (joint), whole-run worst-joint RMS, peak abs(u) 1-4 / 5-7."""
    t_div = P.divergence_time(r)
    if getattr(r, "unstable", False):
        return f"{diverged_marker(float(r.t[-1]), 'MuJoCo reported bad accelerations')} | | "
    if t_div is not None:
        return f"{diverged_marker(t_div)} | | "
    rms2, j = worst_second_half(r)
    rms = np.sqrt(np.mean(r.e1 ** 2, axis=0)).max()
    peak = np.max(np.abs(r.u), axis=0)
    return f"{rms2:.2e} (joint {j}) | {rms:.2e} | {peak[:4].max():.1f} / {peak[4:].max():.2f}"


def table(res, mj=None) -> List[str]:
    """Markdown rows, one per (plant case, run), then the MuJoCo runs ``mj`` (:func:`mujoco_runs`) if given."""
    lines = ["| plant | controller | RMS e1, 2nd half (rad, worst joint) | RMS e1 (rad, worst joint) | "
             "peak abs(u) joints 1-4 / 5-7 (N m) | max abs(q - q_fjm), MuJoCo vs fjm (rad) |",
             "|---|---|---|---|---|---|"]
    for case, runs in res.items():
        for label, r in runs.items():
            plant = "panda (reduced)" if case == "-" else f"panda_complete, {case}"
            lines.append(f"| {plant} | {short(label)} | {cells(r)} | |")
    for label, r in (mj or {}).items():
        gap = "fjm's run diverged" if r.gap is None else f"{r.gap:.1e}"
        lines.append(f"| MuJoCo `{MUJOCO_FILE}`, {MUJOCO_CASE} | {short(label)} | {cells(r)} | {gap} |")
    return lines


def short(label: str) -> str:
    """The controller cell of a :data:`RUNS` label (``'reduced law'``, ``'compensated law'``, ...)."""
    return label.rsplit(", complete", 1)[0].split(", reduced")[0]


def plot(res, path: Path, case: str = "N = 100", mj=None) -> Path:
    """Worst joint's abs(e1) vs time (log scale) of the three runs at ``case``, MuJoCo's runs ``mj`` dashed.

    Diverged runs are named in the legend; the reduced plant's run is dotted.
    """
    from ..sim.plot import pyplot
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 3.6), layout="constrained")
    runs = [(RUNS[0], res["-"][RUNS[0]], "0.4", dict(ls=":", lw=1.8, zorder=3))]
    runs += [(k, res[case][k], c, dict(lw=1.0)) for k, c in zip(RUNS[1:3], ("tab:red", "tab:blue"))]
    runs += [(f"{k} (MuJoCo)", r, c, dict(ls=(0, (5, 3)), lw=1.4, zorder=4))
             for (k, r), c in zip((mj or {}).items(), ("darkred", "navy"))]
    for label, r, color, style in runs:
        t_div = P.divergence_time(r)
        lab = label + (f" ({diverged_marker(t_div)})" if t_div is not None else "")
        if isinstance(r, SimulationDivergedError):
            ax.plot([], [], color=color, label=lab)
            continue
        ax.semilogy(r.t, np.maximum(np.max(np.abs(r.e1), axis=1), 1e-12), color=color, label=lab, **style)
    ax.set_ylim(bottom=1e-7)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("max abs(e1) over joints (rad)")
    ax.set_title(f"Panda, integral SMC at 5 kHz: complete plant ({case}; fjm and MuJoCo) vs reduced plant",
                 fontsize=10)
    ax.legend(fontsize=7, loc="lower right")
    return write_figure(fig, path)


def mujoco_text(mj) -> str:
    """The section's paragraph on the MuJoCo rows (one line when ``mujoco`` is not installed)."""
    if mj is None:
        return ("MuJoCo rows: not run, the `mujoco` package is not installed (`pip install 'fjm[dev]'`).")
    subs = next(iter(mj.values())).substeps
    return (f"*MuJoCo rows*: the same two laws at {MUJOCO_CASE} against `{MUJOCO_FILE}` (this directory: "
            "`panda_complete` exported by `fjm_runtime.export.mjcf.write_mjcf` at the same plant parameters; "
            f"rotors as bodies on the links, so MuJoCo produces the spin coupling itself), MuJoCo's RK4 at "
            f"{P.DT / subs:.3g} s = fjm's step ({subs} substeps per sample), the torque held over the sample "
            "(`fjm_runtime.export.bridge.run_closed_loop`). Last column: the largest difference of the link "
            "angles between MuJoCo's run and fjm's run of the same law, over all samples and joints.")


def complete_section(ctx) -> Tuple[List[str], list]:
    """Demo section (``ctx`` a :class:`~fjm_runtime.experiments.settings.DemoContext`): table and ``panda_complete.png``.

    Quick mode: N = 100 only, at most :data:`fjm_runtime.experiments.panda.QUICK_DURATION` s, CasADi backend.
    Both laws at :data:`MUJOCO_CASE` also run against MuJoCo (:func:`mujoco_runs`; ``MUJOCO_FILE`` in ``ctx.out``).
    """
    t0 = time.perf_counter()
    if ctx.quick:
        gears, duration, backend = {k: GEAR_CASES[k] for k in QUICK_GEARS}, min(ctx.duration, P.QUICK_DURATION), "casadi"
    else:
        gears, duration, backend = GEAR_CASES, ctx.duration, "compiled"
    res = run_all(duration, gears, backend, ctx.progress)
    mj = mujoco_runs(ctx.out, duration, res[MUJOCO_CASE], ctx.progress) if MUJOCO_CASE in res else None
    fig = plot(res, Path(ctx.out) / "panda_complete.png", mj=mj)
    md = ["## Complete elastic model: the Panda with rotor spin coupling", "",
          "The Panda section's integral SMC (same gains, reference, URDF torque limits, "
          f"{1 / P.DT:g} Hz, {duration:g} s, starting at rest holding gravity), built on the REDUCED model "
          "`panda` at its nominal parameters, on the reduced plant and on the complete plant `panda_complete` "
          "(each rotor on the previous link, spinning about its joint axis; gear ratio N of every joint, or of "
          "rotor 7 alone). *Compensated law*: the same law with the coupling put back "
          "(`fjm_runtime.control.coupling.CouplingCompensatedController`): from the NOMINAL complete model "
          "(N = 100) at the measured state under the previous sample's torque, the link-side term "
          "`d_l = (D' - D) ddq + S ddq_m + h' + c_l - h` shifts the motor angle the reduced law sees "
          "(`q_m - K^-1 d_l`, so its y3, y4 are the links' true acceleration and jerk) and "
          "`d_l + S^T ddq + c_m` is added to its torque (docs/complete-model.md, \"Control\"). The plant's "
          "gear ratios are the case's, its other parameters the defaults.", "",
          *table(res, mj), "",
          "The compensated law's nominal gear ratios are N = 100 (`panda_complete`'s defaults) unless the row "
          "says the plant's: rows with another plant N show how the compensation fares when its gear ratios "
          "are wrong (the reduced law's nominal model has no gear ratio at all).", "", mujoco_text(mj), "",
          f"Figure: `{fig.name}` (worst joint's error, {MUJOCO_CASE}: the three fjm runs, MuJoCo's dashed). "
          f"{time.perf_counter() - t0:.0f} s.", ""]
    return md, [fig]
