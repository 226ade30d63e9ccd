"""examples/c/realtime.c: the torque-sensed Panda law at 1 kHz in double and float (make realtime).

The C program builds the measurement m = [q; dq; tau_J; dtau_J; dq_m] from its simulated plant
(true stiffness 0.8 x nominal, unknown to the law) and runs the emitted control_ismc_tau. Checked
here: both precisions track, the float torques stay close to the double ones, and the double run
equals the Python runtime's controller evaluated on the C run's own first sample (C == Python).

Built as `make realtime` builds it (realtime.c and the float model at CFLAGS -O2, everything under
-Werror), except the double model object at -O0 (GEN_CFLAGS_double): the 1.3 MB panda.c compiles in a
fraction of the time, the run is bit for bit the same (SSE2 arithmetic, -std=c99: no contraction), and
its strict -O2 build is tests/generated/test_c_sources.py's (panda, double).
"""
import json
import subprocess

import numpy as np
import pytest

import fjm_runtime as fjm
from fjm_runtime.control.defaults import PANDA_ISMC_TAU_START
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.sensing import torque_measurement
from fjm_runtime.experiments.panda import PANDA_EFFORT, reference
from fjm_runtime.sim.rest import rest_state
from support.paths import REPO

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def runs():
    out = REPO / "build" / "rt-example"      # make rebuilds only what changed (generated/panda, realtime.c)
    proc = subprocess.run(["make", "--no-print-directory", "-C", str(REPO / "examples" / "c"), "realtime",
                           f"OUT={out}", "RT_MODELS=panda", "CC=gcc", "GEN_CFLAGS_double=-O0"], stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    rows = [json.loads(ln) for ln in proc.stdout.splitlines() if ln.startswith("{")]
    return out, rows


def test_torque_sensed_panda_tracks_in_both_precisions(runs):
    _, rows = runs
    by_real = {r["real"]: r for r in rows if "rms_error" in r}
    assert set(by_real) == {"double", "float"}
    for r in by_real.values():
        assert r["rate_hz"] == 1000 and r["rms_error"] < 1e-4, r
        assert r["max_abs_u"] < max(PANDA_EFFORT), r
    cmp = [r for r in rows if "max_abs_u_deviation" in r][0]
    assert cmp["samples"] == 7 * 10001 and cmp["relative"] < 0.05, cmp


def test_first_torque_equals_the_python_controller(runs):
    out, _ = runs
    u = np.fromfile(out / "rt" / "panda-double" / "u.bin", dtype=np.float64).reshape(-1, 7)
    m = fjm.load("panda")
    p_true = dict(m.default_params)
    p_true.update({f"K{i + 1}": 0.8 * m.default_params[f"K{i + 1}"] for i in range(7)})
    ref = reference()
    x0 = rest_state(m, ref(0.0)[0], p_true)
    ctrl = make_controller("ismc", m, m.default_params, sensing="torque", u_max=np.asarray(PANDA_EFFORT),
                           **PANDA_ISMC_TAU_START)
    K = np.array([p_true[f"K{i + 1}"] for i in range(7)])
    s = ctrl.evaluate(0.0, torque_measurement(x0, K), np.zeros(7), ref(0.0))
    np.testing.assert_allclose(u[0], s.u, rtol=1e-9, atol=1e-9)
