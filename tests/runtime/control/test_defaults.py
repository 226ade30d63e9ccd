"""The gain defaults (fjm_runtime.control.defaults) agree with each other."""
from fjm_runtime.control.defaults import DEFAULT_SWITCHING_GAIN, PAPER_K_RANGE, default_delta


def test_the_defaults_agree_with_each_other():
    """The adaptive estimator's default bounds at the paper's nominal 150 are the paper's range."""
    from fjm_runtime.control.defaults import default_K_bounds
    assert default_K_bounds(150.0) == PAPER_K_RANGE
    assert default_delta(DEFAULT_SWITCHING_GAIN) == 5.0
