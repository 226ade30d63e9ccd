"""The demo's tree section: Baxter's gains (shipped design), its task, and a short real loop."""
import numpy as np
import pytest

import fjm_runtime as fjm
from fjm_runtime.cli.design import demo_task
from fjm_runtime.control.design import Design
from fjm_runtime.experiments import baxter as bx


@pytest.fixture(scope="module")
def baxter():
    return fjm.load("baxter")


def test_the_section_runs_the_shipped_design(baxter):
    spec = Design.shipped("baxter", "ismc", "torque", bx.RATE, bx.DELAY)
    assert spec is not None, "fjm_runtime/control/designed/baxter_ismc_tau_1000hz_d1.json is not shipped"
    gains, source = bx.ismc_gains()
    assert "designed" in source and spec.file in source
    assert set(gains) == {"lam", "k_lin", "k_s", "delta"}
    for k in ("k_lin", "k_s", "delta"):
        assert np.shape(gains[k]) == (baxter.n,) and np.all(np.asarray(gains[k]) > 0)
    # the design searched the demo's own task, loop and limits
    assert spec.sensing == "torque" and spec.predict is True and spec.delay == bx.DELAY
    assert spec.gains["u_max"] == baxter.limits.effort.tolist()
    assert spec.task["offset"] == baxter.task.offset.tolist()
    assert spec.report["worst_case"]["diverged"] == 0


def test_design_task_round_trips_through_the_gains_file(baxter):
    """``fjm design baxter`` records the demo's task; ``fjm simulate --gains`` rebuilds the same one."""
    task = demo_task(baxter)
    design = Design(kind="ismc", gains={}, task=task["task"])
    ref, x0 = design.reference(baxter), design.start_state(baxter)
    for t in (0.0, 0.37, 2.5):
        np.testing.assert_allclose(ref(t)[0], bx.reference(baxter)(t)[0], rtol=0, atol=1e-15)
        np.testing.assert_allclose(ref(t)[0], task["reference"](t)[0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(x0, task["x0"], rtol=0, atol=1e-15)
    assert np.all(np.asarray(x0[baxter.n:2 * baxter.n]) == 0)  # at rest


def test_short_real_loop_with_the_designed_gains(baxter):
    """Both sensings, both stiffness cases: finite, the head holds, and the table has a row each."""
    res = bx.run(baxter, 0.02)
    assert set(res) == set(bx.SENSING) and all(set(per) == set(bx.CASES) for per in res.values())
    for per in res.values():
        for r in per.values():
            assert np.all(np.isfinite(r.x))
            assert np.max(np.abs(r.e1)) < 0.05
    rows = bx.table(res)
    assert len(rows) == 2 + len(bx.SENSING) * len(bx.CASES)
