"""fjm design then fjm simulate --gains: a tiny search is deterministic and simulate reads the gains file it
writes (the same run as simulating the gains directly)."""
import json

import numpy as np
import pytest

import fjm_runtime
from support.tiny_search import run_search


@pytest.mark.slow
def test_tiny_design_is_deterministic_and_simulate_reads_it(tmp_path):
    from fjm_runtime.cli.main import main
    m = fjm_runtime.load("link1")
    kw = dict(draws=3, duration=0.3, screen_draws=3, screen_duration=0.2, rounds=1, max_extra_delay=1, seed=5,
              progress=lambda msg: None)
    a, b = run_search(m, **kw), run_search(m, **kw)
    assert a["gains"] == b["gains"] and a["worst_case"] == b["worst_case"]
    assert a["kind"] == "ismc" and a["sensing"] == "torque" and a["draws"] == 3
    path = tmp_path / "g.json"
    path.write_text(json.dumps(a))
    import contextlib
    import io
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["simulate", "link1", "--controller", "ismc", "--sensing", "torque", "--gains", str(path),
                     "--duration", "0.3", "--noise", "panda", "--seed", "5", "--delay-samples", "1", "--json"]) == 0
    rep = json.loads(buf.getvalue())
    from fjm_runtime.control.factory import make_controller
    from fjm_runtime.control.references import make_reference
    from fjm_runtime.sim.metrics import rms_second_half
    from fjm_runtime.sim.sensor import SensorModel
    from fjm_runtime.sim.simulate import simulate
    ctrl = make_controller("ismc", m, {}, sensing="torque", **a["gains"])
    r = simulate(m, ctrl, make_reference("sine", 1, amplitude=0.5, omega=1.0), duration=0.3,
                 sensor=SensorModel.panda(seed=5), delay_samples=1)
    assert rep["diverged"] is False
    assert np.allclose(rep["rms_second_half"], rms_second_half(r), rtol=1e-9, atol=0)
