"""The emitted flatness feedforward ``<model>_feedforward(r, p)`` from first principles.

* Open loop: ``u = u_ff(r(t))`` evaluated inside the integrator (CVODES, rtol = atol = 1e-12), fed to the
  nominal plant ``f + g u`` from the consistent start ``x0 = [q_d(0); q_d'(0); theta_d(0); theta_d'(0)]``:
  the links follow the reference to <= 1e-8 rad over 10 s, on a smooth step and a sine, for linear
  springs (link1, planar2, the Panda, Baxter's tree) and nonlinear springs with motor friction (link1_hd,
  arm1_hd, panda_hd). Nothing corrects a deviation, so the references move about the rest pose of least
  potential energy (found numerically): there gravity does not amplify the integrator's rounding (about a
  held pose 0.2 rad away from it, Baxter's rounding grows e-fold per second and reaches 3e-8 rad in 10 s).
  The motor damping ``B_m`` is set to 0.5 N m s/rad so that its term counts.
* The identity with the state law: at ``x_d = [q_d; q_d'; theta_d; theta_d']``, ``T(x_d) = r[0:4n]`` and
  ``u_ff = alpha(x_d) + beta(x_d) q_d''''`` (``y4' = nu`` at ``nu = q_d''''``) to 1e-9 relative, on every
  reduced model, at random references and parameters.
"""

from __future__ import annotations

import re

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import minimize

import fjm_runtime
from fjm_runtime.control.references import Reference, Sinusoid, SmoothStep
from fjm_runtime.model import available_models, generated_root
from fjm_runtime.validation import FjmValueError

#: Open-loop cases: (model, reference kind).
OPEN_LOOP = [(m, k) for m in ("link1", "planar2", "panda", "link1_hd", "arm1_hd", "panda_hd", "baxter")
             for k in ("step", "sine")]
HORIZON = 10.0
#: The smooth step's profile 126 s^5 - 420 s^6 + 540 s^7 - 315 s^8 + 70 s^9 and its derivatives (checked
#: against the reference class by :func:`open_loop_error`).
SIGMA = [np.polynomial.Polynomial([0, 0, 0, 0, 0, 126, -420, 540, -315, 70]).deriv(k) for k in range(5)]


def nominal_params(model: fjm_runtime.Model) -> np.ndarray:
    """The defaults with every motor damping ``B_m`` at 0.5 N m s/rad (they default to 0)."""
    p = model.params_array(None)
    for j, name in enumerate(model.param_names):
        if re.fullmatch(r"B_?m\d*", name):
            p[j] = 0.5
    return p


def rest_pose(model: fjm_runtime.Model, p: np.ndarray) -> np.ndarray:
    """The least potential energy over two starts (all zero; joint 2 at pi: a spatial arm hanging down)."""
    n = model.n

    def potential(q):
        return model.energy(np.concatenate([q, 0 * q, q, 0 * q]), p)

    starts = [np.zeros(n)] + ([np.r_[0.0, np.pi, np.zeros(n - 2)]] if n > 1 else [])
    best = min((minimize(potential, s, method="BFGS", options={"gtol": 1e-10}) for s in starts),
               key=lambda res: res.fun)
    return best.x


def symbolic_reference(ref: Reference, t: ca.SX) -> ca.SX:
    """The reference's rows ``q_d .. q_d''''`` stacked (5n) as a CasADi expression of ``t`` (checked against it)."""
    if isinstance(ref, Sinusoid):
        rows = [ca.DM(ref.amplitude * ref.omega ** k) * ca.sin(ca.DM(ref.omega) * t + ca.DM(ref.phase) + k * np.pi / 2)
                for k in range(5)]
        rows[0] = rows[0] + ca.DM(ref.offset)
    else:
        s = ca.fmin(ca.fmax((t - ref.t0) / ref.rise_time, 0), 1)
        rows = [ca.DM(ref.q_d - ref.q0) * sum(float(c) * s ** i for i, c in enumerate(SIGMA[k].coef))
                / ref.rise_time ** k for k in range(5)]
        rows[0] = rows[0] + ca.DM(ref.q0)
    return ca.vertcat(*rows)


def make_reference(kind: str, q_rest: np.ndarray) -> Reference:
    n = q_rest.size
    if kind == "step":  # 0.2 rad on every joint, centred on the rest pose, from t = 0.5 s to 2.5 s
        return SmoothStep(q_rest + 0.1, n=n, q0=q_rest - 0.1, rise_time=2.0, t0=0.5)
    return Sinusoid(amplitude=0.3, omega=2.0, n=n, offset=q_rest)


def open_loop_error(model: fjm_runtime.Model, kind: str) -> float:
    """Largest ``|q(t) - q_d(t)|`` (rad) on a 10 ms grid over :data:`HORIZON` under ``u = u_ff(t)`` open loop."""
    n, p = model.n, nominal_params(model)
    ref = make_reference(kind, rest_pose(model, p))
    t, x = ca.SX.sym("t"), ca.SX.sym("x", 4 * n)
    r_t = symbolic_reference(ref, t)
    r_fn = ca.Function("r", [t], [r_t])
    grid = np.linspace(0.0, HORIZON, 1001)
    assert max(np.max(np.abs(r_fn(tk).full().ravel() - ref(tk).ravel())) for tk in grid[::50]) <= 1e-12
    u_ff = model.feedforward_function(r_t, p)[4]
    xdot = model.functions["f"](x, p) + ca.mtimes(model.functions["g"](x, p), u_ff)
    r0 = ref(0.0).ravel()
    _, theta, dtheta, _, _ = model.feedforward(r0, p)
    x0 = np.concatenate([r0[:n], r0[n:2 * n], theta, dtheta])
    sim = ca.integrator("open_loop", "cvodes", {"x": x, "t": t, "ode": xdot}, 0.0, grid[1:],
                        {"reltol": 1e-12, "abstol": 1e-12, "max_num_steps": 10 ** 6})
    q = sim(x0=x0)["xf"].full()[:n]
    return max(float(np.max(np.abs(q[:, k] - ref(tk)[0]))) for k, tk in enumerate(grid[1:]))


@pytest.mark.parametrize("name,kind", OPEN_LOOP)
def test_open_loop_follows_the_reference(name, kind):
    """u_ff alone, fed to the nominal plant from the consistent start, keeps the links on the reference."""
    err = open_loop_error(fjm_runtime.load(name), kind)
    print(f"{name} {kind}: open-loop max |q - q_d| over {HORIZON:g} s = {err:.2e} rad")
    assert err <= 1e-8


def _reduced_models():
    return [m for m in available_models(generated_root()) if fjm_runtime.load(m).form != "complete"]


@pytest.mark.parametrize("name", _reduced_models())
def test_feedforward_is_the_state_law_at_the_reference(name):
    """T(x_d) = [q_d; q_d'; q_d''; q_d'''] and u_ff = alpha(x_d) + beta(x_d) q_d'''' at x_d = [q_d; q_d'; theta_d; theta_d']."""
    model = fjm_runtime.load(name)
    n = model.n
    rng = np.random.default_rng(37 + n)
    base = nominal_params(model)
    worst_u = worst_T = 0.0
    for _ in range(4):
        # every parameter by its own factor; a drive's curve as a whole (its coefficients keep their order)
        p = base * (rng.uniform(0.8, 1.2) if model.spring_functions else rng.uniform(0.8, 1.2, base.size))
        r = rng.uniform(-0.5, 0.5, 5 * n)
        tau, theta, dtheta, ddtheta, u = model.feedforward(r, p)
        x_d = np.concatenate([r[:n], r[n:2 * n], theta, dtheta])
        expected = model.alpha(x_d, p) + model.beta(x_d, p) @ r[4 * n:]
        worst_u = max(worst_u, float(np.max(np.abs(u - expected)) / np.max(np.abs(expected))))
        worst_T = max(worst_T, float(np.max(np.abs(model.T(x_d, p) - r[:4 * n])) / max(1.0, np.max(np.abs(r)))))
        # the motor equation along the state: ddtheta is the plant's motor acceleration at u_ff
        assert np.allclose(model.xdot(x_d, u, p)[3 * n:], ddtheta, rtol=1e-9, atol=1e-9 * np.max(np.abs(ddtheta)))
    print(f"{name}: u_ff vs alpha + beta q_d'''' {worst_u:.1e}, T(x_d) vs r {worst_T:.1e}")
    assert worst_u <= 1e-9
    assert worst_T <= 1e-9


def test_a_complete_model_has_no_feedforward():
    with pytest.raises(FjmValueError, match="panda_complete.*no feedforward Function.*reduced model"):
        fjm_runtime.load("panda_complete").feedforward_function
