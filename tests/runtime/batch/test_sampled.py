"""The batch step keeps each RK4 substep a call: its size does not grow with substeps and delay.

The plant and the predictor are ``substeps (1 + d)`` RK4 steps a sample. Inlined, each copies the
dynamics into the step (the Panda at 11 substeps, d = 2: 225k SX instructions, a gcc build of over
13 minutes at 5 GB); kept as calls of one ``never_inline`` Function, the step grows by one call
statement per substep. The SIMD emitter turns each call into a call of the callee's vector form.
"""
from __future__ import annotations

import numpy as np
import pytest

from fjm_runtime import make_controller, make_reference, simulate, simulate_batch
from fjm_runtime.batch.sampled import GainInput, sampled_metric_step
from fjm_runtime.batch.simd import soa_source
from fjm_runtime.sim.interface import CommandInterface
from fjm_runtime.sim.sample_step import sample_step_function
from fjm_runtime.sim.step_layout import make_layout
from fjm_runtime.sim.sensor import SensorModel


@pytest.fixture(scope="module")
def case():
    import fjm_runtime
    m = fjm_runtime.load("planar2")
    ctrl = make_controller("ismc", m, nominal_params={}, lam=20, k_s=200, delta=5, sensing="torque")
    return m, ctrl


def _size(m, ctrl, substeps, delay, outline=True):
    L = make_layout(m, GainInput(ctrl), 1e-3, substeps, SensorModel.panda_white(), delay, True)
    if outline:
        return sampled_metric_step(m, GainInput(ctrl), L, 1e6, 21)[0].n_instructions()
    import casadi as ca
    step = sample_step_function(m, GainInput(ctrl), L)
    sx = [ca.SX.sym(f"a{i}", step.size1_in(i)) for i in range(step.n_in())]
    return ca.Function("s", sx, step(*sx)).n_instructions()


def test_step_size_does_not_grow_with_substeps_or_delay(case):
    m, ctrl = case
    base, more_subs, more_delay = _size(m, ctrl, 2, 1), _size(m, ctrl, 8, 1), _size(m, ctrl, 2, 3)
    inlined_base, inlined_more = _size(m, ctrl, 2, 1, False), _size(m, ctrl, 8, 1, False)
    per_substep_inlined = (inlined_more - inlined_base) / 12          # 6 more substeps, plant + predictor
    assert per_substep_inlined > 100                                   # what inlining costs (the dynamics)
    assert (more_subs - base) / 12 < 0.1 * per_substep_inlined        # a call, not a copy
    assert more_delay - base < 0.2 * base                              # two more predictor samples: calls + buffers


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
    assert sum(src.count(f"fjm_fn{i}(ci, co);") for i in range(callees)) == 4 * (1 + 2)  # plant and predictor
