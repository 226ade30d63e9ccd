"""The linear sampled-data analysis (LinearAnalyzer of fjm_runtime/analysis/sampled/sampled_analysis.py).

Checked against the loop itself: (a) the CasADi jacobians against central differences of the sample
step; (b) the predicted torque jitter and link-angle error against Monte Carlo runs of ``simulate``
(small noise: the linear regime); (c) the predicted stability boundaries (delay, stiffness scale)
against noise-free simulations on a grid (within one grid step). Cheap case: planar2, torque
sensing, 1 kHz, one sample of delay with prediction, velocities differentiated from the encoders,
dtau_J filtered. The Panda's shipped gains: the rest instability the analysis finds is the loop's.
"""
from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.analysis.sampled.sampled_analysis import LinearAnalyzer
from fjm_runtime.analysis.sampled.sampled_linear import Conditions, scaled_stiffness
from fjm_runtime.cli.analyze import conditions_from_design
from fjm_runtime.control.design import Design
from fjm_runtime.control.references import Sinusoid
from fjm_runtime.sim.metrics import torque_jitter
from fjm_runtime.sim.rest import rest_state
from fjm_runtime.sim.sensor import SensorModel
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.sim.step import SimulationDivergedError

#: Small noise on every sensed signal (the linear regime), the real signal paths, no rate limit.
SMALL = SensorModel(q=1e-6, q_m=1e-6, tau_J=2e-3, dtau_mode="filtered", velocity_mode="differentiated",
                    name="small")
#: Low-gain law: jitter about 1 N m at SMALL noise, far inside the boundary layer.
QUIET = {"lam": 15.0, "k_lin": [20.0, 20.0], "k_s": [200.0, 200.0], "delta": [5.0, 5.0]}
#: Stiffer law whose boundaries lie inside the grids: unstable from 3 samples of delay and outside
#: about K x [0.30, 1.33] (the analysis' numbers; the test checks them against simulation).
STIFF = {"lam": 40.0, "k_lin": [100.0, 100.0], "k_s": [2000.0, 2000.0], "delta": [10.0, 10.0]}


def _setting(m, sensor=SMALL, delay=1):
    q0 = np.array([0.3, -0.4])
    ref = Sinusoid(0.0, 0.0, n=2, offset=list(q0))          # a set point, with sample()
    p = np.asarray(m.params_array({}), dtype=float)
    x0 = rest_state(m, q0, p)
    return Conditions(m, "ismc", "torque", 1e-3, delay, True, sensor, ref, x0, {}, None), ref, x0, p


def test_jacobians_match_finite_differences(planar2):
    """(a) A, B, C, D of the step at the rest equilibrium equal central differences of the step itself,
    and the constant per-run tau_J offset is dropped from the dynamics (not an eigenvalue at 1)."""
    sensor = SensorModel(q=1e-6, q_m=1e-6, tau_J=2e-3, dtau_mode="filtered", velocity_mode="differentiated",
                         tau_J_offset=0.1)
    cond, ref, x0, p = _setting(planar2, sensor)
    an = LinearAnalyzer(cond, plants=[("nominal", p)], task_times=())
    ctrl = cond.controller(QUIET)
    g = np.asarray(ctrl.gains)
    S, w, r = an.operating_point(ctrl, g, 0, p, 1, {})
    assert np.max(np.abs(np.asarray(S.step(w, r, np.zeros(S.L.nm), p, g)[0]).ravel() - w)) < 1e-9  # equilibrium
    lin = S.linearize(w, r, p, g)
    assert lin.dyn.size == w.size - planar2.n                                  # the offset states dropped
    f = lambda wv, nv: [np.asarray(v).ravel() for v in S.step(wv, r, nv, p, g)]
    nm, full = S.L.nm, np.zeros((w.size, w.size))
    eps = 1e-6 * np.maximum(1.0, np.abs(w))
    for j in range(w.size):
        e = np.zeros(w.size); e[j] = eps[j]
        full[:, j] = (f(w + e, np.zeros(nm))[0] - f(w - e, np.zeros(nm))[0]) / (2 * eps[j])
    Bfd, Dfd = np.zeros((w.size, nm)), np.zeros((planar2.n, nm))
    for j in range(nm):
        e = np.zeros(nm); e[j] = 1e-7
        hi, lo = f(w, e), f(w, -e)
        Bfd[:, j], Dfd[:, j] = (hi[0] - lo[0]) / 2e-7, (hi[1][:planar2.n] - lo[1][:planar2.n]) / 2e-7
    Cfd = np.zeros((planar2.n, w.size))
    for j in range(w.size):
        e = np.zeros(w.size); e[j] = eps[j]
        Cfd[:, j] = (f(w + e, np.zeros(nm))[1][:planar2.n] - f(w - e, np.zeros(nm))[1][:planar2.n]) / (2 * eps[j])
    d = lin.dyn
    for name, got, want in (("A", lin.A, full[np.ix_(d, d)]), ("B", lin.B, Bfd[d]), ("C", lin.C, Cfd[:, d]),
                            ("D", lin.D, Dfd)):
        scale = np.max(np.abs(want)) + 1e-300
        assert np.max(np.abs(got - want)) <= 1e-5 * scale, name


def test_jitter_and_error_match_monte_carlo(planar2):
    """(b) Predicted torque jitter (the metric's own quantity) and link-angle error std vs 4 runs x 2 s."""
    cond, ref, x0, p = _setting(planar2)
    an = LinearAnalyzer(cond, plants=[("nominal", p)], task_times=())
    fig = an.analyze(QUIET, margins=False)["plants"][0]["points"]["rest"]
    ctrl = cond.controller(QUIET)
    jit, err = [], []
    for seed in range(4):
        res = simulate(planar2, ctrl, ref, duration=2.0, dt=1e-3, x0=x0, sensor=SMALL.with_seed(seed),
                       delay_samples=1, predict=True)
        jit.append(torque_jitter(res))
        err.append(np.sqrt(np.mean(res.e1[200:] ** 2, axis=0)))
    jit, err = np.mean(jit, axis=0), np.sqrt(np.mean(np.square(err), axis=0))
    assert np.all(np.abs(np.array(fig["torque_jitter"]) / jit - 1) < 0.25), (fig["torque_jitter"], jit)
    assert np.all(np.abs(np.array(fig["q_error_std"]) / err - 1) < 0.25), (fig["q_error_std"], err)
    assert fig["dominant_noise"][0] == "q1"                  # encoder noise of joint 1 through k_lin dominates


def _diverges(m, cond, ref, p, delay, duration=1.5) -> bool:
    """A noise-free run from the rest equilibrium nudged by 1e-6 rad (s well inside the layer): does the error grow?"""
    x0 = rest_state(m, ref(0.0)[0], p)
    x0[0] += 1e-6
    quiet = SensorModel(dtau_mode="filtered", velocity_mode="differentiated")
    try:
        res = simulate(m, cond.controller(STIFF), ref, duration=duration, dt=1e-3, x0=x0, true_params=p,
                       sensor=quiet, delay_samples=delay, predict=True, max_state=1e6)
    except SimulationDivergedError:
        return True
    e = np.max(np.abs(res.e1), axis=1)
    k = int(0.3 / 1e-3)
    return bool(np.max(e[-k:]) > np.max(e[k // 6:k]))


def _first_failing(grid, fails) -> int:
    for i, g in enumerate(grid):
        if fails(g):
            return i
    return len(grid)


def test_stability_boundaries_match_simulation(planar2):
    """(c) The delay and the stiffness scales at which runs start to diverge, within one grid step."""
    cond, ref, x0, p = _setting(planar2)
    an = LinearAnalyzer(cond, plants=[("nominal", p)], task_times=())
    out = an.analyze(STIFF, margins=True, attribution=False)
    d_pred = out["plants"][0]["points"]["rest"]["first_unstable_delay"]
    lo, hi = out["stiffness_scale"]["rest"]["range"]
    assert d_pred is not None and lo is not None and hi is not None
    delays = [1, 2, 3, 4, 5]
    i_sim = _first_failing(delays, lambda d: _diverges(planar2, cond, ref, p, d))
    assert abs(i_sim - delays.index(d_pred)) <= 1, (d_pred, delays[i_sim:i_sim + 1])
    for grid, inside in (([1.15 ** k for k in range(1, 9)], lambda g: g < hi),
                         ([1.15 ** -k for k in range(1, 12)], lambda g: g > lo)):
        i_pred = _first_failing(grid, lambda g: not inside(g))
        i_sim = _first_failing(grid, lambda g: _diverges(planar2, cond, ref, scaled_stiffness(planar2, p, g), 1))
        assert i_pred < len(grid) and abs(i_sim - i_pred) <= 1, (grid, i_pred, i_sim, lo, hi)


@pytest.mark.slow  # builds the Panda's sample step (CasADi, ~3 s)
def test_panda_shipped_gains_rest_instability_is_the_loops(panda):
    """The shipped Panda 1 kHz / d = 1 gains with their design's sensor paths (dtau_J filtered at 1000 rad/s,
    one sample of delay, prediction): the analysis finds the loop UNSTABLE at rest on the task's start, with a
    negative real eigenvalue (a period-2 mode, torque alternating sample to sample) of modulus > 1. The loop
    itself, noise-free from that exact equilibrium nudged by 1e-9 rad, leaves it within a few samples and
    the torque alternates in sign about its holding value: the instability is the loop's, not the
    linearization's (the boundary layer bounds it: a limit cycle, not a divergence)."""

    from fjm_runtime.control.design import Design
    from fjm_runtime.experiments import panda as demo
    spec = Design.shipped("panda", "ismc", "torque", 1000, 1)
    q0 = demo.reference()(0.0)[0]
    ref = Sinusoid(0.0, 0.0, n=7, offset=list(q0))
    p = np.asarray(panda.params_array({}), dtype=float)
    x0 = rest_state(panda, q0, p)
    quiet = replace(SensorModel.panda_white(), q=0.0, dq=0.0, q_m=0.0, dq_m=0.0, tau_J=0.0, name="quiet")
    cond = Conditions(panda, "ismc", "torque", 1e-3, 1, True, quiet, ref, x0, {}, tuple(spec.gains["u_max"]))
    an = LinearAnalyzer(cond, plants=[("nominal", p)], task_times=())
    ctrl = cond.controller(spec.law_gains())
    g = np.asarray(ctrl.gains)
    S, w, r = an.operating_point(ctrl, g, 0, p, 1, {})
    lin = S.linearize(w, r, p, g)
    vals = np.linalg.eigvals(lin.A)
    worst = vals[np.argmax(np.abs(vals))]
    assert abs(worst) > 2.0 and worst.real < 0 and abs(worst.imag) < 1e-9 * abs(worst)
    x1 = x0.copy()
    x1[6] += 1e-9
    res = simulate(panda, ctrl, ref, duration=0.04, dt=1e-3, x0=x1, sensor=quiet, delay_samples=1, predict=True)
    du = np.diff(res.u[:, 6])
    assert np.max(np.abs(res.u[:, 6] - res.u[0, 6])) > 1e-2              # 1e-9 rad grew to a visible torque
    tail = du[-20:]
    assert np.all(tail[1:] * tail[:-1] < 0)                              # alternating: the period-2 mode


def _impedance_at_rest(name: str, kind: str):
    """The shipped 1 kHz / d1 impedance design of ``name`` (franka_like; its interface) at rest on its task's
    start: (model, conditions, controller)."""
    m = fjm_runtime.load(name)
    design = Design.shipped(name, kind, "full", 1000, 1)
    args = SimpleNamespace(rate=None, delay_samples=None, predict=None, sensing=None, noise=None, gains=name,
                           interface=None)
    cond = conditions_from_design(m, design, args)
    q0 = np.asarray(cond.reference(0.0))[0]
    p = np.asarray(m.params_array({}), dtype=float)
    cond = replace(cond, reference=Sinusoid(0.0, 0.0, n=int(m.n), offset=list(q0)), x0=rest_state(m, q0, p))
    return m, cond, cond.controller(dict(design.law_gains(), u_max=cond.u_max))


# the Panda's motor-side design in make test (about 4 s); the others with the exhaustive checks of .ci/run
@pytest.mark.parametrize("name,kind", [("panda", "impedance"),
                                       pytest.param("panda", "joint_impedance", marks=pytest.mark.exhaustive),
                                       pytest.param("panda_hd", "impedance", marks=pytest.mark.exhaustive),
                                       pytest.param("baxter", "impedance", marks=pytest.mark.exhaustive)])
def test_shipped_impedance_design_verdict_and_jitter_match_simulate(name, kind):
    """A law with no boundary layer (no equivalent gain: the small-signal loop is the loop): at rest with the
    design's franka_like sensor and interface, the analysis says stable and the loop holds (2 s, seeds 0 and
    1: error < 1e-2 rad over the second second); the predicted jitter is within 25 % of the simulated one on every joint (measured:
    within 6 %)."""
    m, cond, ctrl = _impedance_at_rest(name, kind)
    an = LinearAnalyzer(cond, plants=[("nominal", np.asarray(m.params_array({}), dtype=float))], task_times=())
    fig = an.analyze(ctrl, margins=False, attribution=False)["plants"][0]["points"]["rest"]
    assert fig["stable"] is True and fig["rho"] < 1.0 and "s_over_delta" not in fig
    for seed in (0, 1):
        res = simulate(m, ctrl, cond.reference, duration=2.0, dt=cond.dt, x0=cond.x0,
                       sensor=cond.sensor.with_seed(seed), delay_samples=cond.delay, predict=cond.predict,
                       interface=cond.interface)
        assert np.max(np.abs(res.e1[len(res.t) // 2:])) < 1e-2  # Baxter's soft drives settle the offset's 13 mrad
        sim = torque_jitter(res)
        assert np.all(np.abs(np.asarray(fig["torque_jitter"]) / sim - 1.0) < 0.25), (fig["torque_jitter"], sim)
