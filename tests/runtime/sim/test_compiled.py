"""Compiled sampled-data loop (fjm_runtime.sim.compiled): same trajectories as Python (its cache:
tests/runtime/test_ccache.py)."""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import Sinusoid
from fjm_runtime.sim.simulate import simulate

# slow: builds C, a wheel or derives in a subprocess: `pytest -m 'not slow'` skips it; each test on a cache
# of its own (conftest's private_cache)
pytestmark = [pytest.mark.slow, pytest.mark.usefixtures("private_cache")]


@pytest.mark.parametrize("name,kind,kw", [
    ("link1", "smc", {"k_s": 300.0, "delta": 2.0}),
    ("link1", "ismc", {"k_s": 300.0, "delta": 2.0, "u_max": 5.0}),
    ("planar2", "smc", {"k_s": 100.0, "delta": 2.0}),
])
def test_compiled_equals_python(name, kind, kw):
    m = fjm_runtime.load(name)
    true = {"K": 110.0} if name == "link1" else {"K1": 120.0, "K2": 180.0}
    ctrl = make_controller(kind, m, {}, lam=8.0, **kw)
    ref = Sinusoid(0.5, 1.0, n=m.n)
    a = simulate(m, ctrl, ref, duration=0.5, true_params=true, backend="python")
    b = simulate(m, ctrl, ref, duration=0.5, true_params=true, backend="compiled")
    assert np.max(np.abs(a.x - b.x)) < 1e-9
    assert np.max(np.abs(a.u - b.u)) < 1e-9 * max(1.0, np.max(np.abs(a.u)))
    assert np.max(np.abs(a.s - b.s)) < 1e-9 * max(1.0, np.max(np.abs(a.s)))
    if a.z.size:
        assert np.max(np.abs(a.z - b.z)) < 1e-9
    for k, v in a.metrics.as_dict().items():
        assert b.metrics.as_dict()[k] == pytest.approx(v, rel=1e-9, abs=1e-12)
