"""Monte Carlo attribution of a miss (fjm_runtime.analysis.search.attribution)."""
import pytest

import fjm_runtime
from fjm_runtime.analysis.search.draws import draw_params
from fjm_runtime.sim.interface import CommandInterface
from fjm_runtime.sim.sensor import SensorModel
from support.tiny_search import TINY, run_search


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_attribution_reruns_the_binding_draw_without_each_noise_source():
    """'as designed' reproduces the miss (same plant row, gains, noise seed); with every level at zero the
    figure no longer depends on the noise seed; the design's sensor is restored afterwards."""
    from fjm_runtime.analysis.search.attribution import attribute, variants
    from fjm_runtime.analysis.search.runs import DesignLoops
    m = fjm_runtime.load("link1")
    a = run_search(m, sensor=SensorModel.panda_white(seed=5), **TINY)
    miss = a["binding"]
    assert miss["threshold"] == "jitter" and a["limited_by"] and a["attribution"]["as designed"] == miss["value"]
    loops = DesignLoops(m, "ismc", "torque", 1000.0, 1, SensorModel.panda_white(seed=5), None, None, True)
    row = draw_params(m, 3, 5)[miss["draw"]]
    sentence, figs = attribute(loops, a["gains"], row, miss["seed"], 0.3, miss)
    assert figs == a["attribution"] and sentence == a["limited_by"]
    assert loops.sensor == SensorModel.panda_white(seed=5)          # the design's sensor is restored
    other = attribute(loops, a["gains"], row, miss["seed"] + 99, 0.3, miss)[1]
    assert other["as designed"] != figs["as designed"]
    assert other["every noise level at zero"] == figs["every noise level at zero"]
    ratelimited = CommandInterface.motor().with_rate_limit(2000.0)
    assert "no torque-rate limit" in variants(loops.sensor, ratelimited)
    assert "no torque-rate limit" not in variants(loops.sensor, CommandInterface.motor())
    # the torque sensor carries this jitter (panda_white: tau_J 0.05 N m, differentiated for dtau_J)
    assert figs["torque-sensor noise (tau_J, dtau_J)"] < 0.5 * figs["as designed"]
    assert figs["encoder noise (q, q_m)"] == pytest.approx(figs["as designed"], rel=0.01)
    assert "torque-sensor noise (tau_J, dtau_J)" in sentence and set(figs) == {
        "as designed", "encoder noise (q, q_m)", "velocity noise (dq, dq_m)", "torque-sensor noise (tau_J, dtau_J)",
        "every noise level at zero"}                                # panda_white: no rate limit to remove
