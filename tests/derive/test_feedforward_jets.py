"""The inverse dynamics and its first two time derivatives along a reference (derive/emit/dynamics.py
``inverse_dynamics_jets``), the input of the flatness feedforward, against independent references.

* finite differences (fourth-order central stencils) of ``tau(q(t), q'(t), q''(t))`` along the quartic
  joint trajectory ``q(t) = q + dq t + a t^2/2 + da t^3/6 + dda t^4/24``: ``tau`` by the model's own
  programme ``D a + h``, no derivative rule in it, to 1e-6 relative;
* the three routes (Taylor recursion of the RNEA for spatial chains and trees, SymPy time derivatives for the
  closed-form planar chains, forward-mode AD of the programme) agree to 1e-12 relative.
"""

from __future__ import annotations

import numpy as np
import pytest

from derive.emit.dynamics import inverse_dynamics, inverse_dynamics_jets
from derive.registry import build

#: (model, routes compared with "ad"): the emitted route first.
CASES = (("planar3", ("symbolic",)), ("link1_hd", ("symbolic",)), ("panda", ("jets",)), ("baxter", ("jets",)))


def _rel(a, b) -> float:
    a, b = np.asarray(a, float).ravel(), np.asarray(b, float).ravel()
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b))))


def _point(m, seed: int):
    rng = np.random.default_rng(seed)
    jets = [rng.uniform(-1, 1, m.n) for _ in range(5)]
    p = np.array([prm.default for prm in m.params])
    return jets, p


@pytest.mark.parametrize("name,routes", CASES)
def test_jets_are_the_time_derivatives(name, routes):
    """dtau and ddtau equal finite differences of tau along the trajectory whose jets are (q, dq, a, da, dda)."""
    m = build(name)
    (q, dq, a, da, dda), p = _point(m, 5)
    tau = inverse_dynamics(m)

    def along(t):  # the programme at q(t), q'(t), q''(t)
        qt = q + dq * t + a * t ** 2 / 2 + da * t ** 3 / 6 + dda * t ** 4 / 24
        dqt = dq + a * t + da * t ** 2 / 2 + dda * t ** 3 / 6
        at = a + da * t + dda * t ** 2 / 2
        return tau(qt, dqt, at, p).full().ravel()

    h = 1e-3
    f = {k: along(k * h) for k in (-2, -1, 0, 1, 2)}
    first = (f[-2] - 8 * f[-1] + 8 * f[1] - f[2]) / (12 * h)
    second = (-f[-2] + 16 * f[-1] - 30 * f[0] + 16 * f[1] - f[2]) / (12 * h * h)
    for route in ("ad",) + routes:
        t0, t1, t2 = (v.full().ravel() for v in inverse_dynamics_jets(m, route)(q, dq, a, da, dda, p))
        assert _rel(t0, f[0]) <= 1e-12, route
        assert _rel(t1, first) <= 1e-6, (route, _rel(t1, first))
        assert _rel(t2, second) <= 1e-6, (route, _rel(t2, second))


@pytest.mark.parametrize("name,routes", CASES)
def test_routes_agree(name, routes):
    """The emitted route equals forward-mode AD of the programme to rounding, and is the default."""
    m = build(name)
    (q, dq, a, da, dda), p = _point(m, 11)
    ref = [v.full() for v in inverse_dynamics_jets(m, "ad")(q, dq, a, da, dda, p)]
    for route in routes:
        got = [v.full() for v in inverse_dynamics_jets(m, route)(q, dq, a, da, dda, p)]
        assert max(_rel(g, r) for g, r in zip(got, ref)) <= 1e-12, route
    default = [v.full() for v in inverse_dynamics_jets(m)(q, dq, a, da, dda, p)]
    emitted = [v.full() for v in inverse_dynamics_jets(m, routes[0])(q, dq, a, da, dda, p)]
    assert all(np.array_equal(d, e) for d, e in zip(default, emitted))


def test_unknown_route_is_refused():
    with pytest.raises(ValueError, match="route = 'rnea'"):
        inverse_dynamics_jets(build("link1"), "rnea")
