"""``fjm figures``: the paper's figures and the comparisons (``make demo``)."""
from __future__ import annotations

from pathlib import Path

from ..validation import FjmValueError
from .ranges import Range
from .common import check_output_dir

#: Monte Carlo samples of the figures (each a 10 s run of every law compared; 40 take minutes).
MC_SAMPLES = Range(1, 1000, "", "samples", integer=True)


def add_arguments(fig) -> None:
    """The arguments of ``fjm figures`` on its parser ``fig`` (name, help, description: commands.toml)."""
    fig.add_argument("--out", type=Path, default=Path("out"),
                     help="output directory, created if its parent exists (default out)")
    fig.add_argument("--samples", type=MC_SAMPLES, default=40, help=f"Monte Carlo samples, {MC_SAMPLES} (default 40)")
    fig.add_argument("--quick", action="store_true",
                     help="smoke test: 1 s runs and at most 2 Monte Carlo samples; still writes every "
                          "figure and summary.md (not the documented numbers)")


def run(args) -> int:
    """Run ``fjm figures``; prints the summary path."""
    if args.samples < 1:
        raise FjmValueError(f"--samples = {args.samples}: expected an integer >= 1")
    check_output_dir(args.out, "--out")
    from ..experiments.demo import make_figures
    print(make_figures(args.out, n_mc=args.samples, quick=args.quick))
    return 0
