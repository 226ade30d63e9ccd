"""The identification's signal processing from first principles (fjm_runtime.ident.signals)."""
import numpy as np
import pytest

from fjm_runtime.ident.signals import consistent_kernels, held_torque, moving_rows, smooth_derivatives, white_noise


def test_derivative_kernels_are_the_value_kernel_on_differences():
    """K1 x = w (central difference of x) and K2 x = w (second difference of x), to rounding, for any x."""
    dt, h = 1e-3, 15
    K = consistent_kernels(h, dt)
    x = np.random.default_rng(0).standard_normal(400)
    w = K[0][1:-1]                       # zero at both ends
    S, dS, ddS = smooth_derivatives(x[:, None], dt, h, kernels=K)
    d1 = (x[2:] - x[:-2]) / (2 * dt)
    d2 = (x[2:] - 2 * x[1:-1] + x[:-2]) / dt ** 2
    ref1 = np.convolve(d1, w[::-1], mode="valid")
    ref2 = np.convolve(d2, w[::-1], mode="valid")
    assert K[0].sum() == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_allclose(dS[:, 0], ref1, rtol=0, atol=1e-9 * np.max(abs(ref1)))
    np.testing.assert_allclose(ddS[:, 0], ref2, rtol=0, atol=1e-9 * np.max(abs(ref2)))


def test_held_torque_matches_the_second_difference_of_a_held_motion():
    """A unit mass under a held (zero-order) torque: Delta^2 x / dt^2 at t_k is (u[k-1] + u[k]) / 2 exactly."""
    dt = 1e-2
    u = np.random.default_rng(1).standard_normal(50)
    x, v, X = 0.0, 0.0, []
    for uk in u:                          # exact integration of a constant acceleration over each sample
        X.append(x)
        x, v = x + v * dt + 0.5 * uk * dt ** 2, v + uk * dt
    X = np.array(X)
    acc = (X[2:] - 2 * X[1:-1] + X[:-2]) / dt ** 2
    np.testing.assert_allclose(acc, held_torque(u)[1:-1], rtol=0, atol=1e-9)


def test_white_noise_variance_under_a_smooth_motion():
    rng = np.random.default_rng(2)
    t = np.arange(0, 20, 1e-3)
    x = 0.5 * np.sin(2 * t) + 3e-5 * rng.standard_normal(t.size)
    assert white_noise(x) == pytest.approx(9e-10, rel=0.03)


def test_moving_rows_leave_out_the_windows_around_a_reversal():
    v = np.cos(np.linspace(0, np.pi, 1001))          # one reversal at sample 500
    rows = moving_rows(v, 10, 0.1)
    slow = np.flatnonzero(np.abs(v) <= 0.1)
    assert not rows[slow[0] - 10:slow[-1] + 11].any()
    assert rows[:slow[0] - 10].all() and rows[slow[-1] + 11:].all()
