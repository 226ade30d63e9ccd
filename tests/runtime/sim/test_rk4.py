"""The RK4 the simulation tests compare the sampled loop against (support.numerics.rk4): fourth-order
convergence on the generated link1 model and on a scalar ODE."""
import numpy as np

import fjm_runtime
from support.numerics import rk4


def _open_loop_error(dt, ref, rhs, x0, t_end):
    x = rk4(rhs, x0, dt, int(round(t_end / dt)))
    return np.max(np.abs(x[-1] - ref))


def test_rk4_order_on_link1_open_loop():
    m = fjm_runtime.load("link1")
    p = m.params_array({"K": 150.0})
    rhs = lambda x: m.f(x, p)  # u = 0: pendulum swinging on its spring
    x0 = np.array([0.5, 0.0, 0.3, 0.0])
    fine = rk4(rhs, x0, 2.5e-4, 4000)
    errs = [_open_loop_error(dt, fine[-1], rhs, x0, 1.0) for dt in (0.02, 0.01, 0.005)]
    ratios = [errs[0] / errs[1], errs[1] / errs[2]]
    assert all(13.0 < r < 19.0 for r in ratios), (errs, ratios)


def test_rk4_step_matches_exponential():
    # w' = -2 w + sin t (time carried as a second state, t' = 1) has the exact solution below;
    # one step's error is O(dt^5)
    rhs = lambda w: np.array([-2.0 * w[0] + np.sin(w[1]), 1.0])
    exact = lambda t: (1.2 + 0.2) * np.exp(-2 * t) + (2 * np.sin(t) - np.cos(t)) / 5
    w0 = np.array([exact(0.0), 0.0])
    e1 = abs(rk4(rhs, w0, 0.1, 1)[-1, 0] - exact(0.1))
    e2 = abs(rk4(rhs, w0, 0.05, 1)[-1, 0] - exact(0.05))
    assert 25.0 < e1 / e2 < 40.0  # local error ratio ~ 2^5 = 32
