"""Stationary covariance and torque jitter of a linear loop (fjm_runtime.analysis.sampled.sampled_noise)."""
from __future__ import annotations

import numpy as np
import pytest

from fjm_runtime.sim.metrics import torque_jitter


def test_jitter_formula_matches_a_long_linear_run():
    """The Lyapunov/autocovariance jitter equals the metric on a long run of a known linear system
    (modal A with a slow pole, so the moving mean matters; direct feedthrough D, so its lag-0 and
    cross terms matter)."""
    from types import SimpleNamespace

    from scipy.signal import lfilter

    from fjm_runtime.analysis.sampled.sampled_noise import stationary_covariance, torque_jitter_variance
    rng = np.random.default_rng(3)
    lam = np.array([0.995, 0.9, -0.6, 0.3])
    A = np.diag(lam)
    B, C, D = rng.normal(size=(4, 3)), rng.normal(size=(2, 4)), rng.normal(size=(2, 3))
    N, h = 400_000, 10
    noise = rng.normal(size=(N, 3))
    drive = noise @ B.T                                              # (B n_k), the input of w_{k+1}
    W = np.column_stack([lfilter([0.0, 1.0], [1.0, -lam[i]], drive[:, i]) for i in range(4)])
    u = W @ C.T + noise @ D.T
    res = SimpleNamespace(u=np.vstack([u, u[-1:]]), t=1e-3 * np.arange(N + 1))
    measured = torque_jitter(res)
    predicted = np.sqrt(torque_jitter_variance(A, B, C, D, h, stationary_covariance(A, B)))
    assert np.all(np.abs(predicted / measured - 1) < 0.02), (predicted, measured)


def test_stationary_covariance_solves_the_lyapunov_equation():
    """The doubling sum equals SciPy's discrete Lyapunov solver and satisfies P = A P A' + Q, also with a
    radius of 0.9995 (a slow mode: 1 kHz, 0.5 1/s); an unstable A is refused."""
    from scipy.linalg import solve_discrete_lyapunov

    from fjm_runtime.analysis.sampled.sampled_noise import stationary_covariance
    rng = np.random.default_rng(7)
    V = rng.normal(size=(12, 12))
    M = np.diag(np.r_[0.9995, -0.9, 0.0, 0.0, np.linspace(-0.7, 0.8, 8)])
    M[2:4, 2:4] = 0.5 * np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])   # a complex pair
    A = V @ M @ np.linalg.inv(V)
    assert abs(np.max(np.abs(np.linalg.eigvals(A))) - 0.9995) < 1e-9
    B = rng.normal(size=(12, 3))
    P = stationary_covariance(A, B)
    ref = solve_discrete_lyapunov(A, B @ B.T)
    assert np.max(np.abs(P - ref)) <= 1e-9 * np.max(np.abs(ref))
    assert np.max(np.abs(A @ P @ A.T + B @ B.T - P)) <= 1e-9 * np.max(np.abs(P))
    with pytest.raises(ValueError, match="spectral radius"):
        stationary_covariance(1.01 * np.eye(2), np.ones((2, 1)))
