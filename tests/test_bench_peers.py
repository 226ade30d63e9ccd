"""The bench's peers compute the same numbers as the generated code (so the timings compare like with like).

Small sizes only; the timings themselves live in `make bench`, never in tests.
"""
import numpy as np
import pytest

import fjm_runtime

pytest.importorskip("sympy")

import os as _os
import shutil as _shutil

pytestmark = pytest.mark.skipif(not (_os.environ.get("CC") or _shutil.which("gcc") or _shutil.which("cc")),
                                reason="needs a C compiler")


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("FJM_CACHE", str(tmp_path / "cache"))


@pytest.mark.parametrize("name", ["link1", "planar2", "planar3"])
@pytest.mark.parametrize("variant", ["structured", "generic"])
def test_ad_peer_alpha_beta_equal_generated(name, variant):
    from bench.peers import peer_functions
    m = fjm_runtime.load(name)
    fns = peer_functions(name, variant)
    rng = np.random.default_rng(3)
    for _ in range(3):
        x = rng.normal(scale=0.7, size=m.nx)
        p = m.params_array() * rng.uniform(0.8, 1.2, size=len(m.param_names))
        a = np.asarray(fns["alpha"](x, p)).ravel()
        b = np.asarray(fns["beta"](x, p))
        assert np.allclose(a, m.alpha(x, p), rtol=1e-9, atol=1e-9 * max(1.0, np.max(np.abs(a))))
        assert np.allclose(b, m.beta(x, p), rtol=1e-12, atol=1e-12)


def test_ad_peer_y3_y4_equal_generated_T():
    from bench.peers import peer_expressions
    import casadi as ca
    m = fjm_runtime.load("planar2")
    x, p, e = peer_expressions("planar2")
    f = ca.Function("y34", [x, p], [e["y3"], e["y4"]])
    xv = np.random.default_rng(4).normal(size=m.nx)
    pv = m.params_array()
    y3, y4 = (np.asarray(v).ravel() for v in f(xv, pv))
    T = m.T(xv, pv).reshape(4, 2)
    assert np.allclose(y3, T[2], rtol=1e-12, atol=1e-12)
    assert np.allclose(y4, T[3], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", ["link1", "planar2"])
def test_compiled_alpha_beta_drivers_agree(tmp_path, name):
    from bench.alpha_beta import build_generated, build_peer
    m = fjm_runtime.load(name)
    x = np.random.default_rng(5).normal(scale=0.5, size=m.nx)
    p = m.params_array()
    gen = build_generated(m, tmp_path)
    peer, _, _ = build_peer(name, "structured", tmp_path, m.n, m.nx)
    for fn in (gen, peer):
        a, b = fn(x, p)
        assert np.allclose(a, m.alpha(x, p), rtol=1e-10, atol=1e-10)
        assert np.allclose(b, m.beta(x, p), rtol=1e-12, atol=1e-12)
    assert gen.seconds_per_call(x, p, 10) > 0 and peer.seconds_per_call(x, p, 10) > 0


def test_hand_c_loop_equals_generated_loop(tmp_path):
    from bench.closed_loop import GeneratedLoop, HandLoop, link1_case
    from fjm_runtime.compiled import closed_loop_library
    case = link1_case(K_true=130.0, duration=1.0)
    hand = HandLoop(case, tmp_path)
    W_h, A_h = hand()
    lib = closed_loop_library(case.model, case.controller, case.dt)
    W_g, A_g = lib(case.x0(), *case.reference_arrays(), case.p_true)
    assert np.max(np.abs(W_h - W_g)) < 1e-9
    assert np.max(np.abs(A_h - A_g)) < 1e-9 * max(1.0, np.max(np.abs(A_g)))
    W_m, A_m = GeneratedLoop(case)()          # the mapaccum + casadi.external form
    assert np.max(np.abs(W_m - W_g)) < 1e-12


def test_python_and_solve_ivp_peers_track_the_same_loop():
    from bench.closed_loop import link1_case, python_loop, solve_ivp_loop
    from fjm_runtime.compiled import closed_loop_library
    case = link1_case(duration=0.3)
    lib = closed_loop_library(case.model, case.controller, case.dt)
    W, _ = lib(case.x0(), *case.reference_arrays(), case.p_true)
    assert np.max(np.abs(python_loop(case).x[1:] - W)) < 1e-9
    pytest.importorskip("scipy")
    ivp = solve_ivp_loop(case)
    assert ivp.success
    assert np.max(np.abs(ivp.y.T[1:] - W)) < 5e-3   # continuous law vs zero-order hold


def test_numpy_batch_peer_equals_simulate_batch():
    from bench.closed_loop import link1_case, numpy_batch
    from fjm_runtime.batch import METRIC_NAMES, simulate_batch
    case = link1_case(duration=1.0)
    Ks = np.array([100.0, 140.0, 200.0])
    P = np.tile(case.p_true, (3, 1))
    P[:, 2] = Ks
    b = simulate_batch(case.model, case.controller, case.reference, P, duration=1.0, x0=case.x0())
    nb = numpy_batch(case, Ks)
    for k in METRIC_NAMES:
        assert np.allclose(b.metrics[k], nb[k], rtol=1e-9, atol=1e-12), k
    assert np.allclose(b.x_final, nb["x_final"], rtol=1e-9, atol=1e-12)
