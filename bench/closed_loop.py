"""Closed-loop peers for link1 (paper's tracking case, 10 s at 1 kHz): THE sample step with one RK4
substep, an ideal sensor, no delay and the stateless SMC law (the sampled loop's form that a hand-written
loop can match: ``u_k = law(x_k)`` held over the sample, one RK4 step of the plant).

* generated: :func:`fjm_runtime.sim.compiled.sampled_loop_library` (the sample step + a C loop,
  cached), and the whole ``simulate(..., backend="compiled", substeps=1)`` call;
* hand C: ``bench/hand_loop.c``, the same loop written by hand, same flags;
* Python loop: ``simulate(..., backend="python")`` (numpy RK4 calling the CasADi Functions),
  timed against the whole compiled ``simulate()`` call (same arguments);
* scipy: ``solve_ivp`` (RK45) of the same closed loop with the control law evaluated
  continuously (no zero-order hold), rtol 1e-6, atol 1e-9;
* numpy batch: RK4 vectorized over the runs, every figure of ``simulate_batch(..., substeps=1)``
  (:mod:`bench.numpy_batch`, on this module's case).
"""
from __future__ import annotations

import ctypes
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import fjm_runtime
from fjm_runtime.analysis.certificates.lemma1 import beta_bounds_link1, lemma1_gain
from fjm_runtime.control.defaults import DEFAULT_LAM, DEFAULT_LAYER_RATE, PAPER_K_RANGE, default_delta
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.laws import coefficients_from_pole
from fjm_runtime.control.references import Sinusoid
from fjm_runtime.sim.compiled import sampled_loop_runner
from fjm_runtime.sim.interface import CommandInterface
from fjm_runtime.sim.sample_step import initial_step_state
from fjm_runtime.sim.step_layout import make_layout
from fjm_runtime.sim.sensor import SensorModel

from .ccutil import compile_object, link_shared

#: The command interface of every fjm run compared with a peer here: the peers (hand-written C, numpy,
#: solve_ivp) apply the computed torque at once, so fjm runs them on the ``ideal`` interface (like for like).
PEER_INTERFACE = "ideal"

HERE = Path(__file__).resolve().parent



#: The paper's link1 tracking design (the same numbers as the figures): triple pole at
#: ``-LAM``, nominal stiffness ``K_NOM``, true stiffness in ``K_BOUNDS``, Lemma 1 margin
#: ``ETA``, boundary layer ``k_s / LAYER_RATE``; the reference and the error region E
#: of Lemma 1 are ``TASKS["tracking"]``.
LAM = DEFAULT_LAM
K_NOM = 150.0
K_BOUNDS = {"K": PAPER_K_RANGE}
ETA = 10.0
LAYER_RATE = DEFAULT_LAYER_RATE
TASKS = {"tracking": (lambda: Sinusoid(0.5, 1.0), (0.05, 0.5, 0.5, 0.5), "0.5 sin(t) rad")}


@dataclass
class Design:
    """Switching gain ``k_s`` (rad/s^4), boundary layer ``delta`` and constant ``beta_hat`` of a design."""

    k_s: float
    delta: float
    beta_hat: float


def tracking_design():
    """The paper's link1 tracking design, computed in the run by the functions that define it.

    Lemma 1 gain (:func:`fjm_runtime.analysis.certificates.lemma1.lemma1_gain`) for ``0.5 sin t`` with
    ``K`` in [100, 200], boundary layer ``k_s / LAYER_RATE``
    (:func:`fjm_runtime.control.defaults.default_delta`), ``beta_hat = (beta_min +
    beta_max) / 2`` (:func:`fjm_runtime.analysis.certificates.lemma1.beta_bounds_link1`); triple pole at
    ``-LAM``, nominal ``K_NOM``.

    Returns
    -------
    design : Design
    lam, k_nom : float
    """
    ref_factory, E, _ = TASKS["tracking"]
    gain = lemma1_gain(coefficients_from_pole(LAM), ref_factory().derivative_bounds()[:, 0],
                       nominal={"K": K_NOM}, bounds=K_BOUNDS, error_bounds=E, eta=ETA)
    design = Design(gain.k_s, default_delta(gain.k_s, LAYER_RATE), beta_bounds_link1({"K": K_NOM}, K_BOUNDS)[2])
    return design, float(LAM), float(K_NOM)


@dataclass
class Case:
    model: object
    controller: object
    reference: object
    p_true: np.ndarray
    p_nom: np.ndarray
    duration: float
    dt: float

    @property
    def n_steps(self) -> int:
        return int(round(self.duration / self.dt))

    def layout(self):
        """The sample step's layout: one RK4 substep, ideal sensor, no delay, the torque applied as computed (the
        ``ideal`` command interface, as every peer here integrates it): ``w = x`` for the SMC law."""
        return make_layout(self.model, self.controller, self.dt, 1, SensorModel.ideal(), 0, False,
                           interface=CommandInterface.ideal())

    def reference_rows(self):
        """The reference at ``t_k``, ``k = 0 .. N-1``, shape (N, 5) (what sample k reads)."""
        return self.reference.sample(self.dt * np.arange(self.n_steps)).reshape(self.n_steps, 5)

    def noise(self):
        """The sensor noise rows of the ideal sensor: zeros, shape (N, nm)."""
        return np.zeros((self.n_steps, self.layout().nm))

    def x0(self):
        r0 = self.reference(0.0)
        return np.array([r0[0, 0], 0.0, r0[0, 0], 0.0])

    def w0(self):
        """The sample step's initial state for :meth:`x0` (the stateless law has no z)."""
        return initial_step_state(self.model, self.layout(), self.x0(), np.zeros(0), self.p_true)


def link1_case(K_true: float = 120.0, duration: float = 10.0, dt: float = 1e-3) -> Case:
    m = fjm_runtime.load("link1")
    design, lam, k_nom = tracking_design()
    ctrl = make_controller("smc", m, {"K": k_nom}, lam=lam, k_s=design.k_s, delta=design.delta,
                           beta_hat=design.beta_hat)
    return Case(m, ctrl, Sinusoid(0.5, 1.0), m.params_array({"K": K_true}),
                m.params_array({"K": k_nom}), duration, dt)


class GeneratedLoop:
    """The sample step's compiled ``mapaccum`` (:func:`sampled_loop_runner`, through ``casadi.external``)
    with the reference pre-sampled (timing excludes sampling); ``() -> (W (N, nw), AUX (N, 6))``."""

    def __init__(self, case: Case):
        self.case = case
        self.runner = sampled_loop_runner(case.model, case.controller, case.layout(), case.n_steps)
        self.R, self.NOISE = case.reference_rows().T.copy(), case.noise().T.copy()
        self.w0 = case.w0()

    def args(self):
        """The runner's inputs ``(w0, R, NOISE, p_true)``."""
        return self.w0, self.R, self.NOISE, self.case.p_true

    def __call__(self):
        W, A = self.runner(*self.args())
        return np.asarray(W).T, np.asarray(A).T


class HandLoop:
    """``bench/hand_loop.c`` compiled with the bench flags, called through ctypes."""

    def __init__(self, case: Case, workdir: Path):
        workdir.mkdir(parents=True, exist_ok=True)
        obj = workdir / "hand_loop.o"
        compile_object(HERE / "hand_loop.c", obj)
        self.lib = ctypes.CDLL(str(link_shared([obj], workdir / "hand_loop.so")))
        dp = ctypes.POINTER(ctypes.c_double)
        self.lib.hand_loop.argtypes = [ctypes.c_int, ctypes.c_double, dp, dp, dp, ctypes.c_double,
                                       ctypes.c_double, ctypes.c_double, dp, dp, dp, dp]
        self.case = case
        self.R = np.ascontiguousarray(case.reference_rows())
        self.w0 = case.x0()
        self.c = np.ascontiguousarray(case.controller.c)
        N = case.n_steps
        self.W = np.zeros((N, 4))
        self.A = np.zeros((N, 6))

    def __call__(self):
        c = self.case
        ptr = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        bh = float(c.controller.beta_hat[0, 0]) if c.controller.beta_hat is not None else -1.0
        self.lib.hand_loop(c.n_steps, c.dt, ptr(c.p_true), ptr(c.p_nom), ptr(self.c),
                           float(c.controller.k_s[0]), float(c.controller.delta[0]), bh,
                           ptr(self.R), ptr(self.w0),
                           ptr(self.W), ptr(self.A))
        return self.W, self.A


def simulate_call(case: Case, backend: str):
    """The whole ``simulate(..., backend=backend, substeps=1)`` call of the case (references, outputs, metrics)."""
    from fjm_runtime.sim.simulate import simulate
    return simulate(case.model, case.controller, case.reference, duration=case.duration, dt=case.dt,
                    true_params=case.p_true, x0=case.x0(), backend=backend, substeps=1, interface=PEER_INTERFACE)


def python_loop(case: Case):
    """``simulate(..., backend="python")``: numpy RK4 calling the CasADi Functions."""
    return simulate_call(case, "python")


def solve_ivp_loop(case: Case, rtol: float = 1e-6, atol: float = 1e-9):
    """scipy RK45 of the closed loop (control law evaluated at every RHS call)."""
    from scipy.integrate import solve_ivp
    m, ctrl, ref, p = case.model, case.controller, case.reference, case.p_true

    def rhs(t, x):
        u = ctrl.evaluate(t, x, np.zeros(0), ref(t)).u
        return m.f(x, p) + m.g(x, p) @ u

    t_eval = case.dt * np.arange(case.n_steps + 1)
    return solve_ivp(rhs, (0.0, case.duration), case.x0(), method="RK45", rtol=rtol, atol=atol,
                     t_eval=t_eval)
