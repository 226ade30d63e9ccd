"""Matplotlib figures of the demo (``fjm figures``); one run's figure is :meth:`SimulationResult.plot`.

Every figure is written at 110 dpi and meant to be read at 100 %: references are drawn
dashed on top of the curves, legends sit outside the data or hold few entries, titles fit
the canvas (constrained layout).
"""
from __future__ import annotations

import contextlib

from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np

from ..sim.plot import pyplot
from .report import log
from .settings import COLORS, CTRL_COLORS, CTRL_LABELS, K_BOUNDS, K_NOM, LAM, TASKS, link1_controller

#: Line style per controller in the comparisons (colour alone does not separate overlapping curves).
CTRL_STYLES = {"smc": "-", "ismc": "--", "fl": ":", "sign": "-", "adaptive": "-", "adaptive-paper": "-."}
#: Drawing order: the adaptive law last (on top), plain FL first.
CTRL_ORDER = ("fl", "smc", "ismc", "adaptive-paper", "adaptive", "sign")
REF_STYLE = dict(color="k", ls=(0, (4, 2)), lw=1.3, zorder=10)


#: Resolution of the written figures (dots per inch); :func:`resolution` changes it for a run.
DPI = {"value": 110}


@contextlib.contextmanager
def resolution(dpi: int):
    """Write the figures of the ``with`` block at ``dpi`` (the quick demo: a smoke test, not for reading)."""
    old, DPI["value"] = DPI["value"], int(dpi)
    try:
        yield
    finally:
        DPI["value"] = old


def write_figure(fig, path, dpi: int = 110, tight: bool = False) -> Path:
    """Write ``fig`` to ``path`` at ``dpi`` (its directory created when missing), close it; returns ``path``."""
    path = Path(path)
    if tight:
        fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    pyplot().close(fig)
    return path


def save(fig, path: Path, tight: bool = True) -> Path:
    """Write ``fig`` to ``path`` (110 dpi, see :func:`resolution`), close it, log the path; returns ``path``."""
    write_figure(fig, path, DPI["value"], tight)
    log(f"  wrote {path}")
    return Path(path)


def settled_limit(t, s, t_from: float, floor: float = 1e-9) -> float:
    """Symmetric y limit of a sliding variable after ``t_from``: 1.3 x its largest abs value there.

    Parameters
    ----------
    t : ndarray, shape (N,)
    s : ndarray, shape (N, n)
    t_from : float
        End of the reaching phase, s (the data before it may be off scale).
    """
    late = t >= min(t_from, t[-1])
    return max(1.3 * float(np.max(np.abs(s[late]))), floor)


def reaching_end(results: Sequence, default: float = 0.5) -> float:
    """Largest finite reaching time of ``results`` (each with ``metrics``), at least ``default`` s."""
    times = [r.metrics.reaching_time for r in results if np.isfinite(r.metrics.reaching_time)]
    return max([default] + times)


def plot_paper_case(results: Dict[float, object], task: str, design, path: Path) -> Path:
    """2 x 2 panel like the paper's Figs 1-4: positions, error, torque, sliding variable."""
    plt = pyplot()
    fig, ax = plt.subplots(2, 2, figsize=(12, 7.5), sharex=True)
    first = next(iter(results.values()))
    for K, r in results.items():
        c = COLORS.get(K, None)
        ax[0, 0].plot(r.t, r.x[:, 0], color=c, lw=1.5, label=f"link $q_l$, K = {K:g}")
        ax[0, 0].plot(r.t, r.x[:, 2], color=c, lw=0.9, ls=":", label=f"motor $q_m$, K = {K:g}")
        ax[0, 1].plot(r.t, r.e1[:, 0], color=c, label=f"K = {K:g} N m/rad")
        ax[1, 0].plot(r.t, r.u[:, 0], color=c, label=f"K = {K:g}")
        ax[1, 1].plot(r.t, r.s[:, 0], color=c, label=f"K = {K:g}")
    ax[0, 0].plot(first.t, first.ref[:, 0, 0], label="reference $q_d$ (dashed, on top)", **REF_STYLE)
    t_from = reaching_end(results.values())
    s_lim = settled_limit(first.t, np.concatenate([r.s for r in results.values()], axis=1), t_from)
    ax[1, 1].axhspan(-design.delta, design.delta, color="0.88", zorder=0,
                     label=rf"boundary layer $|s| \leq \delta$ = {design.delta:.2f}")
    ax[0, 0].set(title="Link and motor angles", ylabel="angle (rad)")
    ax[0, 1].set(title=r"Link position error $e_1 = q_l - q_d$", ylabel="error (rad)")
    ax[1, 0].set(title="Control torque", ylabel="u (N m)", xlabel="time (s)")
    ax[1, 1].set(title=rf"Sliding variable $s$ (from nominal $\hat T$), scaled to t $\geq$ {t_from:.2g} s",
                 ylabel=r"s (rad/s$^3$)", xlabel="time (s)", ylim=(-s_lim, s_lim))
    peak = max(float(np.max(np.abs(r.s[r.t < t_from]))) if np.any(r.t < t_from) else 0.0
               for r in results.values())
    if peak > s_lim:
        ax[1, 1].annotate(f"reaching phase t < {t_from:.2g} s: max abs(s) = {peak:.3g} (off scale)",
                          xy=(0.02, 0.04), xycoords="axes fraction", fontsize=8.5)
    for a in ax.flat[:3]:
        a.legend(loc="best", ncol=1)
    ax[1, 1].legend(loc="upper right", ncol=2, fontsize=8)  # clear of the off-scale note (lower left)
    fig.suptitle(f"link1 {task} ({TASKS[task][2]}): controller uses K_nom = {K_NOM:g}, "
                 f"beta_hat = {design.beta_hat:.4f}, k_s = {design.k_s:.0f} (Lemma 1), "
                 f"lambda = {LAM:g}", fontsize=11)
    return save(fig, path)


def plot_sat_vs_sign(sat, sign, K: float, path: Path) -> Path:
    """Chattering: torque (full run, zoom), error, sliding variable (zoom) of sign(s) vs sat(s/delta).

    The zooms cover 50 ms from the middle of the run (5.00-5.05 s for 10 s); their legends sit
    outside the axes, clear of the sign peaks. The error curves of the two laws nearly coincide:
    sat is drawn dashed on top of sign, and the legend says so.
    """
    plt = pyplot()
    fig, ax = plt.subplots(2, 2, figsize=(13, 7), layout="constrained")
    t0 = 0.5 * float(sat.t[-1])
    scale = max(float(np.max(np.abs(sat.e1))), 1e-12)
    gap = float(np.max(np.abs(sat.e1 - sign.e1))) / scale
    for r, kind, ls, lw in ((sign, "sign", "-", 2.2), (sat, "sat", "--", 1.2)):
        c = CTRL_COLORS["sign" if kind == "sign" else "smc"]
        ax[0, 0].plot(r.t, r.u[:, 0], color=c, lw=0.8, label=f"{kind}: TV(u) = {r.metrics.total_variation_u:.3g} N m")
        win = (r.t >= t0) & (r.t <= t0 + 0.05)
        mk = ".-" if kind == "sign" else "-"
        ax[0, 1].plot(r.t[win], r.u[win, 0], mk, ms=3, color=c, label=kind)
        ax[1, 0].plot(r.t, r.e1[:, 0], color=c, ls=ls, lw=lw,
                      label=kind if kind == "sign" else f"sat (dashed, on top: the curves differ by at most "
                                                        f"{100 * gap:.2g} % of max abs(e1))")
        ax[1, 1].plot(r.t[win], r.s[win, 0], mk, ms=3, color=c, label=kind)
    ax[0, 0].set(title="Control torque (full run)", ylabel="u (N m)", xlabel="time (s)")
    ax[0, 1].set(title=f"Control torque, zoom {t0:.2f}-{t0 + 0.05:.2f} s (1 ms samples)", ylabel="u (N m)",
                 xlabel="time (s)")
    ax[1, 0].set(title=r"Link position error $e_1$ (sign and sat nearly coincide)", ylabel="error (rad)",
                 xlabel="time (s)")
    ax[1, 1].set(title=f"Sliding variable, zoom {t0:.2f}-{t0 + 0.05:.2f} s", ylabel=r"s (rad/s$^3$)",
                 xlabel="time (s)")
    ax[0, 0].legend(loc="best")
    ax[1, 0].legend(loc="best")
    for a in (ax[0, 1], ax[1, 1]):  # zooms: the legend right of the axes, clear of the sign peaks
        a.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    fig.suptitle(f"Chattering: sign(s) vs sat(s/delta), link1 tracking, true K = {K:g}, K_nom = {K_NOM:g}",
                 fontsize=11)
    return save(fig, path, tight=False)


def plot_controller_comparison(results: Dict[str, Dict[str, object]], title: str, path: Path) -> Path:
    """Small multiples: columns = true stiffness cases; rows = e1 then u, one row pair per joint.

    One line per controller (colour and line style; the adaptive law drawn last, on top), one legend
    below the panels with one entry per controller.
    """
    plt = pyplot()
    cases = list(next(iter(results.values())).keys())
    n = next(iter(next(iter(results.values())).values())).e1.shape[1]
    kinds = [k for k in CTRL_ORDER if k in results] + [k for k in results if k not in CTRL_ORDER]
    rows = 2 * n
    fig, ax = plt.subplots(rows, len(cases), figsize=(4.6 * len(cases), 2.3 * rows + 1.2), sharex=True,
                           squeeze=False, layout="constrained")
    for j, case in enumerate(cases):
        for kind in kinds:
            r = results[kind][case]
            style = dict(color=CTRL_COLORS.get(kind), ls=CTRL_STYLES.get(kind, "-"),
                         lw=1.8 if kind == "adaptive" else 1.2, label=CTRL_LABELS.get(kind, kind))
            for i in range(n):
                ax[i, j].plot(r.t, r.e1[:, i], **style)
                ax[n + i, j].plot(r.t, r.u[:, i], **style)
        for i in range(n):
            jl = f" joint {i + 1}" if n > 1 else ""
            ax[i, j].set_title(f"error{jl}, true {case}", fontsize=9.5)
            ax[n + i, j].set_title(f"torque{jl}, true {case}", fontsize=9.5)
            if j == 0:
                ax[i, j].set_ylabel(r"$e_1$ (rad)")
                ax[n + i, j].set_ylabel("u (N m)")
            late = [np.max(np.abs(per[case].u[per[case].t >= 0.5, i])) for per in results.values()]
            peak = max(np.max(np.abs(per[case].u[:, i])) for per in results.values())
            if peak > 3 * max(late) > 0:
                ax[n + i, j].set_ylim(-1.3 * max(late), 1.3 * max(late))
                ax[n + i, j].annotate(f"peak abs(u) = {peak:.0f} N m before 0.5 s (off scale)",
                                      xy=(0.03, 0.04), xycoords="axes fraction", fontsize=8)
        ax[-1, j].set_xlabel("time (s)")
    handles, labels = ax[0, 0].get_legend_handles_labels()
    fig.suptitle(title, fontsize=10.5)
    fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), fontsize=9, frameon=False)
    return save(fig, path, tight=False)


def plot_stiffness_estimates(comp, designs, path: Path, model=None) -> Path:
    """K_hat(t) (top) and |K_hat - K| on a log scale (bottom) of the adaptive controllers, one column per task."""
    plt = pyplot()
    fig, ax = plt.subplots(2, len(comp), figsize=(6.2 * len(comp), 7.5), sharex=True, squeeze=False)
    for j, (task, per_kind) in enumerate(comp.items()):
        for kind, ls in (("adaptive", "-"), ("adaptive-paper", "--")):
            ctrl = link1_controller(kind, designs[task], model)
            for K, r in per_kind[kind].items():
                kh = ctrl.stiffness_estimate(r.z)[:, 0]
                lab = f"{CTRL_LABELS[kind]}, true K = {K:g}"
                ax[0, j].plot(r.t, kh, color=COLORS.get(K), ls=ls, lw=1.3, label=lab)
                if K != K_NOM:
                    ax[1, j].semilogy(r.t, np.abs(kh - K), color=COLORS.get(K), ls=ls, lw=1.3, label=lab)
        for b in K_BOUNDS["K"]:
            ax[0, j].axhline(b, color="0.5", lw=0.8, ls=":")
        ax[0, j].set(title=f"{task} ({TASKS[task][2]})", ylabel=r"$\hat K$ (N m/rad)")
        ax[1, j].set(title="estimation error (K = 150 learns nothing: zero error)", xlabel="time (s)",
                     ylabel=r"$|\hat K - K|$ (N m/rad)")
        ax[0, j].legend(loc="center right", fontsize=7.5)
        ax[1, j].legend(loc="best", fontsize=7.5)
    fig.suptitle(f"Online stiffness estimate (filtered motor-side least squares, K_hat(0) = K_nom = {K_NOM:g}, "
                 f"projected onto {list(K_BOUNDS['K'])})", fontsize=11)
    return save(fig, path)


#: What "reached" means in the Monte Carlo figure and table.
REACHED_DEFINITION = ("reached = share of the samples whose sliding variable enters the boundary layer "
                      "|s| <= delta and stays there until the end of the run")


def plot_monte_carlo(mc, design, n_samples: int, path: Path) -> Path:
    """Envelope of e1 and the empirical CDF of the RMS error per gain factor; legend below the panels."""
    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(13, 5.6), layout="constrained")
    colors = ["tab:blue", "tab:green", "tab:orange", "tab:red", "tab:purple"]
    for (f, d), c in zip(mc.items(), colors):
        if d["e1"].size == 0:
            continue
        lo, hi = d["e1"].min(axis=0), d["e1"].max(axis=0)
        frac = np.mean(np.isfinite(d["reach"]))
        ax[0].fill_between(d["t"], lo, hi, color=c, alpha=0.25)
        ax[0].plot(d["t"], hi, color=c, lw=0.8,
                   label=f"k_s = {f:g} x bound ({d['k_s']:.0f}): reached {100 * frac:.0f} %")
        ax[0].plot(d["t"], lo, color=c, lw=0.8)
        ax[1].plot(np.sort(d["rms"]), np.arange(1, d["rms"].size + 1) / d["rms"].size, "o-", color=c, ms=3)
    ax[0].set(title=f"Envelope (min/max) of tracking error over {n_samples} samples",
              xlabel="time (s)", ylabel=r"$e_1$ (rad)")
    ax[1].set(title="Empirical CDF of RMS error (second half)", xlabel="RMS $e_1$ (rad)",
              ylabel="fraction of samples")
    ax[1].set_xscale("log")
    handles, labels = ax[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=2, fontsize=9, frameon=False,
               title=REACHED_DEFINITION, title_fontsize=8.5)
    fig.suptitle("Monte Carlo: K ~ U[100, 200], J_l, J_m ~ U[+-20 %]; controller: K_nom = 150, J nominal, "
                 f"beta_hat = {design.beta_hat:.4f}, delta = {design.delta:.2f}", fontsize=11)
    return save(fig, path, tight=False)
