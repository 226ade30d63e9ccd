"""The demo's experiment settings (``fjm figures``): constants, the link1 design, the link1 runs.

* link1 with Table 1 (``J_l = 1``, ``J_m = 2``, ``M = 1``, ``g0 = 9.8``, ``L = 1``),
  true stiffness ``K in {100, 150, 200}``;
* the controller knows only the NOMINAL stiffness ``K_nom = 150`` (``T_hat``,
  ``alpha_hat``) and the paper's ``beta_hat = (beta_max + beta_min) / 2`` for
  ``K in [100, 200]``;
* sliding surface from a triple pole at ``-LAM``; ``k_s`` from the paper's Lemma 1
  (:func:`fjm_runtime.analysis.certificates.lemma1.lemma1_gain`) on a stated error region: a bound in
  TRUE coordinates, not a reaching guarantee for the law that runs (which builds ``s``
  from ``T(x; K_nom)``; :mod:`fjm_runtime.experiments.certified` runs the certified gains);
  boundary layer ``delta = k_s / LAYER_RATE`` (the layer's linear slope is ``LAYER_RATE``
  1/s, well inside what a 1 ms zero-order hold tolerates).
"""
from __future__ import annotations

from dataclasses import dataclass

from .. import load
from ..analysis.certificates.lemma1 import beta_bounds_link1, lemma1_gain
from ..control.defaults import DEFAULT_LAM, DEFAULT_LAYER_RATE, PAPER_K_RANGE
from ..control.factory import make_controller
from ..control.laws import coefficients_from_pole
from ..control.references import Sinusoid, SmoothStep
from ..sim.simulate import SimulationResult, simulate

LAM = DEFAULT_LAM
LAYER_RATE = DEFAULT_LAYER_RATE
K_NOM = 150.0
K_CASES = (100.0, 150.0, 200.0)
K_BOUNDS = {"K": PAPER_K_RANGE}
MC_BOUNDS = {"K": PAPER_K_RANGE, "J_l": (0.8, 1.2), "J_m": (1.6, 2.4)}
DURATION = 10.0
#: ``fjm figures --quick``: every experiment, figure and table, with short runs and few samples
#: (a smoke test of the pipeline; its numbers are not the documented ones).
QUICK_DURATION = 1.0
QUICK_SAMPLES = 2
ETA = 10.0
TASKS = {
    # name: (reference factory, error region E for Lemma 1, description)
    "regulation": (lambda n=1: SmoothStep(1.0, n=n, rise_time=2.0), (0.05, 0.1, 0.5, 1.0),
                   "smooth step 0 -> 1 rad in 2 s"),
    "tracking": (lambda n=1: Sinusoid(0.5, 1.0, n=n), (0.05, 0.5, 0.5, 0.5),
                 "0.5 sin(t) rad"),
}
COLORS = {100.0: "tab:red", 150.0: "tab:green", 200.0: "tab:blue"}
CTRL_COLORS = {"smc": "tab:blue", "ismc": "tab:green", "fl": "tab:red", "sign": "tab:orange",
               "adaptive": "tab:purple", "adaptive-paper": "tab:brown"}
CTRL_LABELS = {"smc": "paper SMC (sat)", "ismc": "integral SMC", "fl": "plain FL (k_s = 0)",
               "sign": "paper SMC (sign)", "adaptive": "adaptive K_hat + integral SMC",
               "adaptive-paper": "adaptive K_hat + paper SMC"}


def chain_reference(n: int) -> Sinusoid:
    """The chains' reference: 0.5 sin(t), 0.3 sin(1.5 t + 0.5), 0.2 sin(2 t) (first ``n`` joints)."""
    return Sinusoid([0.5, 0.3, 0.2][:n], [1.0, 1.5, 2.0][:n], n=n, phase=[0.0, 0.5, 0.0][:n])


@dataclass
class Design:
    """Controller design for one task: Lemma 1 gain, boundary layer, beta_hat."""

    task: str
    k_s: float
    delta: float
    beta_hat: float
    gain: object

    @classmethod
    def for_task(cls, task: str, bounds=None) -> "Design":
        """Lemma 1 gain of ``task`` (a key of :data:`TASKS`) on ``bounds`` (default :data:`K_BOUNDS`)."""
        ref_factory, E, _ = TASKS[task]
        bounds = bounds or K_BOUNDS
        gain = lemma1_gain(coefficients_from_pole(LAM), ref_factory().derivative_bounds()[:, 0],
                           nominal={"K": K_NOM}, bounds=bounds, error_bounds=E, eta=ETA)
        return cls(task, gain.k_s, gain.k_s / LAYER_RATE, beta_bounds_link1({"K": K_NOM}, bounds)[2], gain)


def link1_controller(kind: str, design: Design, model=None):
    """The link1 controller ``kind`` with nominal K_NOM and the task's design.

    ``'adaptive'`` / ``'adaptive-paper'``: :mod:`fjm_runtime.control.adaptive` with the
    integral / the paper's surface, ``K_hat`` projected onto ``K_BOUNDS`` and
    ``beta(x; K_hat)`` instead of the constant ``beta_hat``.
    """
    m = model or load("link1")
    if kind.startswith("adaptive"):
        return make_controller("adaptive", m, {"K": K_NOM}, lam=LAM, k_s=design.k_s, delta=design.delta,
                               K_bounds=K_BOUNDS["K"], integral=(kind == "adaptive"))
    return make_controller(kind, m, {"K": K_NOM}, lam=LAM, k_s=design.k_s, delta=design.delta,
                           beta_hat=design.beta_hat)


def run_link1(kind: str, task: str, K: float, design: Design, model=None, duration: float = DURATION,
              **extra) -> SimulationResult:
    """One link1 run: controller ``kind`` with nominal K_NOM, plant with ``K`` (and ``extra`` true params)."""
    m = model or load("link1")
    ref = TASKS[task][0]()
    ctrl = link1_controller(kind, design, m)
    params = {"K": K}
    params.update(extra)
    return simulate(m, ctrl, ref, duration=duration, true_params=params)


@dataclass
class DemoContext:
    """What the sections of one ``fjm figures`` run share.

    Attributes
    ----------
    out : Path
        Output directory (exists).
    duration : float
        Simulated seconds per run.
    quick : bool
        Smoke-test mode (short runs, few samples; not the documented numbers).
    n_mc : int
        Monte Carlo samples.
    progress : callable
        Receives one line per stage.
    results : dict
        Results a section leaves for a later one (e.g. ``'paper'``, ``'comparison'``, ``'gains'``).
    """

    out: object
    duration: float
    quick: bool
    n_mc: int
    progress: object
    results: dict

    @property
    def link1(self):
        """The link1 model (loaded once)."""
        if "link1" not in self.results:
            self.results["link1"] = load("link1")
        return self.results["link1"]

    @property
    def designs(self) -> dict:
        """``{task: Design}`` for every task of :data:`TASKS`."""
        if "designs" not in self.results:
            self.results["designs"] = {task: Design.for_task(task) for task in TASKS}
        return self.results["designs"]
