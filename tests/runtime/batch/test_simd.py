"""The SIMD batch (fjm_runtime.batch.simd): its vector calls of the outlined RK4 substeps agree with the scalar
loop and single runs, and its source emits each callee once."""
from __future__ import annotations

import numpy as np
import pytest

from fjm_runtime import make_reference, simulate, simulate_batch
from fjm_runtime.batch.sampled import GainInput, sampled_metric_step
from fjm_runtime.batch.simd import soa_source
from fjm_runtime.sim.interface import CommandInterface
from fjm_runtime.sim.sensor import SensorModel
from fjm_runtime.sim.step_layout import make_layout
from support.sampled_loop import planar2_torque_ismc


@pytest.fixture(scope="module")
def case():
    return planar2_torque_ismc()


def test_simd_calls_agree_with_the_scalar_loop_and_single_runs(case):
    m, ctrl = case
    ref = make_reference("sine", 2, amplitude=0.3, omega=2.0)
    P = np.tile(m.params_array({}), (3, 1))
    P[:, list(m.param_names).index("K1")] *= [0.8, 1.0, 1.2]
    kw = dict(duration=0.5, sensor=SensorModel.franka_like(seed=4), delay_samples=2, predict=True, substeps=3)
    a = simulate_batch(m, ctrl, ref, P, simd=False, **kw)
    b = simulate_batch(m, ctrl, ref, P, simd=True, **kw)
    assert b.info["path"].startswith("simd") and a.info["path"] == "scalar"
    for k in a.joint_metrics:
        assert np.allclose(a.joint_metrics[k], b.joint_metrics[k], rtol=1e-9, atol=1e-12), k
    single = simulate(m, ctrl, ref, true_params=P[2], backend="compiled",
                      **{**kw, "sensor": kw["sensor"].with_seed(int(a.seeds[2]))})
    assert np.allclose(single.x[-1], a.x_final[2], rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("interface", [CommandInterface.ideal(), CommandInterface.motor()])
def test_soa_source_emits_each_callee_once(case, interface):
    """Ideal actuator: one callee (the held-torque RK4 step) for plant and predictor; with the current loop
    the plant's substeps call the staged RK4 step (the torque at the stages' times), a second callee."""
    m, ctrl = case
    L = make_layout(m, GainInput(ctrl), 1e-3, 4, SensorModel.ideal(), 2, True, interface=interface)
    step = sampled_metric_step(m, GainInput(ctrl), L, 1e6, 21)[0]
    src = soa_source(step, 4, varying=(0, 2), invariant_from=step.size1_in(0) - len(m.param_names))
    callees = 1 if interface.is_ideal() else 2
    for i in range(callees):
        assert src.count(f"static void fjm_fn{i}(") == 1
    assert sum(src.count(f"fjm_fn{i}(ci, co, inv + ") for i in range(callees)) == 4 * (1 + 2)  # plant and predictor


def test_passthrough_entries_are_the_riding_gains_and_the_true_parameters(case):
    """The entries the batch step passes through unchanged (hoisted, never stored by the SIMD form) are exactly
    the gains riding in the controller state, the rate-limit counts (no rate limit here: they stay 0) and the
    TRUE parameters at the end of the accumulator."""
    from fjm_runtime.batch.simd import passthrough_entries
    m, ctrl = case
    gi = GainInput(ctrl)
    L = make_layout(m, gi, 1e-3, 2, SensorModel.panda_white(), 1, False)
    step, A = sampled_metric_step(m, gi, L, 1e6, 21)
    z = L.slices()[1]
    p0 = A.offsets()["p"][0]
    r0 = A.offsets()["rate_j"][0]
    assert not L.rate_step
    expected = list(range(z.start + gi.n_law, z.stop)) + list(range(r0, r0 + m.n)) + list(range(p0, A.nacc))
    assert len(expected) == gi.n_gains + m.n + len(m.param_names)
    assert sorted(passthrough_entries(step)) == expected
