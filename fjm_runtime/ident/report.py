"""What an identification prints and writes: the per-joint table and the parameter file.

The parameter file is the format ``fjm design --params`` and ``fjm simulate --params`` read
(docs/design-command.md): ``[parameters]`` the identified nominal values of the model's parameters,
``[spread]`` the relative half-width of the design's draws, ``SPREAD_SIGMAS`` standard uncertainties
(the statistical standard error and the systematic term combined,
:meth:`~fjm_runtime.ident.identify.Identification.uncertainty`) over the value (at least ``MIN_SPREAD``). A parameter the log does not determine (not excited) is left
out: the model's value and the default spread stay. What is not a parameter of the model (friction, the torque
sensor's offset) is written as comments, with the fit's settings, residuals and conditions.
"""
from __future__ import annotations

from typing import List

from ..model import command_name
from .uncertainty import INTERVAL_SIGMAS

__all__ = ["params_toml", "table_lines", "SPREAD_SIGMAS", "MIN_SPREAD"]

#: Standard uncertainties per half-width of the draws' spread.
SPREAD_SIGMAS = 3.0
#: Smallest spread written (relative): an identification is never exact.
MIN_SPREAD = 0.01
#: Largest spread the parameter file accepts is < 1; a poorly identified value gets this.
MAX_SPREAD = 0.5


def _spread(value: float, se: float) -> float:
    rel = SPREAD_SIGMAS * se / abs(value) if value else MAX_SPREAD
    return float(min(max(rel, MIN_SPREAD), MAX_SPREAD))


def params_toml(ident, model) -> str:
    """The parameter file's text (see the module docstring)."""
    s = ident.settings
    mine = ident.model_values(model)
    lines = [f"# fjm identify {command_name(model)} {s['log']}: {s['samples']} samples, {s['duration_s']:.3g} s at "
             f"{s['rate_hz']:.4g} Hz",
             f"# spring {s['spring']}, friction {s['friction']} (v_c {s['v_c']:g}, v_s {s['v_s']:g} rad/s), "
             f"tau_J from the {s['tau_J']}",
             f"# filter: {s['filter']}; motor equation without the windows where |dq_m| < "
             f"{s.get('reversal_share', 0):g} x its RMS (stiction)"]
    for key in ident.condition:
        lines.append(f"# {key}: condition {ident.condition[key]:.3g}, RMS residual {ident.residual[key]:.3g} N m")
    names = set(model.param_names)
    kept = [k for k in ident.not_excited if k in names]
    if kept:
        lines.append("# not excited, the model's value kept (identified value, standard error):")
        lines += [f"#   {k} = {model.default_params[k]!r}  # identified {ident.values[k]:.4g} +- {ident.stderr[k]:.2g}"
                  for k in kept]
    other = {k: v for k, v in ident.values.items() if k not in names}
    if other:
        lines.append(f"# identified, not parameters of {model.name} (value, standard error):")
        lines += [f"#   {k} = {v!r}  # +- {ident.stderr[k]:.3g}" for k, v in other.items()]
    lines += [f"# warning: {w}" for w in ident.warnings]
    lines += ["", "[parameters]"]
    lines += [f"{k} = {v!r}  # std. error {ident.stderr[k]:.3g}, interval [{lo:.6g}, {hi:.6g}]"
              for k, v in mine.items() for lo, hi in [ident.interval(k)]]
    lines += [f"{k} = {v!r}  # held by the fit, not identified" for k, v in ident.fixed.items()
              if k in names and k not in mine]
    lines += ["", f"[spread]  # relative half-width of the design's draws: {SPREAD_SIGMAS:g} standard uncertainties, "
              f"at least {MIN_SPREAD:g}"]
    lines += [f"{k} = {_spread(v, ident.uncertainty(k))!r}" for k, v in mine.items()]
    return "\n".join(lines) + "\n"


def table_lines(ident) -> List[str]:
    """Human-readable result: one line per parameter (value, statistical standard error, systematic
    term, the stated interval), then conditions, residuals and warnings."""
    out = [f"{'parameter':16s} {'value':>12s} {'std. error':>11s} {'systematic':>11s} {'rel.':>7s}   "
           f"interval (+-{INTERVAL_SIGMAS:g} uncertainties)"]
    for k, v in ident.values.items():
        se, unc = ident.stderr[k], ident.uncertainty(k)
        rel = f"{100 * unc / abs(v):6.2f}%" if v else "     -"
        lo, hi = ident.interval(k)
        out.append(f"{k:16s} {v:12.5g} {se:11.3g} {ident.systematic.get(k, 0.0):11.3g} {rel}   [{lo:.5g}, {hi:.5g}]")
    out.append("")
    for key in ident.condition:
        out.append(f"{key:10s} condition {ident.condition[key]:9.3g}   RMS residual {ident.residual[key]:.3g} N m")
    out += [f"warning: {w}" for w in ident.warnings]
    return out
