"""The control laws emitted by ``make derive`` (generated/<model>/control_<kind>.casadi, C).

* every runtime path (python, fused CasADi, compiled) gives the trajectories of an
  independent NumPy implementation of each law, written here from the formulas of the
  README / fjm_runtime.control.adaptive docstring (not from the emitted code) and run through the
  sampled-data loop of docs/simulation.md, to 1e-11 over 10 s (10^4 samples of closed loop: the two
  implementations' rounding, 1e-16 per step, grows to 1.6e-12 on the adaptive planar2 law);
* the emitted C equals the emitted CasADi Function for every law;
* bad gains are rejected by the runtime with the errors that existed before.
"""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import Sinusoid, SmoothStep
from fjm_runtime.sim.simulate import simulate

TOL = 1e-11


def sat(v):
    return np.minimum(np.maximum(v, -1.0), 1.0)


def stiffness_indices(m):
    names = list(m.param_names)
    if m.n == 1:
        return [names.index("K")], [names.index("J_m")], [names.index("B_m")]
    return ([names.index(f"K{i + 1}") for i in range(m.n)], [names.index(f"Jm{i + 1}") for i in range(m.n)],
            [names.index(f"Bm{i + 1}") for i in range(m.n)])


class Dense:
    """A CasADi Function of dense inputs and outputs called through its FunctionBuffer (the same
    evaluation as ``fn(*args)``, bit for bit, without building a DM per argument and result: the
    reference loops below call their Functions 10 000 times per run). Returns NumPy arrays shaped
    like ``fn(*args).full()``."""

    def __init__(self, fn):
        assert all(fn.sparsity_in(i).is_dense() for i in range(fn.n_in())), fn
        assert all(fn.sparsity_out(i).is_dense() for i in range(fn.n_out())), fn
        self.fn = fn
        self.args = [np.zeros(fn.sparsity_in(i).nnz()) for i in range(fn.n_in())]
        self.res = [np.zeros(fn.sparsity_out(i).nnz()) for i in range(fn.n_out())]
        self.shapes = [fn.sparsity_out(i).shape for i in range(fn.n_out())]
        self.buf, self.eval = fn.buffer()
        for i, a in enumerate(self.args):
            self.buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self.res):
            self.buf.set_res(i, memoryview(r))

    def __call__(self, *args):
        for a, v in zip(self.args, args):
            a[:] = np.asarray(v, dtype=float).ravel(order="F")
        self.eval()
        return [r.reshape(shape, order="F").copy() for r, shape in zip(self.res, self.shapes)]


class ReferenceLaw:
    """The laws from their formulas (README "Controllers", fjm_runtime.control.adaptive docstring)."""

    def __init__(self, m, kind, p_nom, lam, k_s=0.0, delta=1.0, beta_hat=None, u_max=None,
                 K_bounds=None, filter_rate=20.0, ls_gain=1e5):
        self.m, self.kind, self.n = m, kind, m.n
        self.p_nom = m.params_array(p_nom)
        self.integral = kind in ("ismc", "adaptive")
        order = 4 if self.integral else 3
        from math import comb
        self.c = np.array([comb(order, k) * lam ** (order - k) for k in range(order)])
        self.k_s = 0.0 if kind == "fl" else k_s
        self.k_lin = lam if kind == "fl" else 0.0
        self.delta, self.beta_hat, self.u_max = delta, beta_hat, u_max
        self.sign = kind == "sign"
        self.iK, self.iJ, self.iB = stiffness_indices(m)
        self.K_bounds, self.a, self.ls_gain = K_bounds, filter_rate, ls_gain

    def z0(self, x0):
        n = self.n
        if self.kind == "adaptive":
            return np.concatenate([np.zeros(n), self.p_nom[self.iK], np.zeros(2 * n), x0[3 * n:], np.full(n, self.ls_gain)])
        return np.zeros(n if self.integral else 0)

    def ev(self, q, x, p):
        """A model Function of (x, p) as an array (the raw casadi.Function: faster than the Model wrapper)."""
        return self.m.functions[q](x, p).full()

    def ev_all(self, x, p):
        """``T``, ``beta`` and ``alpha`` at (x, p) in one call (the three model Functions composed as they are)."""
        if not hasattr(self, "_tba"):
            import casadi as ca
            xs, ps = ca.MX.sym("x", self.m.nx), ca.MX.sym("p", len(self.m.param_names))
            self._tba = Dense(ca.Function("reference_T_beta_alpha", [xs, ps],
                                          [self.m.functions[q](xs, ps) for q in ("T", "beta", "alpha")]))
        return self._tba(x, p)

    def p_hat(self, z):
        p = self.p_nom.copy()
        if self.kind == "adaptive":
            p[self.iK] = np.clip(z[self.n:2 * self.n], *self.K_bounds)
        return p

    def law(self, x, z, r):
        n = self.n
        p = self.p_hat(z)
        T, beta, alpha = self.ev_all(x, p)
        y = T.reshape(4, n)
        e = y - r[:4]
        if self.integral:
            s = self.c[0] * z[:n] + self.c[1] * e[0] + self.c[2] * e[1] + self.c[3] * e[2] + e[3]
            lin = self.c[0] * e[0] + self.c[1] * e[1] + self.c[2] * e[2] + self.c[3] * e[3]
        else:
            s = self.c[0] * e[0] + self.c[1] * e[1] + self.c[2] * e[2] + e[3]
            lin = self.c[0] * e[1] + self.c[1] * e[2] + self.c[2] * e[3]
        psi = np.sign(s) if self.sign else sat(s / self.delta)
        nu = r[4] - lin - self.k_s * psi - self.k_lin * s
        B = beta if self.beta_hat is None else self.beta_hat * np.eye(n)
        u_cmd = alpha.ravel() + B @ nu
        u = u_cmd if self.u_max is None else np.clip(u_cmd, -self.u_max, self.u_max)
        return u, u_cmd, s

    def zdot(self, x, z, r, u_cmd, u):
        n = self.n
        if not self.integral:
            return np.zeros(0)
        e1 = x[:n] - r[0]
        if self.u_max is not None:
            e1 = np.where((u_cmd > self.u_max) & (e1 < 0) | (u_cmd < -self.u_max) & (e1 > 0), 0.0, e1)
        if self.kind != "adaptive":
            return e1
        K_hat, u_f, phi_f, w_f, P = (z[n * (j + 1):n * (j + 2)] for j in range(5))
        Jm, Bm, a = self.p_nom[self.iJ], self.p_nom[self.iB], self.a
        lo, hi = self.K_bounds
        y_f = u_f - Jm * a * (x[3 * n:] - w_f) - Bm * w_f
        upd = P * phi_f * (y_f - np.clip(K_hat, lo, hi) * phi_f)
        out = ((K_hat >= hi) & (upd > 0)) | ((K_hat <= lo) & (upd < 0))
        return np.concatenate([e1, np.where(out, 0.0, upd), a * (u - u_f), a * (x[2 * n:3 * n] - x[:n] - phi_f),
                               a * (x[3 * n:] - w_f), -P ** 2 * phi_f ** 2])


def reference_run(m, law, ref, p_true, duration, dt, substeps):
    """The sampled-data loop of docs/simulation.md, "One sample": the torque held over the sample, the
    controller state advanced once per sample (``z_{k+1} = z_k + dt z_dot_k``), the plant on
    ``substeps`` RK4 steps of ``dt / substeps``."""
    n, nx = m.n, m.nx
    p_true = m.params_array(p_true)
    r0 = ref(0.0)
    x = np.zeros(nx); x[:n] = r0[0]; x[2 * n:3 * n] = r0[0]
    z = law.z0(x)
    N = int(round(duration / dt))
    X, U = np.empty((N + 1, nx)), np.empty((N + 1, n))
    plant = Dense(_substep_plant(m, dt, substeps))
    for k in range(N + 1):
        t = k * dt
        r = ref(t)
        u, u_cmd, _ = law.law(x, z, r)
        X[k], U[k] = x, u
        if k == N:
            break
        z = z + dt * law.zdot(x, z, r, u_cmd, u)
        x = plant(x, u, p_true)[0].ravel()
    return X, U


def _substep_plant(m, dt, substeps):
    """``x_{k+1}`` from ``(x_k, u_k, p)``: ``substeps`` classical RK4 steps of ``dt / substeps`` of
    ``x' = f(x; p) + g(x; p) u`` with ``u`` held, written here and composed from the model's ``f`` and
    ``g`` into one CasADi Function (one call per sample instead of 8 per substep from Python)."""
    import casadi as ca
    f, g = m.functions["f"], m.functions["g"]
    x0, u, p = ca.MX.sym("x", m.nx), ca.MX.sym("u", m.n), ca.MX.sym("p", len(m.param_names))

    def rhs(v):
        return f(v, p) + ca.mtimes(ca.reshape(g(v, p), m.nx, m.n), u)
    h, x = dt / substeps, x0
    for _ in range(substeps):
        k1 = rhs(x); k2 = rhs(x + h / 2 * k1); k3 = rhs(x + h / 2 * k2); k4 = rhs(x + h * k3)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    fn = ca.Function("reference_plant", [x0, u, p], [x])
    try:
        return fn.expand()
    except RuntimeError:  # a model whose f/g cannot be expanded: the MX graph as it is
        return fn


#: RK4 steps per sample in the reference and in the runs; 2 is at or above the substeps rule for these
#: models (fastest mode ~15 rad/s at 1 kHz needs 1), and 2 > 1 makes the check see whether the plant
#: really takes the substeps it is given.
SUBSTEPS = 2


LINK1 = dict(p_nom={"K": 150.0}, p_true={"K": 120.0}, lam=8.0, k_s=1000.0, delta=5.0, beta_hat=0.02)
CHAIN = dict(p_nom={}, p_true={"K1": 140.0, "K2": 160.0}, lam=6.0, k_s=200.0, delta=5.0)
CASES = [
    ("link1", "smc", LINK1, {}),
    ("link1", "sign", dict(LINK1, k_s=30.0), {}),
    ("link1", "ismc", dict(LINK1, u_max=5.0), {}),
    ("link1", "fl", LINK1, {}),
    ("link1", "adaptive", LINK1, {"K_bounds": (100.0, 200.0)}),
    ("planar2", "smc", CHAIN, {}),
    ("planar2", "sign", dict(CHAIN, k_s=5.0), {}),
    ("planar2", "ismc", CHAIN, {}),
    ("planar2", "fl", CHAIN, {}),
    ("planar2", "adaptive", CHAIN, {"K_bounds": (100.0, 200.0)}),
]


@pytest.mark.parametrize("model, kind, case, extra", CASES, ids=[f"{c[0]}-{c[1]}" for c in CASES])
def test_runtime_law_equals_independent_reference(model, kind, case, extra):
    m = fjm_runtime.load(model)
    ref = SmoothStep(0.6, n=m.n, rise_time=2.0) if case.get("u_max") else Sinusoid(0.5, 1.0, n=m.n)
    kw = {k: v for k, v in case.items() if k not in ("p_nom", "p_true")}
    law = ReferenceLaw(m, kind, case["p_nom"], **kw, **({"K_bounds": extra["K_bounds"]} if extra else {}))
    X_ref, U_ref = reference_run(m, law, ref, case["p_true"], 10.0, 1e-3, SUBSTEPS)
    if kw.get("beta_hat") is not None:
        kw["beta_hat"] = kw["beta_hat"] * np.eye(m.n)
    if kind == "fl":
        kw.pop("k_s"); kw.pop("delta")
    ctrl = make_controller(kind, m, case["p_nom"], **kw, **extra)
    if kw.get("u_max") is not None:  # the limit is active: anti-windup is exercised
        assert np.max(np.abs(U_ref)) == pytest.approx(kw["u_max"])
    # python (calls the law and its _zdot per sample) on the stateful link1 laws; casadi (composes them
    # into the fused loop) everywhere;
    # compiled == casadi and python == casadi on chains: tests/runtime/sim/test_compiled.py, tests/runtime/control/test_laws.py
    # (the python backend over the first 0.5 s only: ~40 s of Python loop per 10 s run otherwise)
    runs = [("casadi", 10.0)] + ([("python", 0.5)] if model == "link1" and kind in ("ismc", "adaptive") else [])
    for backend, duration in runs:
        res = simulate(m, ctrl, ref, duration=duration, dt=1e-3, true_params=case["p_true"], backend=backend,
                       substeps=SUBSTEPS, interface="ideal")   # the reference loop holds the torque (ideal actuator)
        X, U = X_ref[:len(res.t)], U_ref[:len(res.t)]
        assert len(res.t) == int(round(duration / 1e-3)) + 1
        scale = max(1.0, np.max(np.abs(U)))
        assert np.max(np.abs(res.x - X)) <= TOL * max(1.0, np.max(np.abs(X))), backend
        assert np.max(np.abs(res.u - U)) <= 1e-10 * scale, backend  # u = alpha + beta nu amplifies


BAD_GAINS = [
    (dict(lam=5.0, delta=-1.0), ["delta", "expected values > 0"]),
    (dict(c=[1.0, 1.0, 5.0, 0.1]), ["c = ", "not Hurwitz"]),
    (dict(c=[1.0, 1.0]), ["c with shape (2,)", "expected"]),
    (dict(lam=5.0, beta_hat=[[1.0, 0.0, 0.0]]), ["beta_hat with shape (1, 3)", "(2, 2)"]),
    (dict(lam=5.0, k_s=[1.0, 2.0, 3.0]), ["k_s with shape (3,)", "(2,)"]),
    (dict(lam=5.0, u_max=-1.0), ["u_max", "expected values > 0"]),
]
# fl has no boundary layer and no switching gain: those two cases do not apply to it.
BAD_GAIN_CASES = [(kind, kw, fragments) for kind in ("smc", "ismc", "fl", "adaptive")
                  for kw, fragments in BAD_GAINS if not (kind == "fl" and ("delta" in kw or "k_s" in kw))]


@pytest.mark.parametrize("kind, kw, fragments", BAD_GAIN_CASES)
def test_bad_gains_are_rejected_before_the_law_runs(kind, kw, fragments):
    """The gains become runtime inputs of the emitted law: the runtime still validates them."""
    m = fjm_runtime.load("planar2")
    kw = dict(kw)
    if kind in ("smc", "fl") and "c" in kw and len(kw["c"]) == 4:  # the paper's surface has 3 coefficients
        kw["c"] = [1.0, 5.0, 0.1]
    with pytest.raises(ValueError) as info:
        make_controller(kind, m, {}, **kw)
    assert all(f in str(info.value) for f in fragments), str(info.value)


def test_gains_vector_follows_the_manifest_layout():
    """Every named gain lands at the offset the generated header and manifest document."""
    m = fjm_runtime.load("planar2")
    bh = np.array([[0.3, 0.1], [0.1, 0.2]])
    ctrl = make_controller("adaptive", m, {}, lam=4.0, k_s=[7.0, 8.0], delta=[0.5, 0.25], beta_hat=bh,
                           u_max=[30.0, 40.0], K_bounds=(90.0, 210.0), filter_rate=15.0)
    g = ctrl.gains
    layout = {b["name"]: b for b in m.manifest["controls"]["adaptive"]["gains"]}
    at = lambda name: g[layout[name]["offset"]:layout[name]["offset"] + layout[name]["size"]]  # noqa: E731
    np.testing.assert_array_equal(at("c"), [4.0 ** 4, 4 * 4.0 ** 3, 6 * 4.0 ** 2, 4 * 4.0])
    np.testing.assert_array_equal(at("k_s"), [7.0, 8.0])
    np.testing.assert_array_equal(at("delta"), [0.5, 0.25])
    np.testing.assert_array_equal(at("u_max"), [30.0, 40.0])
    np.testing.assert_array_equal(at("beta_hat"), bh.ravel(order="F"))
    np.testing.assert_array_equal(at("K_min"), [90.0, 90.0])
    np.testing.assert_array_equal(at("K_max"), [210.0, 210.0])
    assert at("limit")[0] == 1.0 and at("use_beta_hat")[0] == 1.0 and at("sign")[0] == 0.0
    assert at("filter_rate")[0] == 15.0 and g.size == sum(b["size"] for b in layout.values())
    assert "control_adaptive: " in (m.directory / f"{m.name}.h").read_text()
