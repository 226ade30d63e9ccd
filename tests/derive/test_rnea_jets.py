"""The Taylor recursion of the RNEA (derive/emit/rnea_jets.py) against three independent references.

* its ``tau^(0)`` is the model's RNEA programme ``D a + h`` (itself checked against Pinocchio in
  test_ad_route), to 1e-12;
* its ``tau^(1)``, ``tau^(2)`` are finite differences (fourth-order stencils) of Pinocchio's
  ``rnea`` along the polynomial joint trajectory ``q(t) = q + dq t + a t^2/2 + a_rate t^3/6``
  (Panda), or of our programme (Baxter's tree, a payload, symbolic inertials), to 1e-7;
* they equal forward-mode AD of the programme (:func:`derive.emit.dynamics.time_derivatives`)
  to 1e-12, and the kernel built on them equals the kernel of the AD route.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from derive.emit.dynamics import _body_numbers, _converter, _kernel, build_kernel, inverse_dynamics, time_derivatives
from derive.emit.rnea_jets import rnea_jets
from derive.model_file import load_model_file
from derive.registry import build
from derive.guard.synthetic import write_synthetic_chain


def _jets_function(m) -> ca.Function:
    """``(q, dq, a, a_rate, p) -> (tau^(0), tau^(1), tau^(2))`` of the recursion."""
    n = m.n
    q, dq, a, ar = (ca.SX.sym(s, n) for s in ("q", "dq", "a", "ar"))
    p = ca.SX.sym("p", len(m.params))
    bodies = _body_numbers(m, _converter(m, q, dq, p))
    g0 = p[list(m.param_names).index("g0")]
    return ca.Function("jets", [q, dq, a, ar, p], rnea_jets(bodies, q, [dq, a, ar], g0, 2))


def _rel(a, b) -> float:
    a, b = np.asarray(a, float).ravel(), np.asarray(b, float).ravel()
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b))))


def _along(tau, q, dq, a, ar, step):
    """Fourth-order central differences of ``t -> tau(q(t), dq(t), a(t))``: (first, second) derivative."""
    def at(t):
        return np.asarray(tau(q + dq * t + a * t ** 2 / 2 + ar * t ** 3 / 6, dq + a * t + ar * t ** 2 / 2, a + ar * t),
                          float).ravel()
    f = {k: at(k * step) for k in (-2, -1, 0, 1, 2)}
    first = (-f[2] + 8 * f[1] - 8 * f[-1] + f[-2]) / (12 * step)
    second = (-f[2] + 16 * f[1] - 30 * f[0] + 16 * f[-1] - f[-2]) / (12 * step ** 2)
    return first, second


def _chain_with_symbolic_link(tmp_path):
    toml, _ = write_synthetic_chain(5, tmp_path)
    toml.write_text(toml.read_text().replace('tip = "link5"', 'tip = "link5"\nsymbolic = ["link3"]'))
    return load_model_file(toml).build()


def _params(m, rng):
    p = np.array([pp.default for pp in m.params]) * rng.uniform(0.7, 1.3, len(m.params))
    names = list(m.param_names)
    if "m_load" in names:  # a payload of 1.5 kg off the flange axis
        for key, value in (("m_load", 1.5), ("x_load", 0.03), ("y_load", -0.02), ("z_load", 0.08)):
            p[names.index(key)] = value
    return p


def _models(tmp_path):
    return [build("panda"), build("baxter"), build("elbow3"), _chain_with_symbolic_link(tmp_path)]


def test_spatial_reduced_models_take_the_jets_route_and_others_not():
    assert build("panda").bodies is not None and len(build("baxter").bodies) == 15
    assert build("planar3").bodies is None and build("panda_complete").bodies is None


def test_jets_equal_forward_mode_ad_and_the_programme(tmp_path):
    rng = np.random.default_rng(23)
    for m in _models(tmp_path):
        n = m.n
        jets, tau = _jets_function(m), inverse_dynamics(m)
        d1, d2 = time_derivatives(m)
        for _ in range(5):
            q, dq = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n)
            a, ar = rng.uniform(-5, 5, n), rng.uniform(-20, 20, n)
            p = _params(m, rng)
            t0, t1, t2 = jets(q, dq, a, ar, p)
            z = np.concatenate([q, dq, a])
            assert _rel(t0, tau(q, dq, a, p)) <= 1e-12, m.name
            # tau^(1) is linear in a_rate; d1 and d2 of the programme along z' = [dq; a; a_rate]
            assert _rel(t1, d1(z, np.concatenate([dq, a, ar]), p)) <= 1e-12, m.name
            ad2 = d2(z, np.concatenate([dq, a, ar]), np.concatenate([a, ar, np.zeros(n)]), p)
            assert _rel(t2, ad2) <= 1e-12, m.name


def test_jets_equal_finite_differences_of_pinocchio_rnea_on_the_panda():
    import pinocchio as pin
    from support.paths import REPO
    m = build("panda")
    model = pin.buildModelFromUrdf(str(REPO / m.source["urdf"]))
    assert [model.names[j] for j in range(1, model.njoints)] == list(m.source["joints"])
    data = model.createData()
    rng = np.random.default_rng(29)
    p = np.array([pp.default for pp in m.params])
    model.gravity.linear[:] = [0.0, 0.0, -p[list(m.param_names).index("g0")]]
    jets = _jets_function(m)

    def rnea(q, dq, a):
        return pin.rnea(model, data, q, dq, a)

    for _ in range(4):
        q, dq = rng.uniform(-2, 2, 7), rng.uniform(-1.5, 1.5, 7)
        a, ar = rng.uniform(-5, 5, 7), rng.uniform(-20, 20, 7)
        _, t1, t2 = jets(q, dq, a, ar, p)
        first, second = _along(rnea, q, dq, a, ar, 1e-3)
        assert _rel(t1, first) <= 1e-7 and _rel(t2, second) <= 1e-7


@pytest.mark.exhaustive  # ~7 s: .ci/run runs it after make test (make test stays under 5 minutes)
def test_jets_equal_finite_differences_on_a_tree_a_payload_and_symbolic_inertials(tmp_path):
    rng = np.random.default_rng(31)
    for m in (build("baxter"), build("panda"), _chain_with_symbolic_link(tmp_path)):
        n, jets, tau = m.n, _jets_function(m), inverse_dynamics(m)
        q, dq = rng.uniform(-2, 2, n), rng.uniform(-1.5, 1.5, n)
        a, ar = rng.uniform(-5, 5, n), rng.uniform(-20, 20, n)
        p = _params(m, rng)
        _, t1, t2 = jets(q, dq, a, ar, p)
        first, second = _along(lambda q_, dq_, a_: tau(q_, dq_, a_, p), q, dq, a, ar, 1e-3)
        assert _rel(t1, first) <= 1e-7 and _rel(t2, second) <= 1e-7, m.name


@pytest.mark.parametrize("name", ["panda", pytest.param("baxter", marks=pytest.mark.exhaustive)])  # baxter ~6 s
def test_kernel_on_the_jets_equals_the_kernel_by_ad(name):
    m = build(name)
    jets, ad = build_kernel(m), _kernel(m, "ad")
    rng = np.random.default_rng(37)
    for _ in range(5):
        args = [rng.uniform(-2, 2, m.n) for _ in range(2)] + [rng.uniform(-50, 50, m.n) for _ in range(2)]
        args.append(_params(m, rng))
        for a, b in zip(jets(*args), ad(*args)):
            assert _rel(a, b) <= 1e-11


def test_order_out_of_range_is_refused():
    with pytest.raises(ValueError, match=r"order = 3; expected 0, 1 or 2"):
        rnea_jets([], [], [], 9.81, 3)


def _documented_kernel_operations() -> dict:
    """``model -> (Taylor recursion, AD)`` from docs/derivation.md's table of kernel operations."""
    from support.paths import REPO
    rows = {}
    for line in (REPO / "docs" / "derivation.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 3 and cells[1].isdigit() and cells[2].isdigit():
            rows[cells[0].split(" ")[0]] = (int(cells[1]), int(cells[2]))
    return rows


@pytest.mark.parametrize("name", ["elbow3", "panda", pytest.param("baxter", marks=pytest.mark.exhaustive)])
def test_documented_kernel_operations_are_the_routes_counts(name):
    from derive.emit.functions import operation_count
    m = build(name)
    documented = _documented_kernel_operations()[{"elbow3": "elbow3", "panda": "Panda", "baxter": "Baxter"}[name]]
    assert documented == (operation_count(build_kernel(m)), operation_count(_kernel(m, "ad")))
