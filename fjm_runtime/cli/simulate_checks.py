"""``fjm simulate``'s checks before and after a run: the gains file, the run's size, where its gains
came from, and whether the run left the workspace.

Before any work (one-line :class:`~fjm_runtime.validation.FjmValueError`, exit 2):

* :func:`check_pole`: ``0 < lam <= pi x rate`` (the Nyquist frequency, rad/s).
* :func:`check_run_size`: the memory the run will hold and the RK4 substeps per sample, against
  :data:`DEFAULT_MAX_MEMORY_GB` (``--max-memory``) and :data:`MAX_SUBSTEPS`.

Then :func:`check_flag_ranges` (the flags' physical ranges, :mod:`fjm_runtime.cli.ranges`, beyond what the
memory and substeps checks let by) and :func:`check_gain_magnitudes` (a ``--gains`` file's gains within a
physical loop's magnitudes).

After the run: :func:`gains_provenance` (where the gains came from, and whether they were designed
for this model and these conditions) and :func:`workspace_exit` (the first sample where a link
angle or the tracking error is beyond :data:`WORKSPACE_BOUND` / :data:`ERROR_BOUND`).
"""
from __future__ import annotations

import math
from typing import Optional, Tuple

import numpy as np

from ..control.design import is_real
from ..validation import FjmValueError, check_magnitudes
from .ranges import DELAY, DURATION, GAIN, RATE, STIFFNESS, TORQUE, Range, available_bytes

__all__ = ["DEFAULT_MAX_MEMORY_GB", "ERROR_BOUND", "MAX_SUBSTEPS", "MEMORY_GB", "PEAK_FACTOR", "WORKSPACE_BOUND",
           "check_flag_ranges", "check_gain_magnitudes",
           "check_pole", "check_run_size", "check_substeps", "gains_provenance", "workspace_exit"]

#: ``--max-memory``, GB.
MEMORY_GB = Range(0, 1e4, "GB", "memory", lo_open=True)
#: Default of ``--max-memory``: the largest estimated peak memory of one run, GB.
DEFAULT_MAX_MEMORY_GB = 4.0
#: Measured peak resident memory of a run / the arrays it stores (link1 2000 s: 4.4 GB for 0.38 GB
#: stored, 11.6x; Panda torque-sensed 60 s: 1.0 GB for 0.13 GB, 7.2x; the CasADi loop's copies).
PEAK_FACTOR = 12.0
#: Largest number of RK4 plant steps per control sample (the default rule gives 11 for the Panda at
#: 1 kHz, :mod:`fjm_runtime.sim.substeps`); beyond it the stiffness or inertia is not physical.
MAX_SUBSTEPS = 10_000
#: ``|q_i|`` beyond this (rad) is outside any revolute arm's workspace: two full turns each way.
WORKSPACE_BOUND = 4.0 * math.pi
#: ``|q_i - q_d,i|`` beyond this (rad) is a tracking error of more than a full turn.
ERROR_BOUND = 2.0 * math.pi

def check_pole(lam, rate: float, where: str) -> float:
    """``lam`` as a float with ``0 < lam <= pi x rate``: poles at ``-lam`` beyond the Nyquist frequency
    ``pi / T`` (rad/s) cannot be realized by a law sampled at ``rate`` (and ``lam^4`` overflows long
    before a float does)."""
    top = math.pi * rate
    if not (is_real(lam) and math.isfinite(lam) and 0 < lam <= top):
        raise FjmValueError(f"{where} {lam!r}: expected a pole magnitude 0 < lam <= pi x rate = {top:.4g} 1/s "
                            f"(the Nyquist frequency at {rate:g} Hz)")
    return float(lam)


def check_substeps(substeps: float, omega: Optional[float] = None) -> None:
    """Refuse more than :data:`MAX_SUBSTEPS` RK4 plant steps per sample (before any work).

    Parameters
    ----------
    substeps : float
        ``--substeps``, or the rule's value (``1.5 T omega / 0.1``, :mod:`fjm_runtime.sim.substeps`).
    omega : float, optional
        The fastest mode (rad/s) the rule used (None: ``--substeps`` was given).
    """
    if substeps > MAX_SUBSTEPS:
        why = (f"the plant's fastest mode at the TRUE parameters is {omega:.4g} rad/s: the substeps rule needs "
               f"{math.ceil(substeps):.4g}" if omega is not None else f"--substeps {substeps}:")
        raise FjmValueError(f"{why} RK4 substeps per sample; expected at most {MAX_SUBSTEPS} (a stiffness and "
                            "inertia in a physical range: --K, --param, --k-scale, --jm-scale; or a higher --rate)")


def check_run_size(layout_nw: int, n: int, nm: int, duration: float, dt: float, max_memory_gb: float) -> dict:
    """Refuse, before allocating, a run too large to hold.

    The run stores ``N + 1 = round(duration / dt) + 1`` rows of the step state (``nw``), the
    applied torque, s and the estimate (``6n``), the reference (``5n``), the noise (``nm``), the
    true outputs (``4n``) and the error (``n``), 8 bytes each; its measured peak is up to
    :data:`PEAK_FACTOR` times that.

    Parameters
    ----------
    layout_nw : int
        Columns of the step state (``StepLayout.nw``: plant, controller, delay buffers, filters).
    n, nm : int
        Joints; measurement columns (4n or 5n).
    duration, dt : float
        s; the period (s).
    max_memory_gb : float
        ``--max-memory``.

    Returns
    -------
    dict
        ``samples``, ``columns``, ``stored_bytes``, ``peak_bytes`` (the estimate).

    Raises
    ------
    FjmValueError
        The estimated peak beyond ``--max-memory`` or the machine's available memory.
    """
    if not (math.isfinite(max_memory_gb) and max_memory_gb > 0):
        raise FjmValueError(f"--max-memory {max_memory_gb!r}: expected a finite size > 0 GB")
    samples = int(round(duration / dt)) + 1
    columns = int(layout_nw) + 6 * n + 5 * n + int(nm) + 4 * n + n
    stored = float(samples) * columns * 8.0
    peak = PEAK_FACTOR * stored
    limit = max_memory_gb * 1e9
    avail = available_bytes()
    what = (f"--duration {duration:g} s at {1.0 / dt:g} Hz: {samples:.4g} samples x {columns} stored columns x "
            f"8 bytes = {stored / 1e9:.3g} GB (about {peak / 1e9:.3g} GB at peak)")
    if peak > limit:
        raise FjmValueError(f"{what}; expected at most --max-memory {max_memory_gb:g} GB (shorten --duration, "
                            "lower --rate or --delay-samples, or raise --max-memory)")
    if avail is not None and peak > avail:
        raise FjmValueError(f"{what}; this machine has {avail / 1e9:.3g} GB available (shorten --duration "
                            "or lower --rate)")
    return {"samples": samples, "columns": columns, "stored_bytes": stored, "peak_bytes": peak}


def check_flag_ranges(args) -> None:
    """The flags' physical ranges beyond what the memory and substeps checks (first: they state the size) let by."""
    DURATION.check("--duration", args.duration)
    if args.rate is not None:
        RATE.check("--rate", args.rate)
    if args.dt is not None and args.dt < 1.0 / RATE.hi:
        raise FjmValueError(f"--dt {args.dt:g}: expected {1.0 / RATE.hi:g} <= dt <= 1 s (rates up to {RATE.hi:g} Hz)")
    if args.delay_samples is not None:
        DELAY.check("--delay-samples", args.delay_samples)
    if args.K is not None:
        STIFFNESS.check("--K", args.K)
    MEMORY_GB.check("--max-memory", args.max_memory)


def check_gain_magnitudes(path, design) -> None:
    """A ``--gains`` file's gains (already finite, of the right sign and shape: :meth:`Design.check`) within a
    physical loop's magnitudes: 0 or 1e-12..1e20, ``u_max`` up to 1e6 N m (``lam``: at most pi x rate, checked
    with the rate)."""
    for key, value in design.gains.items():
        if key == "lam" or value is None or isinstance(value, (bool, str, dict)):
            continue
        try:
            values = np.ravel(np.asarray(value, dtype=float))
        except (TypeError, ValueError):                         # not numbers: the law's own check names it
            continue
        top = TORQUE.hi if key == "u_max" else GAIN.hi
        check_magnitudes([key] * values.size, values, f"--gains {path}: gains.", hi=top,
                         why=f"SI units: {'N m' if key == 'u_max' else 'a gain'} of a physical loop")


def gains_provenance(source: str, design, conditions: dict, lemma1: Optional[str] = None) -> dict:
    """Where the run's gains came from and whether they were designed for this model and conditions.

    Parameters
    ----------
    source : str
        ``"shipped design FILE"``, ``"--gains FILE"``, ``"command line"`` (a gain flag given) or ``"defaults"``.
    design : Design or None
        The design (None: gains from the flags and their defaults).
    conditions : dict
        ``model``, ``kind``, ``sensing``, ``rate``, ``delay``, ``predict``, ``sensor`` of the run.
    lemma1 : str, optional
        With ``design`` None: how the switching gain came from the Lemma 1 bound (it holds for the
        continuous-time loop, not for a sampled one with delay and noise).

    Returns
    -------
    dict
        ``gains_source``, ``designed_for_these_conditions`` (bool) and, when False,
        ``not_designed_because`` (list of reasons).
    """
    if design is None:
        whose = ("fjm's generic defaults (no --gains, --lam, --k-s, --delta given)" if source == "defaults" else
                 "the command line's (--lam, --k-s, --delta; generic defaults for the others)")
        reasons = [f"the gains are {whose}; no design exists for these conditions (`fjm design` finds one)"]
        if lemma1:
            reasons.append(f"k_s is the Lemma 1 bound ({lemma1}) for the continuous-time loop, not a design "
                           "for the sampled loop")
    else:
        reasons = design.mismatches(conditions)
    out = {"gains_source": source, "designed_for_these_conditions": not reasons}
    if reasons:
        out["not_designed_because"] = reasons
    return out


def workspace_exit(t: np.ndarray, q: np.ndarray, e1: np.ndarray) -> Optional[Tuple[float, str]]:
    """The first sample where a link angle leaves the workspace or the error exceeds a full turn.

    Parameters
    ----------
    t : ndarray, shape (N+1,)
    q : ndarray, shape (N+1, n)
        Link angles, rad.
    e1 : ndarray, shape (N+1, n)
        ``q - q_d``, rad.

    Returns
    -------
    (float, str) or None
        The time and a one-line reason (joint, value, bound), or None when the run stayed inside
        ``|q| <= WORKSPACE_BOUND`` and ``|e1| <= ERROR_BOUND``.
    """
    q, e1 = np.abs(np.asarray(q, dtype=float)), np.abs(np.asarray(e1, dtype=float))
    bad = (q > WORKSPACE_BOUND) | (e1 > ERROR_BOUND) | ~np.isfinite(q) | ~np.isfinite(e1)
    rows = np.flatnonzero(bad.any(axis=1))
    if rows.size == 0:
        return None
    k = int(rows[0])
    j = int(np.flatnonzero(bad[k])[0])
    tk = float(t[k])
    if not (q[k, j] <= WORKSPACE_BOUND):
        why = f"link angle |q_{j + 1}| = {q[k, j]:.4g} rad beyond the workspace bound 4 pi = {WORKSPACE_BOUND:.4g}"
    else:
        why = f"tracking error |e_{j + 1}| = {e1[k, j]:.4g} rad beyond a full turn (2 pi)"
    return tk, f"left the workspace at t = {tk:.4f} s: {why}"
