"""Matplotlib figure of one closed-loop run (:meth:`fjm_runtime.sim.simulate.SimulationResult.plot`).

matplotlib is an optional dependency (the ``plot`` extra): it is imported inside
:func:`pyplot`, never at import time, so the runtime runs without it.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

from ..validation import FjmValueError

#: Resolution of the written figures (dots per inch).
DPI = 110


def pyplot():
    """``matplotlib.pyplot`` with the Agg backend (no display needed) and the project's style.

    Raises
    ------
    FjmValueError
        matplotlib is not installed (the message says how to install it).
    """
    try:
        import matplotlib
    except ImportError:
        raise FjmValueError("plotting needs matplotlib, which is not installed: "
                            "pip install 'fjm[plot]' (or pip install matplotlib)") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    plt.rcParams.update({"font.size": 10, "axes.grid": True, "grid.alpha": 0.3,
                         "legend.fontsize": 8.5, "figure.dpi": 100})
    return plt


def plot_run(res, title: str = "", path: Optional[Path] = None, dpi: int = DPI):
    """Angles, error, torque and sliding variable of one run, in a 2 x 2 figure.

    Panels with more than 3 joints get one legend below the panels (one entry per joint colour,
    the line styles explained in the titles) instead of a legend per panel.

    Parameters
    ----------
    res : SimulationResult
        ``n`` joints: link angles ``res.x[:, :n]`` and motor angles ``res.x[:, 2n:3n]`` (rad),
        reference ``res.ref[:, 0]`` (rad), error ``res.e1`` (rad), torque ``res.u`` (N m),
        sliding variable ``res.s`` (rad/s^3) against ``res.t`` (s).
    title : str
        The figure's title.
    path : path-like, optional
        Where to write the figure (``dpi`` dots per inch); the figure stays open either way.
    dpi : int
        Resolution of the written file.

    Returns
    -------
    matplotlib.figure.Figure
        Axes ``[0, 0]`` angles, ``[0, 1]`` error, ``[1, 0]`` torque, ``[1, 1]`` sliding variable.
    """
    plt = pyplot()
    n = res.e1.shape[1]
    fig, ax = plt.subplots(2, 2, figsize=(12, 7.5), sharex=True, layout="constrained")
    for i in range(n):
        sfx = f"joint {i + 1}" if n > 1 else ""
        line, = ax[0, 0].plot(res.t, res.x[:, i], lw=1.5, label=sfx or "link $q_l$")
        c = line.get_color()
        ax[0, 0].plot(res.t, res.x[:, 2 * n + i], ls=":", lw=1.0, color=c, label=None if n > 1 else "motor $q_m$")
        ax[0, 0].plot(res.t, res.ref[:, 0, i], color=c if n > 1 else "k", ls=(0, (4, 2)), lw=1.0, zorder=10,
                      label=None if n > 1 else "reference (dashed)")
        ax[0, 1].plot(res.t, res.e1[:, i], color=c)
        ax[1, 0].plot(res.t, res.u[:, i], color=c)
        ax[1, 1].plot(res.t, res.s[:, i], color=c)
    d = float(np.max(res.delta))
    if np.isfinite(d):
        ax[1, 1].axhspan(-d, d, color="0.88", zorder=0, label=rf"$|s| \leq \delta$ = {d:.3g}")
    late = res.t > 0.05 * res.t[-1]
    lim = max(5 * d if np.isfinite(d) else 0, 1.2 * float(np.max(np.abs(res.s[late]))))
    ax[1, 1].set_ylim(-lim, lim)
    ax[0, 0].set(title="Angles: link (solid), motor (dotted), reference (dashed)", ylabel="rad")
    ax[0, 1].set(title=r"Link position error $e_1 = q_l - q_d$", ylabel="rad")
    ax[1, 0].set(title="Control torque", ylabel="N m", xlabel="time (s)")
    ax[1, 1].set(title="Sliding variable", ylabel=r"rad/s$^3$", xlabel="time (s)")
    if n > 1:
        handles, labels = ax[0, 0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", ncol=min(n, 8), fontsize=9, frameon=False)
        if np.isfinite(d):
            ax[1, 1].legend(loc="upper right", fontsize=8)
    else:
        ax[0, 0].legend(loc="best", fontsize=8)
        if np.isfinite(d):
            ax[1, 1].legend(loc="best", fontsize=8)
    fig.suptitle(title, fontsize=11)
    if path is not None:
        fig.savefig(path, dpi=int(dpi))
    return fig
