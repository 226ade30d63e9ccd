"""The law table behind make_controller: each name builds its law with its fixed keywords."""
import numpy as np
import pytest

from fjm_runtime.control.defaults import DEFAULT_LAM, DEFAULT_SWITCHING_GAIN, default_delta
from fjm_runtime.control.factory import CONTROLLER_KINDS, FULL_SENSED_KINDS, LAWS, REGULATION_KINDS, make_controller
from fjm_runtime.control.laws import SlidingModeController
from fjm_runtime.control.references import Sinusoid, make_reference


def test_every_name_is_in_the_table():
    assert CONTROLLER_KINDS == ("smc", "ismc", "fl", "sign", "adaptive")
    assert FULL_SENSED_KINDS == ("impedance", "joint_impedance")
    assert set(LAWS) == set(CONTROLLER_KINDS + REGULATION_KINDS + FULL_SENSED_KINDS)


@pytest.mark.parametrize("kind, direct", [("smc", {"mode": "sat"}), ("sign", {"mode": "sign"}),
                                          ("ismc", {"mode": "sat", "integral": True}),
                                          ("fl", {"mode": "fl"})])
def test_table_builds_the_same_law_as_the_constructor(planar2, kind, direct):
    """Same gain vector and same control at a state off the reference as the constructor called by hand."""
    gains = {"lam": DEFAULT_LAM, "delta": default_delta(DEFAULT_SWITCHING_GAIN)}
    k_s = {} if kind == "fl" else {"k_s": DEFAULT_SWITCHING_GAIN}
    a = make_controller(kind, planar2, {}, k_s=DEFAULT_SWITCHING_GAIN, **gains)   # fl drops k_s
    b = SlidingModeController(planar2, {}, **direct, **k_s, **gains)
    np.testing.assert_array_equal(np.asarray(a.gains), np.asarray(b.gains))
    assert a.law_kind == b.law_kind


def test_ismc_takes_another_mode_and_unknown_names_are_refused(planar2):
    c = make_controller("ismc", planar2, {}, lam=DEFAULT_LAM, k_s=10.0, delta=1.0, mode="sign")
    assert c.law_kind == SlidingModeController(planar2, {}, lam=DEFAULT_LAM, k_s=10.0, delta=1.0, mode="sign",
                                               integral=True).law_kind
    with pytest.raises(ValueError, match="controller = 'nope'"):
        make_controller("nope", planar2, {})


def test_unknown_reference_and_controller(link1):
    with pytest.raises(ValueError, match="reference = 'ramp'"):
        make_reference("ramp")
    with pytest.raises(ValueError, match="controller = 'pid'"):
        make_controller("pid", link1, {}, lam=5.0)
    with pytest.raises(ValueError, match="amplitude"):
        Sinusoid([0.1, 0.2, 0.3], n=2)
    with pytest.raises(ValueError, match="rise_time"):
        make_reference("step", rise_time=0.0)
