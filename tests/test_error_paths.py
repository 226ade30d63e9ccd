"""Every runtime error path in one list: each raises ValueError naming the field and the expectation.

(The model-file error paths are listed in tests/test_model_file.py; property-based
variations of x and p are in tests/test_validation_props.py.)
"""

import numpy as np
import pytest

import fjm_runtime as f
from fjm_runtime.controllers import make_controller
from fjm_runtime.references import make_reference
from fjm_runtime.simulate import simulate
from fjm_runtime.sweep import sample_parameters

m = f.load("link1")
p2 = f.load("planar2")


def ctrl(**kw):
    base = dict(lam=8, k_s=1, delta=1)
    base.update(kw)
    return make_controller("smc", m, m.default_params, **base)


CASES = [
    (lambda: f.load("planar8"), r"unknown model 'planar8'; available models: link1, planar1"),
    (lambda: m.alpha(np.zeros(3)), r"x: expected shape \(4,\), got shape \(3,\)"),
    (lambda: m.alpha([0, np.nan, 0, 0]), r"x: entry 1 is nan; expected finite values"),
    (lambda: m.alpha(["0.1", 0, 0, 0]), r"x: expected a numeric array of shape \(4,\)"),
    (lambda: m.f(np.zeros(4), np.ones(6)), r"p: expected shape \(7,\), got shape \(6,\)"),
    (lambda: m.f(np.zeros(4), {"k": 1.0}), r"p: unknown parameter name\(s\) \['k'\]; expected names among"),
    (lambda: m.f(np.zeros(4), {"K": float("nan")}), r"p\['K'\] = nan: expected a finite value"),
    (lambda: m.f(np.zeros(4), [1, 2, np.inf, 1, 9.8, 1, 0]), r"p: entry 2 is inf"),
    (lambda: m.f(np.zeros(4), {"K": -1.0}), r"p\['K'\] = -1.0: expected > 0"),
    (lambda: m.f(np.zeros(4), {"J_m": 0.0}), r"p\['J_m'\] = 0.0: expected > 0"),
    (lambda: m.f(np.zeros(4), {"B_m": -0.1}), r"p\['B_m'\] = -0.1: expected >= 0"),
    (lambda: p2.f(np.zeros(8), {"m1": 0.0}), r"p\['m1'\] = 0.0: expected > 0"),
    (lambda: p2.f(np.zeros(8), {"r2": 1.5}), r"p\['r2'\] = 1.5: expected <= l2 = 1.0"),
    (lambda: m.f(np.zeros(4), {"K": "stiff"}), r"p\['K'\] = 'stiff': expected a real number"),
    (lambda: m.xdot(np.zeros(4), [1, 2]), r"u: expected shape \(1,\), got shape \(2,\)"),
    (lambda: ctrl(delta=0), r"delta = \[0.0\]: expected values > 0"),
    (lambda: ctrl(k_s=-1), r"k_s = \[-1.0\]: expected values >= 0"),
    (lambda: ctrl(c=[1, 2, 3]), r"lam/c: give exactly one of lam"),
    (lambda: make_controller("pid", m, m.default_params, lam=8), r"controller = 'pid': expected one of smc"),
    (lambda: make_controller("ismc", m, m.default_params, lam=8, k_s=1, delta=1, u_max=0),
     r"u_max = \[0.0\]: expected values > 0"),
    (lambda: make_controller("adaptive", m, m.default_params, lam=8, k_s=1, delta=1, K_bounds=(200, 100)),
     r"K_bounds = .*expected finite 0 < K_min < K_max"),
    (lambda: make_reference("square", 1), r"reference = 'square': expected one of step, sine, constant"),
    (lambda: make_reference("sine", 2, amplitude=[1, 2, 3]), r"amplitude with shape \(3,\): expected a scalar or shape \(2,\)"),
    (lambda: simulate(m, ctrl(), make_reference("sine", 1), duration=0.0), r"duration = 0.0: expected a finite value > 0"),
    (lambda: simulate(m, ctrl(), make_reference("sine", 1), duration=1.0, dt=float("nan")), r"dt = nan: expected"),
    (lambda: simulate(m, ctrl(), make_reference("sine", 1), duration=1.0, x0=np.zeros(3)), r"x0 with shape \(3,\): expected \(4,\)"),
    (lambda: sample_parameters(m, 5, k_range=(200, 100)), r"k_range = \(200, 100\): expected 0 < K_min <= K_max"),
]


@pytest.mark.parametrize("call, message", CASES, ids=[c[1][:40] for c in CASES])
def test_error_path(call, message):
    with pytest.raises(ValueError, match=message):
        call()
