"""The batch step keeps each RK4 substep a call: its size does not grow with substeps and delay.

The plant and the predictor are ``substeps (1 + d)`` RK4 steps a sample. Inlined, each copies the
dynamics into the step (the Panda at 11 substeps, d = 2: 225k SX instructions, a gcc build of over
13 minutes at 5 GB); kept as calls of one ``never_inline`` Function, the step grows by one call
statement per substep. The SIMD emitter turns each call into a call of the callee's vector form.
"""
from __future__ import annotations

import pytest

from fjm_runtime.batch.sampled import GainInput, sampled_metric_step
from fjm_runtime.sim.sample_step import sample_step_function
from fjm_runtime.sim.step_layout import make_layout
from fjm_runtime.sim.sensor import SensorModel
from support.sampled_loop import planar2_torque_ismc


@pytest.fixture(scope="module")
def case():
    return planar2_torque_ismc()


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
