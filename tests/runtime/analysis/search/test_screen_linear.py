"""The linear sampled-data analysis as the screen of the gain search (fjm_runtime.analysis.search.screen_linear)."""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.analysis.search.draws import default_spread
from fjm_runtime.sim.sensor import SensorModel


@pytest.mark.slow  # the linear analysis builds CasADi jacobians
def test_linear_screen_verdicts_follow_the_analysis():
    """The screen passes a candidate only when every corner is stable with the decay margin and the predicted
    jitter is within 1.25 x the limit; its reasons and explanation quote the analysis."""
    from fjm_runtime.analysis.search.runs import DesignLoops
    from fjm_runtime.analysis.search.screen_linear import JITTER_SLACK, LinearScreen
    m = fjm_runtime.load("planar2")
    unstable = {"lam": 20.0, "k_lin": [100.0] * 2, "k_s": [200.0] * 2, "delta": [1.0] * 2}
    stable = {"lam": 10.0, "k_lin": [100.0] * 2, "k_s": [50.0] * 2, "delta": [1.0, 0.5]}
    noisy = LinearScreen(DesignLoops(m, "ismc", "torque", 1000.0, 1, SensorModel.panda_white(seed=5), None, None,
                                     True), default_spread(m))
    a, b = noisy.check([unstable, stable])
    # small-signal unstable (radius > 1 inside the boundary layer), but under this noise s lives outside the
    # layer: the equivalent-gain loop is stable (simulate holds it, 40 / 14 N m of jitter) and the jitter rejects it
    assert not a.ok and a.reason.startswith("predicted jitter") and a.predicted["rho"] < 1.0
    jit = b.predicted["torque_jitter"]
    assert not b.ok and b.predicted["rho"] <= noisy.rho_max and max(jit) > JITTER_SLACK * 3.0
    assert b.reason == f"predicted jitter {max(jit):.3g} N m on joint {int(np.argmax(jit)) + 1} > 1.25 x 3 N m"
    assert noisy.explain(stable).startswith(f"linear analysis: predicted jitter {max(jit):.3g} N m on joint")
    quiet = LinearScreen(DesignLoops(m, "ismc", "torque", 1000.0, 1, SensorModel.ideal(), None, None, True),
                         default_spread(m))
    assert quiet.check([stable])[0].ok and not quiet.check([unstable])[0].ok     # no noise: stability decides
