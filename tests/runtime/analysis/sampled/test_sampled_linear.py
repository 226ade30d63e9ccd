"""Noise levels of the linear sampled-data analysis (fjm_runtime.analysis.sampled.sampled_linear)."""
from __future__ import annotations

import math

import numpy as np

from fjm_runtime.analysis.sampled.sampled_linear import noise_levels
from fjm_runtime.sim.sensor import SensorModel


def test_quantization_folds_into_noise():
    """Encoder quantization enters as uniform noise: sigma^2 + step^2 / 12 on the angle slots only."""
    s = SensorModel(q=2e-5, q_m=1e-5, tau_J=0.05, q_quant=1e-4, q_m_quant=2e-4, dtau_mode="filtered",
                    velocity_mode="differentiated")
    lev = noise_levels(s, "torque", 2)                    # slots: q, dq, tau_J, dtau_J, dq_m (= q_m's noise)
    assert np.allclose(lev[0:2], math.sqrt(2e-5 ** 2 + 1e-4 ** 2 / 12))
    assert np.allclose(lev[2:4], 0.0) and np.allclose(lev[4:6], 0.05) and np.allclose(lev[6:8], 0.0)
    assert np.allclose(lev[8:10], math.sqrt(1e-5 ** 2 + 2e-4 ** 2 / 12))
