"""examples/c/designed_controller.c (make designed): the Panda's shipped design, exported by
`fjm export controller` and linked as a library, holds the design's thresholds in a 10 s closed loop
with the generated plant, the design's sensor noise and one sample of delay.

Checked: the program's figures (second-half RMS, time at a torque limit, jitter of joints 1-4, the
same definitions as fjm_runtime.sim.metrics) hold and the noise reached the loop; and its first
torque -- computed before any noisy reading is used (the delay buffer holds the rest reading) -- is
the simulator's sample step's from the same rest state (1e-9 relative), so the reading layout, the
reference layout and the reset are the simulator's. The double model object is built at -O0 (a
quicker compile; the run is the same arithmetic, as in test_realtime_example.py).
"""
import json
import subprocess

import casadi as ca
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.control.design import Design
from fjm_runtime.export.controller import design_controller
from fjm_runtime.sim.sample_step import initial_step_state, sample_step_function
from support.paths import REPO

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def run():
    out = REPO / "build" / "designed-example"   # make rebuilds only what changed
    proc = subprocess.run(["make", "--no-print-directory", "-C", str(REPO / "examples" / "c"), "designed",
                           f"OUT={out}", "CC=gcc", "GEN_CFLAGS_double=-O0"], stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True)
    rows = [json.loads(ln) for ln in proc.stdout.splitlines() if ln.startswith("{")]
    assert rows, proc.stdout[-2000:] + proc.stderr[-2000:]
    return out, rows[-1], proc.returncode


def test_designed_controller_holds_the_design_thresholds(run):
    _, row, rc = run
    print(json.dumps(row))
    assert row["seconds"] == 10 and row["rate_hz"] == 1000
    assert row["status_ok"] + row["status_saturated"] == 10001 and row["status_not_finite"] == 0
    assert row["worst_rms"] <= 2e-3 and row["worst_at_limit"] <= 0.02 and row["worst_jitter_1_4"] <= 3.0, row
    assert row["holds"] and rc == 0
    assert min(row["torque_jitter"][:4]) > 0.1, "no torque jitter: the sensor noise did not reach the loop"


def test_first_torque_equals_the_simulator(run):
    out, _, _ = run
    u = np.fromfile(out / "designed" / "u.bin", dtype=np.float64).reshape(-1, 7)
    model = fjm_runtime.load("panda")
    design = design_controller(model, Design.shipped("panda", "ismc", "torque", 1000.0, 1))
    L, p = design.layout, np.asarray(design.controller.p_nom, dtype=float)
    ref, x0 = design.design.reference(model), design.design.start_state(model)
    w0 = initial_step_state(model, L, x0, np.zeros(L.nz), p, sensor=design.sensor)
    r0 = np.asarray(ref.sample(np.zeros(1)), dtype=float).reshape(5 * L.n)
    _, aux = sample_step_function(model, design.controller, L)(w0, r0, np.zeros(L.nm), p)
    u_ref = np.asarray(aux).ravel()[:L.n]
    assert np.max(np.abs(u[0] - u_ref)) <= 1e-9 * np.max(np.abs(u_ref)), (u[0], u_ref)
    assert np.max(np.abs(u[1] - u[0])) > 0.0     # from the next sample on, the noisy readings are in
