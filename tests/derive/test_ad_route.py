"""The emitted T, alpha and torque-sensed functions (CasADi AD of the inverse dynamics) against
independent routes: the SymPy implicit derivation, and Pinocchio's RNEA for the programme itself.

* ``T``, ``alpha`` (state laws) and ``T_tau``, ``alpha_tau`` (torque-sensed) of the emitted route
  (:mod:`derive.emit.dynamics`) equal those of the SymPy route (``linearize(..., symbolic=True)``,
  :func:`derive.core.torque.torque_linearize`) at random states, to 1e-12 relative;
* the RNEA with the acceleration as an input (``model.inverse_dynamics``) equals Pinocchio's
  ``rnea(q, dq, ddq)`` on the same URDF;
* the C file's MX twins equal the ``.casadi`` SX Functions.
"""

from __future__ import annotations

import numpy as np
import pytest

from derive.emit.dynamics import inverse_dynamics
from derive.emit.functions import build_model_functions, build_functions
from derive.emit.torque import build_torque_functions, build_torque_functions_symbolic
from derive.core.linearize import linearize
from derive.registry import build
from derive.core.torque import torque_linearize

RTOL = 1e-12


def _close(a, b, what):
    a, b = np.array(a, dtype=float), np.array(b, dtype=float)
    assert a.shape == b.shape, what
    if a.size == 0:
        return
    scale = max(1.0, float(np.max(np.abs(b))))
    err = float(np.max(np.abs(a - b))) / scale
    assert err <= RTOL, f"{what}: relative error {err:.2e}"


def _states(rng, n, count=6):
    for _ in range(count):
        q = rng.uniform(-np.pi, np.pi, n)
        dq = rng.uniform(-2, 2, n)
        yield np.concatenate([q, dq, q + rng.uniform(-0.1, 0.1, n), dq + rng.uniform(-1, 1, n)])


def _params(m, rng):
    return np.array([p.default for p in m.params]) * rng.uniform(0.8, 1.2, len(m.params))


@pytest.mark.parametrize("name", ["link1", "planar3", "elbow3", "panda"])
def test_emitted_T_alpha_equal_the_symbolic_route(name):
    rng = np.random.default_rng(19)
    emitted, kernel = build_model_functions(linearize(build(name)))
    lin_sym = linearize(build(name), symbolic=True)
    symbolic = build_functions(lin_sym, route="symbolic")
    m = lin_sym.model
    tor = build_torque_functions(lin_sym, kernel)
    tor_sym = build_torque_functions_symbolic(torque_linearize(lin_sym))
    n = m.n
    for x in _states(rng, n):
        p = _params(m, rng)
        for q in ("T", "alpha", "beta", "f"):
            _close(emitted[q](x, p), symbolic[q](x, p), f"{name} {q}")
        meas = np.concatenate([x[:2 * n], rng.uniform(-5, 5, 2 * n), x[3 * n:]])
        for q in ("T_tau", "alpha_tau", "beta_tau"):
            _close(tor[q](meas, p), tor_sym[q](meas, p), f"{name} {q}")


def test_spatial_models_have_the_rnea_programme_and_planar_ones_not():
    assert build("panda").inverse_dynamics is not None
    assert build("planar3").inverse_dynamics is None


def _pinocchio(name):
    import pinocchio as pin
    import fjm_runtime
    from support.paths import REPO
    m = fjm_runtime.load(name)
    src = m.manifest["source"]
    model = pin.buildModelFromUrdf(str(REPO / src["urdf"]))
    model.gravity.linear[:] = [0.0, 0.0, -float(m.default_params["g0"])]
    assert [model.names[j] for j in range(1, model.njoints)] == src["joints"]
    nqs = [model.joints[j].nq for j in range(1, model.njoints)]

    def q_pin(q):  # continuous joints are (cos, sin) in Pinocchio
        return np.concatenate([[np.cos(v), np.sin(v)] if k == 2 else [v] for v, k in zip(q, nqs)])
    return pin, model, model.createData(), q_pin, [float(m.default_params[k]) for k in m.param_names]


@pytest.mark.parametrize("name", ["elbow3", "panda"])
def test_inverse_dynamics_programme_equals_pinocchio_rnea(name):
    """tau(q, dq, ddq) of the RNEA programme (the one the emitted T, alpha differentiate) == rnea."""
    pin, model, data, q_pin, p = _pinocchio(name)
    tau = inverse_dynamics(build(name))
    rng = np.random.default_rng(7)
    n = model.nv
    for _ in range(20):
        q, dq, a = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n), rng.uniform(-5, 5, n)
        ref = pin.rnea(model, data, q_pin(q), dq, a)
        np.testing.assert_allclose(np.array(tau(q, dq, a, p)).ravel(), ref, rtol=1e-10,
                                   atol=1e-10 * max(1.0, np.max(np.abs(ref))))


@pytest.mark.parametrize("name", ["planar3", "panda"])
def test_c_twins_equal_the_casadi_functions(name):
    """The MX twins the C file is generated from (kernel called once) == the SX ``.casadi`` Functions."""
    from derive.emit.feedforward import build_feedforward
    from derive.emit.writer import _build_laws, c_functions
    lin = linearize(build(name))
    functions, kernel = build_model_functions(lin)
    feedforward = build_feedforward(lin.model)
    controls = _build_laws(lin, functions, kernel, feedforward)
    twins = c_functions(lin, functions, controls, kernel, feedforward)
    assert set(twins) == set(functions) | set(controls) | {"feedforward"}
    rng = np.random.default_rng(3)
    for key in ("T", "alpha", "control_core", "T_tau", "alpha_tau", "control_core_tau", "control_smc",
                "control_impedance", "control_joint_impedance"):
        sx, mx = {**functions, **controls}[key], twins[key]
        assert mx.name() == sx.name() and mx.name_in() == sx.name_in() and mx.name_out() == sx.name_out()
        args = [rng.uniform(0.5, 1.5, sx.size1_in(i) * sx.size2_in(i)) for i in range(sx.n_in())]
        for a, b in zip(mx.call(args), sx.call(args)):
            _close(a, b, f"{name} {key}")


@pytest.mark.parametrize("name", ["planar3", "panda", "panda_hd", "link1_hd"])
def test_the_cores_beta_from_the_kernels_D_equals_beta(name):
    """A law's core takes ``beta`` from the kernel's ``D`` output (one ``D`` per call), ``<model>_beta`` from
    ``inertia``: the same matrix, wired two ways; and the core's ``y_hat`` and ``alpha`` are ``T`` and ``alpha``
    (state and torque-sensed, linear and nonlinear springs)."""
    import casadi as ca
    import fjm_runtime
    m = fjm_runtime.load(name)
    rng = np.random.default_rng(11)
    def load(quantity):  # a .casadi file: comment lines, then the serialized Function
        text = (m.directory / f"{quantity}.casadi").read_text().splitlines()
        return ca.Function.deserialize(next(ln for ln in text if ln and not ln.startswith("#")))
    core, core_tau = load("control_core"), load("control_core_tau")
    T_tau, alpha_tau, beta_tau = load("T_tau"), load("alpha_tau"), load("beta_tau")
    for _ in range(3):
        x = rng.uniform(-1, 1, m.nx)
        p = m.params_array() * rng.uniform(0.9, 1.1, len(m.param_names))
        y_hat, alpha, beta = core(x, p)
        _close(y_hat, m.T(x, p).reshape(-1, 1), f"{name} core y_hat")
        _close(alpha, m.alpha(x, p).reshape(-1, 1), f"{name} core alpha")
        _close(beta, m.beta(x, p), f"{name} core beta")
        meas = rng.uniform(-1, 1, 5 * m.n)
        y_hat, alpha, beta = core_tau(meas, p)
        _close(y_hat, T_tau(meas, p), f"{name} core_tau y_hat")
        _close(alpha, alpha_tau(meas, p), f"{name} core_tau alpha")
        _close(beta, beta_tau(meas, p), f"{name} core_tau beta")
