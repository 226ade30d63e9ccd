"""The excitation's closed-loop check on the nominal model (fjm_runtime.ident.excite_loop)."""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.ident.excite import design_excitation, nominal_motion
from fjm_runtime.ident.excite_loop import check_in_closed_loop


def test_closed_loop_check_tracks_on_the_nominal_model():
    m = fjm_runtime.load("link1")
    exc = design_excitation(m, 4.0, candidates=3, iterations=2)
    check = check_in_closed_loop(m, exc)
    assert "diverged" not in check
    assert check["max_error"] < 5e-3                       # PD + exact feedforward: noise-level errors
    assert check["peak_torque"][0] == pytest.approx(np.max(np.abs(nominal_motion(
        m, exc.reference, np.arange(4001) * 1e-3, m.params_array())["u"])), rel=0.1)
