"""The screening step of a design: reject candidate gains before any Monte Carlo run.

A screen is any object with

* ``check(cands) -> list of Verdict`` — one verdict per candidate gains dict (``ok``: worth
  simulating; ``reason``: why not, one line; ``predicted``: the figures it rests on, JSON-able);
* ``explain(gains) -> str or None`` — what limits these gains (named in a failed design's record,
  e.g. ``"limited by encoder noise through k_lin on joint 2"``);
* ``name`` — how the record names it.

:func:`fjm_runtime.analysis.search.search.design` takes one as ``screen=``: candidates it rejects cost
:data:`SCREENED_COST` and are not simulated. :func:`linear_screen` builds the screen of the linear
sampled-data analysis (:mod:`fjm_runtime.analysis.search.screen_linear`: spectral radius below 1
with a margin at every corner of the parameter box, predicted torque jitter under the limit) when
:mod:`fjm_runtime.analysis.sampled.sampled_linear` is installed, and returns None otherwise. It is opt-in
(``fjm design --screen linear``): measured on the Panda it costs about 30 s per candidate (the MC
stage about 0.5 s), and it predicted 30.5 N m of jitter on joint 4 for the shipped d = 1 gains, whose
Monte Carlo worst case over 200 draws is 3.07 N m, so by default it would reject gains that work.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import List, Optional, Protocol

from .thresholds import DIVERGED_COST

__all__ = ["SCREENED_COST", "Screen", "Verdict", "screen_costs"]

#: Cost of a candidate the screen rejected (as a diverged run: never chosen over a simulated one).
SCREENED_COST = DIVERGED_COST


@dataclass
class Verdict:
    """A screen's verdict on one candidate."""

    ok: bool
    reason: str = ""
    predicted: dict = field(default_factory=dict)


class Screen(Protocol):
    """What :func:`fjm_runtime.analysis.search.search.design` needs of a screen (module docstring)."""

    name: str

    def check(self, cands: List[dict]) -> List[Verdict]:
        ...

    def explain(self, gains: dict) -> Optional[str]:
        ...


def screen_costs(screen, cands):
    """``(keep, verdicts)``: indices of the candidates to simulate and every verdict (None: no screen)."""
    if screen is None:
        return list(range(len(cands))), None
    verdicts = screen.check(cands)
    if len(verdicts) != len(cands):
        raise RuntimeError(f"screen {getattr(screen, 'name', screen)!r}: {len(verdicts)} verdicts for "
                           f"{len(cands)} candidates")
    return [i for i, v in enumerate(verdicts) if v.ok], verdicts
