"""The divergence check of the sampled loop (fjm_runtime.sim.step): where it stops and the peak torques it
reports."""
from __future__ import annotations

import numpy as np
import pytest

from fjm_runtime.sim.step import SimulationDivergedError, check_divergence


def test_check_divergence_peak_covers_the_rows_up_to_the_bad_state_only():
    t = np.array([0.1, 0.2, 0.3, 0.4])
    W = np.array([[0.0], [1.0], [np.inf], [0.0]])
    U = np.array([[1.0, -2.0], [-5.0, 1.0], [3.0, 7.0], [100.0, 100.0]])
    before = np.array([[-6.0, 0.5]])
    with pytest.raises(SimulationDivergedError) as e:
        check_divergence(t, W, U, 1e6, before)
    assert e.value.t == 0.3 and e.value.peak_torque.tolist() == [6.0, 7.0]
