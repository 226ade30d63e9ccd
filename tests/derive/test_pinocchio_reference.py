"""The generated models against references that share no code with ``derive/``.

The planar chains are rebuilt from their physical description only
(``tests/support/independent_chain.py``): once with Pinocchio's model-building API
(``crba``, ``rnea``, ``aba``), once as CasADi SX dynamics from link kinematics
with every Lie derivative and bracket by CasADi AD. ``link1`` is checked as
``planar1`` with ``J_l = I1 + m1 r1^2``, ``M = m1``, ``L = r1``.

Parameters are drawn over wide physical ranges (a new draw for every state)
and angles over the whole circle, so a wrong coupling, centre-of-mass or
gravity term in the derivation cannot hide behind the defaults.
"""

from __future__ import annotations

import numpy as np
import pytest

import fjm_runtime
from support.independent_chain import (PinocchioReference, casadi_reference, evaluate,
                                random_chain_params, random_chain_state)

MODELS = ("link1",) + tuple(f"planar{n}" for n in range(1, 8))
N_STATES = 50
TOL = 1e-10


def _links(name: str) -> int:
    return 1 if name == "link1" else int(name[len("planar"):])


def _model_params(name: str, p: dict) -> dict:
    """The chain parameters ``p`` in the generated model's own names."""
    if name != "link1":
        return p
    return {"J_l": p["I1"] + p["m1"] * p["r1"] ** 2, "J_m": p["Jm1"], "K": p["K1"], "M": p["m1"],
            "g0": p["g0"], "L": p["r1"], "B_m": p["Bm1"]}


def _cases(name: str, count: int, seed: int):
    """``count`` (state, chain parameters, model parameters) triples, reproducible per model."""
    rng = np.random.default_rng([seed, sum(map(ord, name))])
    n = _links(name)
    for _ in range(count):
        p = random_chain_params(n, rng)
        yield random_chain_state(n, rng), p, _model_params(name, p)


def _rel(got, want) -> float:
    got, want = np.asarray(got, float), np.asarray(want, float).reshape(np.shape(got))
    return float(np.linalg.norm(got - want) / max(np.linalg.norm(want), 1e-300))


@pytest.mark.parametrize("name", MODELS)
def test_inertia_matrix_equals_crba(name):
    """``D(q)`` (``m.inertia``) == Pinocchio's composite rigid body algorithm."""
    m, n = fjm_runtime.load(name), _links(name)
    worst = 0.0
    for x, p, pm in _cases(name, N_STATES, 1):
        err = _rel(m.inertia(x, pm), PinocchioReference(p, n).inertia(x[:n]))
        worst = max(worst, err)
        assert err <= TOL, (name, x, p, err)
    print(f"{name}: max relative error of D vs crba {worst:.1e}")


@pytest.mark.parametrize("name", MODELS)
def test_coriolis_gravity_equals_rnea(name):
    """``h = C dq + G`` read off the generated ``f`` == ``rnea(q, dq, 0)``.

    The generated link acceleration satisfies ``D ddq = -(h + K (q - q_m))``, so
    ``h = -D ddq - K (q - q_m)`` with the stiffness taken from the parameters.
    """
    m, n = fjm_runtime.load(name), _links(name)
    worst = 0.0
    for x, p, pm in _cases(name, N_STATES, 2):
        q, dq, qm = x[:n], x[n:2 * n], x[2 * n:3 * n]
        K = np.array([p[f"K{i + 1}"] for i in range(n)])
        h = -m.inertia(x, pm) @ m.f(x, pm)[n:2 * n] - K * (q - qm)
        err = _rel(h, PinocchioReference(p, n).bias(q, dq))
        worst = max(worst, err)
        assert err <= TOL, (name, x, p, err)
    print(f"{name}: max relative error of h vs rnea {worst:.1e}")


@pytest.mark.parametrize("name", MODELS)
def test_drift_equals_aba_and_motor_equation(name):
    """Link rows of ``f`` == ``aba(q, dq, K (q_m - q))``; motor rows == ``J_m^-1 (K (q - q_m) - B_m dq_m)``."""
    m, n = fjm_runtime.load(name), _links(name)
    worst = [0.0, 0.0]
    for x, p, pm in _cases(name, N_STATES, 3):
        q, dq, qm, dqm = (x[k * n:(k + 1) * n] for k in range(4))
        K, Jm, Bm = (np.array([p[f"{g}{i + 1}"] for i in range(n)]) for g in ("K", "Jm", "Bm"))
        f = m.f(x, pm)
        errs = [_rel(f[n:2 * n], PinocchioReference(p, n).link_accel(q, dq, K * (qm - q))),
                _rel(f[3 * n:], (K * (q - qm) - Bm * dqm) / Jm)]
        worst = list(map(max, worst, errs))
        assert max(errs) <= TOL, (name, x, p, errs)
        np.testing.assert_array_equal(f[:n], dq)
        np.testing.assert_array_equal(f[2 * n:3 * n], dqm)
    print(f"{name}: max relative error of link / motor accelerations {worst[0]:.1e} / {worst[1]:.1e}")


@pytest.mark.parametrize("name", MODELS)
def test_energy_equals_pinocchio(name):
    """``m.energy`` == Pinocchio's kinetic + potential energy of the links + motors + springs."""
    m, n = fjm_runtime.load(name), _links(name)
    for x, p, pm in _cases(name, N_STATES, 4):
        want = PinocchioReference(p, n).energy(x)
        assert abs(m.energy(x, pm) - want) <= TOL * max(abs(want), 1.0), (name, x, p)


@pytest.mark.parametrize("n", [1, 2, 3, 5, 7])
def test_the_two_references_agree(n):
    """Pinocchio and the SX chain are two independent readings of the same description."""
    F = casadi_reference(n)
    rng = np.random.default_rng(n)
    for _ in range(10):
        p, x = random_chain_params(n, rng), random_chain_state(n, rng)
        ref = PinocchioReference(p, n)
        q, dq = x[:n], x[n:2 * n]
        assert _rel(evaluate(F["inertia"], x, p, n), ref.inertia(q)) <= TOL
        assert _rel(evaluate(F["h"], x, p, n).ravel(), ref.bias(q, dq)) <= TOL
        assert _rel(evaluate(F["f"], x, p, n).ravel(), ref.f(x)) <= TOL
        assert _rel(evaluate(F["energy"], x, p, n), ref.energy(x)) <= TOL


#: (model, states). The two sides reach the brackets by different roads (the
#: generated code differentiates ``D y3 = r3`` implicitly, the reference
#: differentiates a Cholesky solve with ``D`` by AD), so they round differently.
#: Over 150 random draws per model the largest relative difference was
#: 6e-14 (planar3), 6e-12 (planar4) and 3e-10 (planar7, alpha, where
#: ``-beta a`` cancels); f, T, beta and ad stayed below 1e-12. Hence 1e-9.
LIE_CASES = [("link1", 20), ("planar1", 20), ("planar2", 20), ("planar3", 30), ("planar4", 30),
             ("planar7", 12)]
LIE_TOL = 1e-9


@pytest.mark.parametrize("name,count", LIE_CASES)
def test_linearization_and_brackets_equal_independent_casadi(name, count):
    """``T``, ``alpha``, ``beta``, ``ad`` (and ``f``, ``g``) == the independent CasADi SX chain."""
    m, n = fjm_runtime.load(name), _links(name)
    F = casadi_reference(n)
    worst = {}
    for x, p, pm in _cases(name, count, 5):
        for k in ("f", "g", "T", "alpha", "beta", "ad"):
            err = _rel(getattr(m, k)(x, pm), evaluate(F[k], x, p, n))
            worst[k] = max(worst.get(k, 0.0), err)
            assert err <= LIE_TOL, (name, k, x, p, err)
    print(name, {k: f"{v:.1e}" for k, v in worst.items()})
