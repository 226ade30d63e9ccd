"""Every runtime error path in one list: each raises ValueError naming the field and the expectation.

(The model-file error paths are listed in tests/derive/test_model_file.py; property-based
variations of x and p are in tests/runtime/test_validation.py.)
"""

import re

import numpy as np
import pytest

import fjm_runtime as f
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import make_reference
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.batch.sweep import sample_parameters

m = f.load("link1")
p2 = f.load("planar2")


def ctrl(**kw):
    base = dict(lam=8, k_s=1, delta=1)
    base.update(kw)
    return make_controller("smc", m, m.default_params, **base)


# Each case: the call, then what the message must contain, written from the meaning (not copied
# patterns): the argument's name, the bad value (or shape) given, and the expected value/range.
CASES = [
    (lambda: f.load("planar8"), ["planar8", "available models", "link1", "planar7"]),
    (lambda: m.alpha(np.zeros(3)), ["x", "(3,)", "expected", "(4,)"]),
    (lambda: m.alpha([0, np.nan, 0, 0]), ["x", "entry 1", "nan", "finite"]),
    (lambda: m.alpha(["0.1", 0, 0, 0]), ["x", "'0.1'", "numeric", "(4,)"]),
    (lambda: m.f(np.zeros(4), np.ones(6)), ["p", "(6,)", "expected", "(7,)"]),
    (lambda: m.f(np.zeros(4), {"k": 1.0}), ["p", "'k'", "unknown", "J_l", "B_m"]),
    (lambda: m.f(np.zeros(4), {"K": float("nan")}), ["p", "'K'", "nan", "finite"]),
    (lambda: m.f(np.zeros(4), [1, 2, np.inf, 1, 9.8, 1, 0]), ["p", "entry 2", "inf", "finite"]),
    (lambda: m.f(np.zeros(4), {"K": -1.0}), ["p", "'K'", "-1.0", "> 0"]),
    (lambda: m.f(np.zeros(4), {"J_m": 0.0}), ["p", "'J_m'", "0.0", "> 0"]),
    (lambda: m.f(np.zeros(4), {"B_m": -0.1}), ["p", "'B_m'", "-0.1", ">= 0"]),
    (lambda: p2.f(np.zeros(8), {"m1": 0.0}), ["p", "'m1'", "0.0", "> 0"]),
    (lambda: p2.f(np.zeros(8), {"r2": 1.5}), ["p", "'r2'", "1.5", "<= l2", "1.0"]),
    (lambda: m.f(np.zeros(4), {"K": "stiff"}), ["p", "'K'", "'stiff'", "number"]),
    (lambda: m.xdot(np.zeros(4), [1, 2]), ["u", "(2,)", "expected", "(1,)"]),
    (lambda: ctrl(delta=0), ["delta", "0.0", "> 0"]),
    (lambda: ctrl(k_s=-1), ["k_s", "-1.0", ">= 0"]),
    (lambda: ctrl(c=[1, 2, 3]), ["lam", "c", "exactly one"]),
    (lambda: make_controller("pid", m, m.default_params, lam=8), ["controller", "'pid'", "smc", "ismc", "adaptive"]),
    (lambda: make_controller("ismc", m, m.default_params, lam=8, k_s=1, delta=1, u_max=0),
     ["u_max", "0.0", "> 0"]),
    (lambda: make_controller("adaptive", m, m.default_params, lam=8, k_s=1, delta=1, K_bounds=(200, 100)),
     ["K_bounds", "200", "100", "K_min < K_max"]),
    (lambda: make_reference("square", 1), ["reference", "'square'", "step", "sine", "constant"]),
    (lambda: make_reference("sine", 2, amplitude=[1, 2, 3]), ["amplitude", "(3,)", "(2,)"]),
    (lambda: simulate(m, ctrl(), make_reference("sine", 1), duration=0.0), ["duration", "0.0", "> 0"]),
    (lambda: simulate(m, ctrl(), make_reference("sine", 1), duration=1.0, dt=float("nan")), ["dt", "nan", "expected"]),
    (lambda: simulate(m, ctrl(), make_reference("sine", 1), duration=1.0, x0=np.zeros(3)), ["x0", "(3,)", "(4,)"]),
    (lambda: sample_parameters(m, 5, k_range=(200, 100)), ["k_range", "200", "100", "K_min <= K_max"]),
]


@pytest.mark.parametrize("call, fragments", CASES, ids=[" ".join(c[1][:2]) for c in CASES])
def test_error_path(call, fragments):
    with pytest.raises(ValueError) as info:
        call()
    msg = str(info.value)
    # the argument is named as a word at the start or as p[...]/x: (not just a substring of another word)
    first = fragments[0]
    assert re.search(rf"(^|[^A-Za-z0-9_]){re.escape(first)}([^A-Za-z0-9_]|$)", msg), (first, msg)
    missing = [frag for frag in fragments[1:] if frag not in msg]
    assert not missing, f"message lacks {missing}: {msg}"
