"""The paper's link1 experiments as demo sections (``fjm figures``): Lemma 1 gains, Figs 1-4,
the regulation offset, sign vs sat, the controller comparison, the adaptive estimate, anti-windup
and the Monte Carlo study.

Every section is a function ``section(ctx) -> (markdown lines, figure paths)`` of a
:class:`~fjm_runtime.experiments.settings.DemoContext`; :mod:`fjm_runtime.experiments.demo`
runs them in order. The settings (``LAM``, ``K_NOM``, ``Design`` ...) are in
:mod:`fjm_runtime.experiments.settings`.
"""
from __future__ import annotations

from typing import Callable, Dict, List, Tuple

import numpy as np

from .. import load
from ..analysis.certificates.regulation import predict_regulation_offset
from ..control.defaults import PAPER_K_RANGE
from ..control.factory import make_controller
from ..control.laws import coefficients_from_pole
from ..control.references import SmoothStep
from ..sim.simulate import SimulationResult, simulate
from ..sim.step import SimulationDivergedError
from .plots import (REACHED_DEFINITION, plot_controller_comparison, plot_monte_carlo, plot_paper_case,
                    plot_sat_vs_sign, plot_stiffness_estimates)
from .report import METRIC_HEADER, fmt, log, metrics_row
from .settings import (CTRL_LABELS, DURATION, K_BOUNDS, K_CASES, K_NOM, LAM, LAYER_RATE, MC_BOUNDS, TASKS, Design,
                       DemoContext, link1_controller, run_link1)

Section = Tuple[List[str], list]


def intro_section(ctx: DemoContext) -> Section:
    """Title, the quick-mode notice and the common setting."""
    md: List[str] = ["# fjm demo: paper reproduction and beyond", ""]
    if ctx.quick:
        md += [f"**Quick mode** (`fjm figures --quick`): {ctx.duration:g} s runs and {ctx.n_mc} Monte Carlo "
               "samples, a smoke test of the pipeline; run `fjm figures` (`make demo`) for the documented "
               "numbers.", ""]
    md += [f"link1, Table 1 parameters, true K in {list(K_CASES)}; the controller knows only "
           f"K_nom = {K_NOM:g} (T_hat, alpha_hat) and the paper's beta_hat for K in [100, 200]. "
           f"Triple pole at -{LAM:g} (c = {coefficients_from_pole(LAM).tolist()}), boundary layer "
           f"delta = k_s / {LAYER_RATE:g}, RK4 with dt = 1 ms, torque sampled and held every step, "
           f"{ctx.duration:g} s per run.", ""]
    return md, []


def lemma1_section(ctx: DemoContext) -> Section:
    """The Lemma 1 switching gain of each task."""
    md = ["## Lemma 1 switching gain", "",
          "| task | reference | error region E | W (rad/s^4) | H (N m) | beta_hat | rho | "
          "k_s eq (16) | k_s with rho | delta |", "|---|---|---|---|---|---|---|---|---|---|"]
    for task, d in ctx.designs.items():
        g = d.gain
        md.append(f"| {task} | {TASKS[task][2]} | {TASKS[task][1]} | {g.W:.1f} | {g.H:.2f} | "
                  f"{g.beta_hat:.4f} | {g.rho:.3f} | **{g.k_s:.0f}** | {g.k_s_tight:.0f} | {d.delta:.2f} |")
    md += ["", "k_s = W + H / beta_hat + eta (eta = 10) on the region |y_i - y_id| <= E_i; "
           "see `fjm_runtime/analysis/certificates/lemma1.py` for the reading of eq (16). This bounds s in TRUE coordinates; "
           "the controller builds s from T(x; K_nom), so it is not a reaching guarantee for the law that runs "
           "(see \"Certified gains for the law that runs\" below).", ""]
    return md, []


def reproduction_section(ctx: DemoContext) -> Section:
    """Figs 1-4: the paper's law on the three stiffnesses, both tasks (keeps the runs in ``ctx``)."""
    paper: Dict[str, Dict[float, SimulationResult]] = {}
    figs = []
    for task in TASKS:
        ctx.progress(f"paper {task}: K = {', '.join(f'{k:g}' for k in K_CASES)}")
        paper[task] = {K: run_link1("smc", task, K, ctx.designs[task], ctx.link1, duration=ctx.duration)
                       for K in K_CASES}
        fig_name = {"regulation": "fig1_2_regulation.png", "tracking": "fig3_4_tracking.png"}[task]
        figs.append(plot_paper_case(paper[task], task, ctx.designs[task], ctx.out / fig_name))
    ctx.results["paper"] = paper
    md = ["## Paper reproduction (Figs 1-4): sliding-mode control with sat, nominal parameters only", "",
          f"| task | true K | {METRIC_HEADER} |", "|---|---|---|---|---|---|---|---|"]
    for task, per in paper.items():
        for K, r in per.items():
            md.append(metrics_row([task, f"{K:g}"], r))
    md += ["", "Figures: `fig1_2_regulation.png`, `fig3_4_tracking.png`. Reaching time = first time after "
           "which |s| <= delta for the rest of the run (0 when the run starts and stays inside).", ""]
    return md, figs


def offset_section(ctx: DemoContext) -> Section:
    """The paper controller's steady-state regulation offset: predicted vs simulated."""
    md = ["### Steady-state regulation offset of the paper's controller (real, not hidden)", "",
          "With only nominal parameters the controller's y3_hat = (K_nom/K - 1) M g0 L sin(q) / J_l at rest, "
          "so the link rests at c1 e1 + c3 e3_hat = s_ss (inside the layer): "
          "e1 ~ -(3 / lambda^2)(K_nom/K - 1) M g0 L sin(q) / J_l. Predicted by "
          "`analysis.certificates.regulation.predict_regulation_offset` vs simulated:", "",
          "| true K | predicted offset (rad) | first-order term -(c3/c1) e3 at q_d (rad) | simulated e1(end) (rad) |",
          "|---|---|---|---|"]
    d = ctx.designs["regulation"]
    smc_reg = make_controller("smc", ctx.link1, {"K": K_NOM}, lam=LAM, k_s=d.k_s, delta=d.delta,
                              beta_hat=d.beta_hat)
    for K, r in ctx.results["paper"]["regulation"].items():
        pred = predict_regulation_offset(ctx.link1, smc_reg, 1.0, {"K": K})
        md.append(f"| {K:g} | {pred.offset:+.4f} | {pred.first_order:+.4f} | {r.e1[-1, 0]:+.4f} |")
    md.append("")
    return md, []


def chattering_section(ctx: DemoContext) -> Section:
    """sign(s) vs sat(s/delta) on tracking with true K = 100."""
    ctx.progress("sat vs sign")
    K_chat = 100.0
    sign = run_link1("sign", "tracking", K_chat, ctx.designs["tracking"], ctx.link1, duration=ctx.duration)
    sat = ctx.results["paper"]["tracking"][K_chat]
    fig = plot_sat_vs_sign(sat, sign, K_chat, ctx.out / "chattering_sat_vs_sign.png")
    md = ["## Chattering: sign vs sat (tracking, true K = 100)", "",
          f"| switching | {METRIC_HEADER} |", "|---|---|---|---|---|---|---|",
          metrics_row(["sign(s)"], sign), metrics_row(["sat(s/delta)"], sat),
          "", f"Total variation ratio sign/sat = {sign.metrics.total_variation_u / sat.metrics.total_variation_u:.0f}. "
          "Figure: `chattering_sat_vs_sign.png` (the error curves of the two laws coincide to the eye: the "
          "chattering is in the torque, not in the position).", ""]
    return md, [fig]


def comparison_section(ctx: DemoContext) -> Section:
    """Plain FL vs paper SMC vs integral SMC vs the adaptive laws on link1 (keeps the runs in ``ctx``)."""
    comp: Dict[str, Dict[str, Dict[float, SimulationResult]]] = {}
    figs = []
    for task in TASKS:
        ctx.progress(f"controller comparison link1 {task}")
        comp[task] = {"smc": ctx.results["paper"][task]}
        for kind in ("fl", "ismc", "adaptive", "adaptive-paper"):
            comp[task][kind] = {K: run_link1(kind, task, K, ctx.designs[task], ctx.link1, duration=ctx.duration)
                                for K in K_CASES}
        labelled = {kind: {f"K = {K:g}": r for K, r in per.items()} for kind, per in comp[task].items()
                    if kind != "adaptive-paper"}
        figs.append(plot_controller_comparison(
            labelled, f"link1 {task} ({TASKS[task][2]}), K_nom = {K_NOM:g}, lambda = {LAM:g}, "
            f"k_s = {ctx.designs[task].k_s:.0f}", ctx.out / f"compare_link1_{task}.png"))
    ctx.results["comparison"] = comp
    md = ["## Plain feedback linearization vs paper SMC vs integral SMC vs adaptive stiffness (link1, nominal "
          "parameters only)", "",
          "plain FL: nu = y4d' - (c1 e2 + c2 e3 + c3 e4) - lambda s (quadruple pole at -lambda, no switching term); "
          "integral SMC: s = c0 z + c1 e1 + c2 e2 + c3 e3 + e4, z' = e1, quadruple pole at -lambda, same k_s, delta.",
          "", f"| task | controller | true K | {METRIC_HEADER} |", "|---|---|---|---|---|---|---|---|---|"]
    for task, per_kind in comp.items():
        for kind in ("smc", "ismc", "adaptive", "adaptive-paper", "fl"):
            for K, r in per_kind[kind].items():
                md.append(metrics_row([task, CTRL_LABELS[kind], f"{K:g}"], r))
    md += ["", "Figures: `compare_link1_regulation.png`, `compare_link1_tracking.png` (the adaptive controller "
           "with the paper's surface is in the table only).", ""]
    return md, figs


def _adaptive_rows(comp, designs, model) -> List[str]:
    rows = []
    for task, per_kind in comp.items():
        for kind in ("adaptive", "adaptive-paper"):
            c = link1_controller(kind, designs[task], model)
            for K, r in per_kind[kind].items():
                kh = c.stiffness_estimate(r.z)[:, 0]
                at = lambda ts: kh[min(int(round(ts / (r.t[1] - r.t[0]))), kh.size - 1)]
                rms = r.metrics.rms_error_second_half
                ratio = lambda other: ("-" if K == K_NOM else
                                       f"{comp[task][other][K].metrics.rms_error_second_half / rms:.3g}")
                rows.append(f"| {task} | {'integral' if kind == 'adaptive' else 'paper'} | {K:g} | {at(1.0):.3f} | "
                            f"{at(5.0):.3f} | {kh[-1]:.4f} | {fmt(rms)} | {ratio('ismc')} | {ratio('smc')} |")
    return rows


def _adaptive_verdict(comp) -> List[str]:
    verdict = []
    for task in comp:
        for K in K_CASES:
            if K == K_NOM:
                continue
            a, i = comp[task]["adaptive"][K].metrics, comp[task]["ismc"][K].metrics
            verdict.append(f"{task}, K = {K:g}: RMS 2nd half {fmt(a.rms_error_second_half)} vs "
                           f"{fmt(i.rms_error_second_half)}, whole-run RMS {fmt(a.rms_error)} vs "
                           f"{fmt(i.rms_error)}, final {fmt(a.final_error)} vs {fmt(i.final_error)}")
    return ["**Does it beat the integral surface?** (adaptive + integral vs integral SMC) " + "; ".join(verdict)
            + ". Tracking: yes, by two orders of magnitude, because K_hat removes the T_hat mismatch that the "
            "integral term can only chase. Regulation: no at steady state (the integrator already drives e1 to "
            "zero for any constant mismatch, and the still-moving K_hat keeps the adaptive loop about 1e-6 rad "
            "away at 10 s), but the transient (whole-run RMS) is smaller. With the paper's surface the estimate "
            "removes the regulation offset (final abs(e1) "
            + ", ".join(f"K = {K:g}: {fmt(comp['regulation']['smc'][K].metrics.final_error)} -> "
                        f"{fmt(comp['regulation']['adaptive-paper'][K].metrics.final_error)} rad"
                        for K in K_CASES if K != K_NOM) + ").", ""]


def adaptive_section(ctx: DemoContext) -> Section:
    """Summary lines and the K_hat figure of the adaptive-stiffness controllers."""
    comp, designs, model = ctx.results["comparison"], ctx.designs, ctx.link1
    fig = plot_stiffness_estimates(comp, designs, ctx.out / "adaptive_stiffness_link1.png", model)
    ctrl = link1_controller("adaptive", designs["tracking"], model)
    md = ["### Adaptive stiffness estimate", "",
          f"`fjm_runtime.control.adaptive`: per joint, the motor equation J_m ddq_m + B_m dq_m + K (q_m - q_l) = u "
          f"is filtered by a / (s + a) (a = {ctrl.filter_rate:g} 1/s; no differentiation), giving "
          "y_f = u_f - J_m a (dq_m - w_f) - B_m w_f = K phi_f; continuous least squares "
          f"K_hat' = P phi_f (y_f - K_hat phi_f), P' = -P^2 phi_f^2, P(0) = {ctrl.ls_gain:g}, projected onto "
          f"{list(K_BOUNDS['K'])}; K_hat replaces K in T_hat, alpha_hat and beta(x; K_hat). Measured: full "
          "state and the applied u; J_m, B_m nominal (exact here, so the estimate is unbiased). K is "
          "learned only while the joint is deflected (gravity away from q = 0, link acceleration).", "",
          "| task | surface | true K | K_hat(1 s) | K_hat(5 s) | K_hat(10 s) | RMS e1 2nd half (rad) | "
          "integral SMC / adaptive | paper SMC / adaptive |", "|---|---|---|---|---|---|---|---|---|"]
    md += _adaptive_rows(comp, designs, model)
    md += ["", "Figure: `adaptive_stiffness_link1.png`. With K_true = K_nom nothing is learned (zero prediction "
           "error) and the adaptive controllers coincide with the non-adaptive ones up to beta(x; K_nom) vs the "
           "constant beta_hat. The least-squares error is (K - K_nom) / (1 + P(0) int phi_f^2): it decays like "
           "1 / t once the joint is deflected, so the residual tracking error is set by P(0) (about 1 / P(0); "
           "P(0) phi^2 dt must stay well below the RK4 stability limit 2.8).", ""]
    md += _adaptive_verdict(comp)
    return md, [fig]


def anti_windup_section(ctx: DemoContext) -> Section:
    """Integral SMC under a 10 N m torque limit, with and without conditional integration."""
    ctx.progress("integral SMC with torque limit (anti-windup)")
    d = ctx.designs["regulation"]
    md = ["### Integral SMC under a torque limit (anti-windup)", "",
          "Regulation 0 -> 1 rad with a faster 1 s smooth step (needs ~20 N m unconstrained), u_max = 10 N m "
          "(holding 1 rad needs 8.25 N m). Anti-windup = conditional integration: z_i is frozen while joint i "
          "is saturated and e1_i would push it further into the limit.", "",
          "| true K | anti-windup | overshoot (rad) | final abs(e1) (rad) | max abs(z) (rad s) | max abs(u) (N m) |",
          "|---|---|---|---|---|---|"]
    for K in PAPER_K_RANGE:
        for aw in (True, False):
            ctrl = make_controller("ismc", ctx.link1, {"K": K_NOM}, lam=LAM, k_s=d.k_s, delta=d.delta,
                                   beta_hat=d.beta_hat, u_max=10.0, anti_windup=aw)
            r = simulate(ctx.link1, ctrl, SmoothStep(1.0, rise_time=1.0), duration=ctx.duration,
                         true_params={"K": K})
            md.append(f"| {K:g} | {'on' if aw else 'off'} | {np.max(r.e1[:, 0]):.4f} | {fmt(abs(r.e1[-1, 0]))} | "
                      f"{np.max(np.abs(r.z)):.4f} | {r.metrics.max_abs_u:.2f} |")
    md.append("")
    return md, []


def monte_carlo(n_samples: int, design: Design, factors=(1.0, 0.1, 0.02, 0.0), seed: int = 7,
                progress: Callable[[str], None] = log, duration: float = DURATION):
    """Tracking with K ~ U[100, 200], J_l, J_m ~ U[+-20 %]; k_s = factor x Lemma 1 bound (fixed delta).

    Returns
    -------
    dict factor -> dict with arrays ``e1`` (samples, N+1), ``reach`` (samples,), ``rms`` (samples,),
    ``umax`` (samples,), ``diverged`` count, ``t`` (N+1,), ``k_s``; and the list of sampled parameters.
    """
    m = load("link1")
    rng = np.random.default_rng(seed)
    samples = [{k: float(rng.uniform(*b)) for k, b in MC_BOUNDS.items()} for _ in range(n_samples)]
    ref = TASKS["tracking"][0]()
    out = {}
    for f in factors:
        e1, reach, rms, umax, diverged, t = [], [], [], [], 0, None
        for p in samples:
            ctrl = make_controller("smc", m, {"K": K_NOM}, lam=LAM, k_s=f * design.k_s, delta=design.delta,
                                   beta_hat=design.beta_hat)
            try:
                r = simulate(m, ctrl, ref, duration=duration, true_params=p)
            except SimulationDivergedError:
                diverged += 1
                continue
            e1.append(r.e1[:, 0]); reach.append(r.metrics.reaching_time)
            rms.append(r.metrics.rms_error_second_half); umax.append(r.metrics.max_abs_u)
            t = r.t
        progress(f"  Monte Carlo k_s = {f:g} x bound: {n_samples} samples done")
        out[f] = dict(e1=np.array(e1), reach=np.array(reach), rms=np.array(rms), umax=np.array(umax),
                      diverged=diverged, t=t, k_s=f * design.k_s)
    return out, samples


def monte_carlo_section(ctx: DemoContext) -> Section:
    """The Monte Carlo study: table, CSV and figure."""
    n_mc = ctx.n_mc
    ctx.progress(f"Monte Carlo ({n_mc} samples x 4 gains)")
    mc_design = Design.for_task("tracking", MC_BOUNDS)
    mc, _ = monte_carlo(n_mc, mc_design, progress=ctx.progress, duration=ctx.duration)
    fig = plot_monte_carlo(mc, mc_design, n_mc, ctx.out / "monte_carlo.png")
    md = ["## Monte Carlo robustness (tracking)", "",
          f"{n_mc} samples (seed 7): K ~ U[100, 200], J_l ~ U[0.8, 1.2], J_m ~ U[1.6, 2.4]; controller nominal "
          f"K = 150, J_l = 1, J_m = 2, beta_hat = {mc_design.beta_hat:.4f} (midpoint over the whole box), "
          f"delta = {mc_design.delta:.2f} fixed; Lemma 1 bound over the box k_s = {mc_design.k_s:.0f}. "
          f"Reached layer: {REACHED_DEFINITION.split(' = ', 1)[1]} (reaching time finite).", "",
          "| k_s / bound | k_s | reached layer | diverged | median reaching (s) | max reaching (s) | "
          "max RMS e1 2nd half (rad) | median RMS e1 2nd half (rad) | max abs(u) (N m) |",
          "|---|---|---|---|---|---|---|---|---|"]
    lines_csv = []
    for f, d in mc.items():
        reach = d["reach"]
        ok = np.isfinite(reach)
        md.append(f"| {f:g} | {d['k_s']:.0f} | {ok.sum()}/{n_mc} | {d['diverged']} | "
                  f"{fmt(np.median(reach[ok])) if ok.any() else '-'} | {fmt(np.max(reach[ok])) if ok.any() else '-'} | "
                  f"{fmt(np.max(d['rms']))} | {fmt(np.median(d['rms']))} | {fmt(np.max(d['umax']))} |")
        lines_csv.append(f"{f},{d['k_s']:.3f},{ok.sum()},{n_mc},{d['diverged']},"
                         f"{np.max(d['rms']):.6g},{np.median(d['rms']):.6g}")
    (ctx.out / "monte_carlo.csv").write_text("factor,k_s,reached,samples,diverged,max_rms,median_rms\n"
                                             + "\n".join(lines_csv) + "\n")
    md += ["", "Figure: `monte_carlo.png`; table also in `monte_carlo.csv`. The RMS error is dominated by the "
           "T_hat mismatch on the sliding surface, not by reaching: see the integral SMC above.", ""]
    return md, [fig]
