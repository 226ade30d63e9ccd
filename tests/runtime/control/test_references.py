"""The references' derivatives (fjm_runtime.control.references): each is the time derivative of the one before."""
import numpy as np
import pytest

from fjm_runtime.control.references import Constant, Sinusoid, SmoothStep


@pytest.mark.parametrize("ref", [SmoothStep([1.0, -0.5], n=2, rise_time=1.5, t0=0.2),
                                 Sinusoid([0.5, 0.2], [1.0, 3.0], n=2, phase=[0.0, 1.0]), Constant(0.7)])
def test_reference_derivatives_are_consistent(ref):
    t = np.linspace(0.0013, 2.9987, 300)  # off the step's junctions, where the 5th derivative jumps
    h = 1e-5
    r = ref.sample(t)
    fd = (ref.sample(t + h) - ref.sample(t - h)) / (2 * h)
    scale = np.max(np.abs(r[:, 1:]), axis=0) + 1.0
    assert np.max(np.abs(fd[:, :4] - r[:, 1:]) / scale) < 1e-5
    assert np.allclose(r, np.stack([ref(tk) for tk in t]))
    bounds = ref.derivative_bounds()
    assert np.all(np.max(np.abs(r), axis=0) <= bounds + 1e-9)
