"""Bad inputs give ValueError naming the field; divergence reports the time."""
import numpy as np
import pytest

from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.laws import SlidingModeController
from fjm_runtime.control.references import Sinusoid, make_reference
from fjm_runtime.analysis.certificates.lemma1 import lemma1_gain
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.sim.step import SimulationDivergedError


@pytest.mark.parametrize("kwargs, field", [
    ({"delta": 0.0}, "delta"),
    ({"delta": -1.0}, "delta"),
    ({"k_s": -5.0}, "k_s"),
    ({"k_s": float("nan")}, "k_s"),
    ({"k_s": [1.0, 2.0]}, "k_s"),
    ({"lam": -2.0, "c": None}, "lam"),
    ({"lam": None, "c": [1.0, 2.0]}, "c"),
    ({"lam": None, "c": [8.0, 1.0, 1.0]}, "c"),      # c3 c2 < c1: not Hurwitz
    ({"lam": None, "c": [1.0, -2.0, 3.0]}, "c"),
    ({"mode": "tanh"}, "mode"),
    ({"beta_hat": [[1.0, 0.0]]}, "beta_hat"),
    ({"beta_hat": -0.01}, "beta_hat"),
    ({"u_max": 0.0}, "u_max"),
    ({"k_lin": -1.0}, "k_lin"),
])
def test_controller_rejects_bad_design(link1, kwargs, field):
    args = {"lam": 5.0, "k_s": 10.0, "delta": 1.0}
    args.update(kwargs)
    args = {k: v for k, v in args.items() if v is not None}
    with pytest.raises(ValueError, match=field):
        SlidingModeController(link1, {}, **args)


def test_controller_rejects_bad_nominal_params(link1):
    with pytest.raises(ValueError, match="nominal_params"):
        SlidingModeController(link1, {"K": float("nan")}, lam=5.0, k_s=1.0)
    with pytest.raises(ValueError, match="stiffness|nominal_params"):
        SlidingModeController(link1, {"stiffness": 1.0}, lam=5.0, k_s=1.0)


def test_unknown_reference_and_controller(link1):
    with pytest.raises(ValueError, match="reference = 'ramp'"):
        make_reference("ramp")
    with pytest.raises(ValueError, match="controller = 'pid'"):
        make_controller("pid", link1, {}, lam=5.0)
    with pytest.raises(ValueError, match="amplitude"):
        Sinusoid([0.1, 0.2, 0.3], n=2)
    with pytest.raises(ValueError, match="rise_time"):
        make_reference("step", rise_time=0.0)


@pytest.mark.parametrize("kwargs, field", [
    ({"duration": 0.0}, "duration"),
    ({"duration": float("inf")}, "duration"),
    ({"dt": 0.0}, "dt"),
    ({"dt": 2.0}, "dt"),
    ({"x0": np.zeros(3)}, "x0"),
    ({"x0": [0.0, np.nan, 0.0, 0.0]}, "x0"),
    ({"true_params": {"K": np.nan}}, "true_params"),
    ({"true_params": {"K": -100.0}}, "true_params"),
    ({"true_params": np.ones(3)}, "true_params"),
    ({"backend": "gpu"}, "backend"),
])
def test_simulate_rejects_bad_inputs(link1, kwargs, field):
    args = {"duration": 1.0}
    args.update(kwargs)
    ctrl = SlidingModeController(link1, {}, lam=5.0, k_s=10.0, delta=1.0)
    with pytest.raises(ValueError, match=field):
        simulate(link1, ctrl, Sinusoid(0.5, 1.0), **args)


def test_simulate_rejects_reference_for_wrong_joint_count(link1):
    ctrl = SlidingModeController(link1, {}, lam=5.0, k_s=10.0, delta=1.0)
    with pytest.raises(ValueError, match="reference"):
        simulate(link1, ctrl, Sinusoid(0.5, 1.0, n=2), duration=1.0)


@pytest.mark.parametrize("backend", ["casadi", "python"])
def test_divergence_reports_time(link1, backend):
    # a linear gain far beyond what a 1 ms zero-order hold can take: the sampled loop is unstable
    ctrl = SlidingModeController(link1, {}, lam=5.0, mode="fl", k_lin=5.0e3)
    with pytest.raises(SimulationDivergedError, match=r"diverged at t = \d") as info:
        simulate(link1, ctrl, Sinusoid(0.5, 1.0), duration=2.0, backend=backend)
    assert 0.0 < info.value.t < 2.0


@pytest.mark.parametrize("kwargs, field", [
    ({"c": [1.0, 2.0]}, "c"),
    ({"reference_bounds": [1.0, 1.0]}, "reference_bounds"),
    ({"error_bounds": [-1.0, 0, 0, 0]}, "error_bounds"),
    ({"eta": 0.0}, "eta"),
    ({"bounds": {"K": (200.0, 100.0)}}, "bounds"),
    ({"bounds": {"stiffness": (1.0, 2.0)}}, "bounds"),
])
def test_lemma1_rejects_bad_inputs(kwargs, field):
    args = {"c": [512.0, 192.0, 24.0], "reference_bounds": [0.5] * 5, "bounds": {"K": (100.0, 200.0)}}
    args.update(kwargs)
    c, rb = args.pop("c"), args.pop("reference_bounds")
    with pytest.raises(ValueError, match=field):
        lemma1_gain(c, rb, **args)
