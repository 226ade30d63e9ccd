"""The plant's substeps (fjm_runtime.sim.substeps): the fastest mode from the model's formulas, convergence
to a ten times finer reference, the one-line warning for coarse substeps."""
import warnings

import numpy as np
import pytest

from fjm_runtime.control.references import Sinusoid
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.sim.substeps import CoarseIntegrationWarning, fastest_mode, resolve_substeps
from support.sampled_loop import ismc_controller


def test_fastest_mode_equals_the_link1_formula(link1):
    # link1: D = J_l, so omega^2 = K / J_l + K / J_m (independent of q)
    p = link1.params_array({"K": 180.0, "J_l": 0.7, "J_m": 1.9})
    x0 = np.array([0.4, 0.1, -0.2, 0.3])
    assert fastest_mode(link1, x0, p) == pytest.approx(np.sqrt(180.0 / 0.7 + 180.0 / 1.9), rel=1e-12)


def test_fastest_mode_uses_the_inverse_inertia_diagonal(planar2):
    p = planar2.params_array({})
    x0 = np.array([0.3, -0.5, 0, 0, 0.3, -0.5, 0, 0], dtype=float)
    D = np.asarray(planar2.inertia(x0, p), dtype=float).reshape(2, 2)
    K = p[[planar2.param_names.index("K1"), planar2.param_names.index("K2")]]
    Jm = p[[planar2.param_names.index("Jm1"), planar2.param_names.index("Jm2")]]
    expected = np.max(np.sqrt(K * np.diag(np.linalg.inv(D)) + K / Jm))
    assert fastest_mode(planar2, x0, p) == pytest.approx(expected, rel=1e-9)


def test_substeps_converge_to_a_ten_times_finer_reference(planar2):
    """The default rule's plant equals a 10x finer one to 1e-8 rad (planar2, 2 s at 1 kHz, stiff joints)."""
    ctrl = ismc_controller(planar2)
    stiff = {"K1": 4e4, "K2": 4e4}
    ref = Sinusoid(0.5, 1.0, n=2)
    S = resolve_substeps(None, planar2, np.zeros(8), planar2.params_array(stiff), 1e-3)
    assert S > 1                                   # the rule asks for substeps on this stiff plant
    ideal = "ideal"                                # the rule is for the plant under a held torque
    a = simulate(planar2, ctrl, ref, duration=2.0, true_params=stiff, interface=ideal)
    b = simulate(planar2, ctrl, ref, duration=2.0, true_params=stiff, substeps=10 * S, interface=ideal)
    with pytest.warns(CoarseIntegrationWarning):  # deliberately coarse: the warning is part of the contract
        c = simulate(planar2, ctrl, ref, duration=2.0, true_params=stiff, substeps=1, interface=ideal)
    assert a.settings["substeps"] == S
    err = np.max(np.abs(a.x[:, :2] - b.x[:, :2]))
    assert err < 1e-8
    assert np.max(np.abs(c.x[:, :2] - b.x[:, :2])) > 10 * err   # one step per sample is measurably worse


def test_coarse_substeps_warn_in_one_line(planar2):
    stiff = {"K1": 4e4, "K2": 4e4}
    with pytest.warns(CoarseIntegrationWarning) as rec:
        simulate(planar2, ismc_controller(planar2), Sinusoid(0.5, 1.0, n=2), duration=0.01, true_params=stiff, substeps=1)
    msg = str(rec[0].message)
    assert "\n" not in msg and "omega_max" in msg and "rule" in msg
    with warnings.catch_warnings():
        warnings.simplefilter("error", CoarseIntegrationWarning)
        simulate(planar2, ismc_controller(planar2), Sinusoid(0.5, 1.0, n=2), duration=0.01, true_params=stiff)
