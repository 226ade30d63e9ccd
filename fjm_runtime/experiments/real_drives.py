"""Real drives in the demo: arm1_hd's datasheet spring, the laws compared in a Franka-like loop.

``arm1_hd`` is a one-link arm on a harmonic drive (the three-segment datasheet stiffness curve, motor
friction; docs/real-drives.md). The laws run in the sampled loop as a Franka-like robot runs it (1 kHz,
``franka_like`` sensor (tau_J offset, velocities differentiated from quantized encoders), the motor interface
with a 1000 N m/s rate limit and the 2 kHz current loop, one sample of delay with prediction) on ``draws`` TRUE drives that differ from
the datasheet (curve x U(0.85, 1.15), friction x U(0.5, 1.5), rotor x U(0.9, 1.1)), holding the arm
about horizontal where the drive works past its first breakpoint. :func:`compare_datasheet_laws` is
shared with ``examples/nonlinear_spring_laws.py``; :func:`real_drives_section` is the demo's section.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Dict, List, Tuple

import numpy as np

from .plots import write_figure
from ..sim.interface import CommandInterface

#: The motor interface with libfranka's 1000 N m/s rate limit (the franka_like sensor held it before).
FRANKA_RATE = CommandInterface.motor().with_rate_limit(1000.0)

#: ismc gains of the comparison (a stiff drive: lambda 60), N m limit.
GAINS = {"lam": 60.0, "k_s": 100.0, "delta": 5.0, "u_max": 100.0}

#: The compared laws: (sensing, label, nominal-parameter edits of the datasheet values).
LAWS = (("torque", "derived for the curve", {}),
        ("torque", "linear spring K_1", {"K_2": "K_1", "K_3": "K_1"}),
        ("torque", "curve, no friction feedforward", {"F_c": 0.0, "F_s": 0.0}),
        ("state", "derived for the curve", {}),
        ("state", "linear spring K_1", {"K_2": "K_1", "K_3": "K_1"}))


def true_drives(d: dict, draws: int, seed: int = 28) -> List[dict]:
    """``draws`` TRUE parameter sets around the datasheet values ``d`` (module docstring)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(draws):
        c, f, j = rng.uniform(0.85, 1.15), rng.uniform(0.5, 1.5), rng.uniform(0.9, 1.1)
        out.append({**d, **{k: c * d[k] for k in ("K_1", "K_2", "K_3")}, "F_c": f * d["F_c"], "F_s": f * d["F_s"],
                    "Jm1": j * d["Jm1"]})
    return out


def compare_datasheet_laws(duration: float, draws: int, progress=None) -> Dict[str, dict]:
    """Every law of :data:`LAWS` on every drive of :func:`true_drives`.

    Returns
    -------
    dict
        ``"<sensing>: <label>"`` -> ``{"rms": [per drive], "at_limit": [...], "phi": (min, max) rad,
        "t", "e1": the first drive's run (for the figure)}``.
    """
    from .. import load
    from ..control.factory import make_controller
    from ..control.references import make_reference
    from ..sim.metrics import rms_second_half, time_at_limit
    from ..sim.sensor import SensorModel
    from ..sim.simulate import simulate
    arm = load("arm1_hd")
    d = arm.default_params
    ref = make_reference("sine", 1, amplitude=0.5, omega=3.0, offset=np.pi / 2)
    out = {}
    for sensing, label, edits in LAWS:
        nominal = {**d, **{k: (d[v] if isinstance(v, str) else v) for k, v in edits.items()}}
        key = f"{sensing}: {label}"
        if progress:
            progress(f"real drives: arm1_hd, {key}, {draws} drives")
        row = {"rms": [], "at_limit": [], "phi": (np.inf, -np.inf)}
        for i, true in enumerate(true_drives(d, draws)):
            phi0 = float(arm.spring_functions["spring_inverse"](d["m1"] * d["g0"] * d["r1"], arm.params_array(true)))
            x0 = np.array([np.pi / 2, 0.0, np.pi / 2 + phi0, 0.0])          # at rest, horizontal: past T_1
            ctrl = make_controller("ismc", arm, nominal, sensing=sensing, **GAINS)
            r = simulate(arm, ctrl, ref, duration=duration, dt=1e-3, x0=x0, true_params=true, delay_samples=1,
                         predict=True, sensor=SensorModel.franka_like(), interface=FRANKA_RATE)
            phi = r.x[:, 2] - r.x[:, 0]
            row["rms"].append(float(np.max(rms_second_half(r))))
            row["at_limit"].append(float(np.max(time_at_limit(r))))
            row["phi"] = (min(row["phi"][0], float(phi.min())), max(row["phi"][1], float(phi.max())))
            if i == 0:
                row["t"], row["e1"] = r.t.ravel(), r.e1.ravel()
        out[key] = row
    return out


def _plot(arm, rows: Dict[str, dict], path: Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    d = arm.default_params
    pv = arm.params_array(d)
    phi = np.linspace(0.0, 4.5e-3, 400)
    psi = np.array([float(arm.spring_functions["spring"](v, pv)[0]) for v in phi])
    b1 = d["T_1"] / d["K_1"]
    b2 = b1 + (d["T_2"] - d["T_1"]) / d["K_2"]
    corner = np.interp(phi, [0.0, b1, b2, phi[-1]], [0.0, d["T_1"], d["T_2"], d["T_2"] + d["K_3"] * (phi[-1] - b2)])
    lo, hi = rows["torque: derived for the curve"]["phi"]
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.8))
    ax[0].plot(1e3 * phi, corner, "k--", lw=0.8, label="datasheet segments K_1, K_2, K_3")
    ax[0].plot(1e3 * phi, psi, label="the model's curve (C2 blends)")
    ax[0].axvspan(1e3 * max(lo, 0.0), 1e3 * hi, color="C2", alpha=0.2, label="deflections in the runs")
    for b in (b1, b2):
        ax[0].axvline(1e3 * b, color="0.6", lw=0.6)
    ax[0].set(xlabel="deflection q_m - q (mrad)", ylabel="tau_J (N m)", title="arm1_hd spring")
    ax[0].legend(fontsize=8)
    for key, row in rows.items():
        ax[1].semilogy(row["t"], np.abs(row["e1"]) + 1e-9, lw=0.8, label=key)
    ax[1].set(xlabel="t (s)", ylabel="|e1| (rad)", title="tracking error, first drive", ylim=(1e-6, 10))
    ax[1].legend(fontsize=7)
    return write_figure(fig, path, tight=True)


def real_drives_section(ctx) -> Tuple[List[str], list]:
    """The section of ``make demo``: ``real_drives.png`` and the markdown lines."""
    from .. import load
    t0 = time.perf_counter()
    draws, duration = (2, 2.0) if ctx.quick else (8, 4.0)
    rows = compare_datasheet_laws(duration, draws, ctx.progress)
    fig = _plot(load("arm1_hd"), rows, ctx.out / "real_drives.png")
    ctx.results["real_drives"] = {k: max(r["rms"]) for k, r in rows.items()}
    table = ["| law (nominal: the datasheet) | worst RMS e1, 2nd half (rad) | median | at the limit |", "|---|---|---|---|"]
    table += [f"| {k} | {max(r['rms']):.3g} | {np.median(r['rms']):.3g} | {100 * max(r['at_limit']):.1f} % |"
              for k, r in rows.items()]
    md = ["## Real drives: the datasheet spring (`arm1_hd`)", "",
          "A one-link arm on a harmonic drive whose stiffness follows the catalogue's three segments "
          "(1.3e4, 1.7e4, 2.0e4 N m/rad to 14 and 48 N m, C2-blended) with motor friction, in the loop as a "
          "Franka-like robot runs it (1 kHz, `franka_like` sensor, the motor interface with a 1000 N m/s rate "
          "limit and the 2 kHz current loop, one "
          f"sample of delay with prediction), {draws} TRUE drives off the datasheet (curve x0.85..1.15, friction "
          f"x0.5..1.5, rotor x0.9..1.1), {duration:g} s of a 0.5 rad, 3 rad/s sine about horizontal:", "",
          *table, "",
          "Torque-sensed, the spring law hardly matters (the torque coordinates read tau_J; psi' only scales "
          "beta) and the friction feedforward does; state-sensed, the law derived for the curve can lose a drive "
          "that is softer than its datasheet (docs/real-drives.md). "
          + ("QUICK MODE: a smoke test, not the documented numbers. " if ctx.quick else "")
          + f"Figure: `{fig.name}` (the curve with the runs' deflections, the error of each law). "
          f"{time.perf_counter() - t0:.0f} s.", ""]
    return md, [fig]
