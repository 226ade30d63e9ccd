"""The demo's identification section: link1's drive parameters from a MuJoCo log, and what they buy.

``fjm excite`` draws the excitation; MuJoCo plays the robot (:mod:`fjm_runtime.ident.mujoco_robot`:
the TRUE plant with stiffness x1.15, rotor inertia x0.9, motor damping and a dry friction fjm's
model lacks, logged with the ``franka_like`` sensor levels); ``fjm identify`` fits the log. Then the
state-sensed integral SMC (the gains ``fjm design link1 --params`` found for the identified values:
:data:`GAINS`) runs in fjm's sampled loop on the TRUE parameters (1 kHz, ``panda_white`` noise, one
sample of delay with prediction), once on the model's default nominal values and once on the
identified ones. ``examples/identify_roundtrip.py`` runs the same chain against MuJoCo itself.
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import List, Tuple

import numpy as np

from .plots import write_figure

#: Excitation length, s (quick mode: QUICK_DURATION).
DURATION, QUICK_DURATION = 10.0, 3.0
#: State-sensed ismc gains from `fjm design link1 --params <identified> --sensing state --noise panda_white
#: --predict` (the round trip's design; re-run it to re-derive them).
GAINS = {"lam": 10.0, "k_lin": 100.0, "k_s": 475.7, "delta": 4.0}


def _closed_loops(m, p_true: dict, nominal: dict, duration: float) -> dict:
    """Worst second-half RMS of the law on ``nominal`` against the TRUE plant, for each nominal set."""
    from ..control.factory import make_controller
    from ..control.references import make_reference
    from ..sim.metrics import rms_second_half
    from ..sim.rest import rest_state
    from ..sim.sensor import SensorModel
    from ..sim.simulate import simulate
    ref = make_reference("sine", 1, amplitude=0.5, omega=1.0)
    out = {}
    for label, nom in (("model defaults", dict(m.default_params)), ("identified", {**m.default_params, **nominal})):
        ctrl = make_controller("ismc", m, nom, **GAINS)
        res = simulate(m, ctrl, ref, duration=duration, dt=1e-3, true_params=p_true,
                       x0=rest_state(m, ref(0.0)[0], p_true), sensor=SensorModel.panda_white(), delay_samples=1,
                       predict=True)
        out[label] = float(np.max(rms_second_half(res)))
    return out


def _plot(log, ident, p_true, path: Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    phi = (log.q_m - log.q)[:, 0]
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    ax[0].plot(phi[::5], log.tau_J[::5, 0], ".", ms=1.5, alpha=0.4, label="log (noisy, offset)")
    grid = np.linspace(phi.min(), phi.max(), 50)
    ax[0].plot(grid, ident.values["K"] * grid + ident.values.get("tau_J_offset1", 0.0), label="identified")
    ax[0].plot(grid, p_true["K"] * grid, "--", label="true")
    ax[0].set(xlabel="deflection q_m - q (rad)", ylabel="tau_J (N m)", title="spring")
    ax[0].legend(fontsize=8)
    names = [k for k in ("K", "J_m", "F_c1") if k in ident.values]
    truth = {"K": p_true["K"], "J_m": p_true["J_m"], "F_c1": ident.settings.get("friction_true", np.nan)}
    err = [100 * (ident.values[k] / truth[k] - 1) for k in names]
    se = [100 * ident.stderr[k] / truth[k] for k in names]
    ax[1].bar(names, err, yerr=se, capsize=4)
    ax[1].axhline(0, color="k", lw=0.8)
    ax[1].set(ylabel="identified - true (%)", title="error, with one standard error")
    return write_figure(fig, path, tight=True)


def identification_section(ctx) -> Tuple[List[str], list]:
    """The section of ``make demo``: ``identification.png`` and the markdown lines."""
    try:
        import mujoco  # noqa: F401 - MuJoCo plays the robot
    except ImportError:
        return ["## Identification from a log", "", "Skipped: needs `mujoco` (the dev extra).", ""], []
    from .. import load
    from ..ident.excite import design_excitation
    from ..ident.identify import identify
    from ..ident.mujoco_robot import B_M, FRICTION, JM_FACTOR, K_FACTOR, mujoco_log, true_params
    t0 = time.perf_counter()
    m = load("link1")
    duration = QUICK_DURATION if ctx.quick else DURATION
    ctx.progress(f"identification: link1, {duration:g} s MuJoCo log")
    exc = design_excitation(m, duration)
    with tempfile.TemporaryDirectory(prefix="fjm-ident-") as tmp:
        log = mujoco_log(m, exc.reference, duration, Path(tmp))
    ident = identify(m, log)
    ident.settings["friction_true"] = FRICTION
    p_true = true_params(m)
    loops = _closed_loops(m, p_true, ident.model_values(m), 4.0 if ctx.quick else 10.0)
    fig = _plot(log, ident, p_true, ctx.out / "identification.png")
    truth = {"K": p_true["K"], "J_m": p_true["J_m"], "B_m": p_true["B_m"], "F_c1": FRICTION}
    rows = ["| parameter | identified | std. error | true | error | written to params.toml |", "|---|---|---|---|---|---|"]
    for k, tv in truth.items():
        v, se = ident.values[k], ident.stderr[k]
        written = "yes" if k in ident.model_values(m) else ("no: not excited" if k in ident.not_excited
                                                            else "no: not a link1 parameter")
        rows.append(f"| {k} | {v:.5g} | {se:.2g} | {tv:.5g} | {100 * (v / tv - 1):+.2f} % | {written} |")
    ctx.results["identification"] = {"errors": {k: ident.values[k] / tv - 1 for k, tv in truth.items()},
                                     "loops": loops}
    md = ["## Identification from a log (`fjm excite`, `fjm identify`)", "",
          f"MuJoCo plays link1 with TRUE drives: K x{K_FACTOR}, J_m x{JM_FACTOR}, B_m = {B_M}, and a dry friction "
          f"(`frictionloss`) of {FRICTION} N m that fjm's model does not have. A {duration:g} s excitation "
          f"(`fjm excite`, regressor condition {exc.condition:.3g}) under a motor PD, logged at 1 kHz with the "
          "`franka_like` sensor levels (quantized noisy encoders, tau_J noise and offset); `fjm identify` sees "
          "only the log:", "", *rows, "",
          f"Fit residuals (RMS): spring {ident.residual['spring 1']:.3g} N m, motor {ident.residual['motor 1']:.3g} "
          f"N m; regressor conditions {ident.condition['spring 1']:.3g}, {ident.condition['motor 1']:.3g}. "
          "What the values buy: the state-sensed integral SMC (gains of `fjm design link1 --params`) in the sampled "
          "loop on the TRUE parameters (1 kHz, panda_white noise, delay 1 with prediction, 0.5 rad sine): worst "
          f"second-half RMS {loops['model defaults']:.3g} rad on the model's default nominal values, "
          f"{loops['identified']:.3g} rad on the identified ones (fjm's plant: without the dry friction; "
          "`examples/identify_roundtrip.py` runs it against MuJoCo's). "
          + ("QUICK MODE: a smoke test, not the documented numbers. " if ctx.quick else "")
          + f"Figure: `{fig.name}`. {time.perf_counter() - t0:.0f} s.", ""]
    return md, [fig]
