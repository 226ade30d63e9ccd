"""Demo sections on the planar chains (``fjm figures``): the per-joint law on planar2 and planar3
under stiffness mismatch, the closed-loop eigenvalues at rest, and the nominal stiffness at the
lower bound. Each section is ``section(ctx) -> (markdown lines, figure paths)``.
"""
from __future__ import annotations

from typing import Dict, List, Tuple

from .. import load
from ..analysis.certificates.regulation import closed_loop_eigenvalues
from ..control.defaults import DEFAULT_SWITCHING_GAIN, default_delta
from ..control.factory import make_controller
from ..drives import role_names
from ..sim.simulate import SimulationResult, simulate
from ..sim.step import SimulationDivergedError
from .plots import plot_controller_comparison
from .report import METRIC_HEADER, diverged_row, metrics_row
from .settings import CTRL_LABELS, K_NOM, LAM, LAYER_RATE, DemoContext, chain_reference

Section = Tuple[List[str], list]
#: True stiffness cases of each chain (the first two are plotted).
N_LINK_CASES = {"planar2": [(165.0, 180.0), (200.0, 200.0), (100.0, 100.0)],
                "planar3": [(165.0, 180.0, 170.0), (200.0, 200.0, 200.0), (100.0, 100.0, 100.0)]}


def _chain_runs(ctx: DemoContext, name: str, md: List[str]) -> Dict[str, Dict[str, SimulationResult]]:
    """Every controller and gain on every case of ``name``; rows appended to ``md``; the k_s = 20000 runs."""
    mn = load(name)
    n = mn.n
    ref = chain_reference(n)
    K_names = role_names(mn, "stiffness")
    nominal = {k: K_NOM for k in K_names}
    per_kind: Dict[str, Dict[str, SimulationResult]] = {}
    for kind in ("smc", "ismc", "adaptive", "fl"):
        per_kind[kind] = {}
        for k_s in ((0.0,) if kind == "fl" else (DEFAULT_SWITCHING_GAIN, 20000.0)):
            for Ks in N_LINK_CASES[name]:
                true = dict(zip(K_names, Ks))
                label = "K = (" + ", ".join(f"{k:g}" for k in Ks) + ")"
                ctrl = make_controller(kind, mn, nominal, lam=LAM, k_s=k_s, delta=default_delta(k_s))
                try:
                    r = simulate(mn, ctrl, ref, duration=ctx.duration, true_params=true)
                except SimulationDivergedError as exc:
                    md.append(diverged_row([name, CTRL_LABELS[kind], f"{k_s:g}", label], exc.t))
                    continue
                if k_s != DEFAULT_SWITCHING_GAIN:
                    per_kind[kind][label] = r
                md.append(metrics_row([name, CTRL_LABELS[kind], f"{k_s:g}", label], r))
    return per_kind


def chains_section(ctx: DemoContext) -> Section:
    """planar2 / planar3 tracking with stiffness mismatch: table and one comparison figure each."""
    md = ["## n links: the same per-joint law on planar2 and planar3 (stiffness mismatch)", "",
          f"Controller: nominal K_i = {K_NOM:g} for every joint (all other parameters exact), beta_hat(x) from "
          f"the nominal model, lambda = {LAM:g}, delta = k_s / {LAYER_RATE:g}; the Lemma 1 gain is derived for "
          "link1 only, so two gains are shown: k_s = 1000 (about the link1 bound) and k_s = 20000. The light "
          "distal links make alpha_hat - alpha much larger than on link1 (the J_m / D_ii factor), so the "
          "switching gain that keeps sliding is an order of magnitude larger. Reference per joint: "
          "0.5 sin(t), 0.3 sin(1.5 t + 0.5), 0.2 sin(2 t). Figures use k_s = 20000. The adaptive controller "
          "estimates each K_i from its own motor (Jm_i, Bm_i nominal), projected onto [100, 200], integral "
          "surface, beta(x; K_hat).", "",
          f"| model | controller | k_s | true stiffness | {METRIC_HEADER} |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    figs = []
    for name in N_LINK_CASES:
        ctx.progress(f"{name} tracking with stiffness mismatch")
        per_kind = _chain_runs(ctx, name, md)
        cases = [lab for lab in per_kind["smc"] if all(lab in per_kind[k] for k in per_kind)][:2]
        figs.append(plot_controller_comparison(
            {k: {c: v[c] for c in cases} for k, v in per_kind.items()},
            f"{name} tracking, nominal K_i = {K_NOM:g}, k_s = 20000", ctx.out / f"compare_{name}_tracking.png"))
    md += ["", "Figures: `compare_planar2_tracking.png`, `compare_planar3_tracking.png`.", ""]
    return md, figs


def eigenvalue_section(ctx: DemoContext) -> Section:
    """Largest real part of the closed-loop eigenvalues at the hanging rest point."""
    md = ["Largest real part of the closed-loop eigenvalues, linearized at the hanging rest point "
          "(continuous time, no sampling; `analysis.certificates.regulation.closed_loop_eigenvalues`), controller nominal "
          "K_i = 150:", "",
          "| model | controller | " + " | ".join(f"K_i = {k:g}" for k in (100, 140, 150, 160, 200)) + " |",
          "|---|---|---|---|---|---|---|"]
    for name in ("link1", "planar2", "planar3"):
        mn = load(name)
        names = role_names(mn, "stiffness")
        for kind in ("smc", "fl"):
            ctrl = make_controller(kind, mn, {k: K_NOM for k in names}, lam=LAM, k_s=DEFAULT_SWITCHING_GAIN,
                                   delta=default_delta(DEFAULT_SWITCHING_GAIN))
            cells = [f"{closed_loop_eigenvalues(mn, ctrl, {k: K for k in names})[0].real:+.2f}"
                     for K in (100.0, 140.0, 150.0, 160.0, 200.0)]
            md.append(f"| {name} | {CTRL_LABELS[kind]} | " + " | ".join(cells) + " |")
    md += ["", "Positive = unstable rest point. With the boundary-layer gain (k_s / delta = 200 1/s) the rest "
           "point stays locally stable on all three models; plain FL loses it on the chains when the true "
           "stiffness is below the nominal one (and planar3 also at K_i = 200). Local stability is not enough: "
           "with k_s = 1000 the chains leave the boundary layer and diverge at K_i = 100 (table above).", ""]
    return md, []


def low_nominal_section(ctx: DemoContext) -> Section:
    """The chains with the nominal stiffness at the lower bound of the range."""
    k_low = 100.0
    md = [f"### Nominal stiffness at the lower bound (K_nom = {k_low:g}) on the chains", "",
          "Same reference, lambda, delta = k_s / 200 and k_s = 20000 as above, every joint with the same "
          "true stiffness. Underestimating the stiffness avoids the divergence seen above at K_nom = 150 "
          "for equal stiffnesses over the whole range [100, 200] (not for unequal ones: on planar3, e.g. "
          "K = (200, 100, 150) diverges; see tests/scenarios/test_chain_stability.py); the "
          "accuracy still degrades as the true stiffness moves away from the nominal one, much less with "
          "the integral surface than with the paper's.", "",
          f"| model | controller | true stiffness | {METRIC_HEADER} |", "|---|---|---|---|---|---|---|---|---|"]
    for name in ("planar2", "planar3"):
        ctx.progress(f"{name} with K_nom = {k_low:g}")
        mn = load(name)
        n = mn.n
        ref = chain_reference(n)
        for kind in ("smc", "ismc"):
            for K in (100.0, 150.0, 200.0):
                ctrl = make_controller(kind, mn, {k: k_low for k in role_names(mn, "stiffness")}, lam=LAM, k_s=20000.0,
                                       delta=20000.0 / LAYER_RATE)
                label = f"K_i = {K:g}"
                try:
                    r = simulate(mn, ctrl, ref, duration=ctx.duration,
                                 true_params={k: K for k in role_names(mn, "stiffness")})
                except SimulationDivergedError as exc:
                    md.append(diverged_row([name, CTRL_LABELS[kind], label], exc.t))
                    continue
                md.append(metrics_row([name, CTRL_LABELS[kind], label], r))
    md.append("")
    return md, []
