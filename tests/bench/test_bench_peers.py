"""The bench's peers compute the same numbers as the generated code (so the timings compare like with like);
the bench fails when one does not; its README tables are the report of the committed results.

Small sizes only; the timings themselves live in `make bench`, never in tests.
"""
import json
import shutil

import numpy as np
import pytest

import fjm_runtime


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
        y_hat, a1, b1 = (np.asarray(v) for v in fns["core"](x, p))   # the one-call form: same numbers, and T
        assert np.allclose(y_hat.ravel(), m.T(x, p), rtol=1e-9, atol=1e-9 * max(1.0, np.max(np.abs(y_hat))))
        assert np.allclose(a1.ravel(), a, rtol=1e-12, atol=1e-12 * max(1.0, np.max(np.abs(a))))
        assert np.allclose(b1, b, rtol=1e-12, atol=1e-12)


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


@pytest.mark.parametrize("one_call", [False, True], ids=["two_calls", "one_call"])
@pytest.mark.parametrize("name", ["link1", "planar2"])
def test_compiled_alpha_beta_drivers_agree(tmp_path, name, one_call):
    """Both forms the bench times, alpha then beta, and one call of a core (the generated control_core, the
    peer's core Function), return alpha and beta and time the loop they claim."""
    from bench.alpha_beta import build_generated, build_peer
    m = fjm_runtime.load(name)
    x = np.random.default_rng(5).normal(scale=0.5, size=m.nx)
    p = m.params_array()
    gen = build_generated(m, tmp_path, one_call=one_call)
    peer, _, _ = build_peer(name, "structured", tmp_path, m.n, m.nx, one_call=one_call)
    iters = 11   # the timed loop perturbs x[0] by 1e-9 (k mod 8) on call k
    want = sum(float(m.alpha(xk, p)[0]) + float(m.beta(xk, p)[0, 0])
               for xk in (np.concatenate([[x[0] + 1e-9 * (k % 8)], x[1:]]) for k in range(iters)))
    for fn in (gen, peer):
        a, b = fn(x, p)
        assert np.allclose(a, m.alpha(x, p), rtol=1e-10, atol=1e-10)
        assert np.allclose(b, m.beta(x, p), rtol=1e-12, atol=1e-12)
        _, checksum = fn.timed_run(x, p, iters)     # the timed loop computes alpha and beta
        assert checksum == pytest.approx(want, rel=1e-10, abs=1e-12)


def _generated(case):
    """The sample step (one substep, ideal sensor, no delay) in C: ``(W (N, nw), AUX (N, 6n))``."""
    from fjm_runtime.sim.compiled import sampled_loop_library
    lib = sampled_loop_library(case.model, case.controller, case.layout())
    return lib(case.w0(), case.reference_rows(), case.noise(), case.p_true)


def test_hand_c_loop_equals_generated_loop(tmp_path):
    from bench.closed_loop import GeneratedLoop, HandLoop, link1_case
    case = link1_case(K_true=130.0, duration=1.0)
    hand = HandLoop(case, tmp_path)
    W_h, A_h = hand()
    W_g, A_g = _generated(case)
    assert W_g.shape == W_h.shape == (1000, 4)   # w = x: the stateless law, ideal sensor, no delay
    assert np.max(np.abs(W_h - W_g)) < 1e-9
    assert np.max(np.abs(A_h - A_g)) < 1e-9 * max(1.0, np.max(np.abs(A_g)))
    W_m, A_m = GeneratedLoop(case)()          # the mapaccum + casadi.external form
    assert np.max(np.abs(W_m - W_g)) < 1e-12
    # the peer is not trivially equal: another plant (K) moves the states by far more than the tolerance
    W_o, _ = HandLoop(link1_case(K_true=180.0, duration=1.0), tmp_path / "other")()
    assert np.max(np.abs(W_o - W_g)) > 1e-4


def test_python_and_solve_ivp_peers_track_the_same_loop():
    from bench.closed_loop import link1_case, python_loop, simulate_call, solve_ivp_loop
    case = link1_case(duration=0.3)
    W, _ = _generated(case)
    assert np.max(np.abs(python_loop(case).x[1:] - W)) < 1e-9
    assert np.max(np.abs(simulate_call(case, "compiled").x[1:] - W)) < 1e-12
    ivp = solve_ivp_loop(case)
    assert ivp.success
    assert np.max(np.abs(ivp.y.T[1:] - W)) < 5e-3   # continuous law vs zero-order hold


def test_numpy_batch_peer_equals_simulate_batch():
    """The NumPy peer (one RK4 step per sample, closed forms) == the sampled batch with substeps=1, row by row:
    the metrics, the final states, the per-joint figures and the divergence check (K = 4e7 N m/rad makes RK4 at
    1 ms unstable: that run is frozen at its last good state in both, at the same time)."""
    from bench.closed_loop import PEER_INTERFACE, link1_case
    from bench.numpy_batch import JOINT_PEER_FIGURES, numpy_batch
    from fjm_runtime.batch.runner import METRIC_NAMES, simulate_batch
    case = link1_case(duration=1.0)
    Ks = np.array([100.0, 140.0, 200.0, 4e7])
    P = np.tile(case.p_true, (4, 1))
    P[:, 2] = Ks
    b = simulate_batch(case.model, case.controller, case.reference, P, duration=1.0, x0=case.x0(), substeps=1,
                       interface=PEER_INTERFACE)
    nb = numpy_batch(case, Ks)
    assert list(b.diverged) == list(nb["diverged"]) == [False, False, False, True]
    assert np.array_equal(b.divergence_time, nb["divergence_time"], equal_nan=True)
    for k in METRIC_NAMES:
        assert np.allclose(b.metrics[k], nb[k], rtol=1e-9, atol=1e-12, equal_nan=True), k
    for k in JOINT_PEER_FIGURES:
        assert np.allclose(b.joint_metrics[k], nb["joint_metrics"][k], rtol=1e-9, atol=1e-12, equal_nan=True), k
    assert np.allclose(b.x_final, nb["x_final"], rtol=1e-9, atol=1e-12)
    assert len(set(np.round(b.x_final[:3, 0], 9))) == 3        # three different plants
    assert np.all(np.isfinite(nb["x_final"])) and np.max(np.abs(b.joint_metrics["torque_jitter"][:3])) > 0


def test_closed_loop_design_is_computed_not_pasted(monkeypatch):
    """k_s, delta, beta_hat come from Lemma 1 in the run: change its margin and they follow."""
    import bench.closed_loop as figures
    from bench.closed_loop import link1_case
    from fjm_runtime.control.laws import coefficients_from_pole
    from fjm_runtime.analysis.certificates.lemma1 import beta_bounds_link1, lemma1_gain
    ref, E, _ = figures.TASKS["tracking"]
    gain = lemma1_gain(coefficients_from_pole(figures.LAM), ref().derivative_bounds()[:, 0],
                       nominal={"K": figures.K_NOM}, bounds=figures.K_BOUNDS, error_bounds=E, eta=figures.ETA)
    ctrl = link1_case(duration=0.1).controller
    assert float(ctrl.k_s[0]) == pytest.approx(gain.k_s, rel=1e-12)
    assert float(ctrl.delta[0]) == pytest.approx(gain.k_s / figures.LAYER_RATE, rel=1e-12)
    assert float(ctrl.beta_hat[0, 0]) == pytest.approx(
        beta_bounds_link1({"K": figures.K_NOM}, figures.K_BOUNDS)[2], rel=1e-12)
    monkeypatch.setattr(figures, "ETA", figures.ETA + 7.0)
    assert float(link1_case(duration=0.1).controller.k_s[0]) == pytest.approx(gain.k_s + 7.0, rel=1e-12)


# -- the bench fails when a peer disagrees ------------------------------------------------------

def test_check_records_and_fails_beyond_tolerance():
    from bench.checks import check, metric_diff
    checks = []
    check(checks, "a", "within", 1e-12, 1e-9)
    check(checks, "b", "beyond", 2e-9, 1e-9)
    check(checks, "c", "nan", float("nan"), 1e-9)
    assert [c["ok"] for c in checks] == [True, False, False]
    a = {"m": np.array([1.0, np.inf, 2.0])}
    assert metric_diff(a, {"m": np.array([1.0, np.inf, 2.0 + 2e-9])}, ["m"]) == pytest.approx(1e-9, rel=1e-6)
    assert metric_diff(a, {"m": np.array([1.0, 5.0, 2.0])}, ["m"]) == np.inf   # inf vs finite


@pytest.mark.parametrize("measured,status", [(0.0, 0), (1.0, 1)])
def test_bench_exit_status_follows_the_peer_checks(tmp_path, monkeypatch, measured, status):
    import bench.__main__ as bm
    import bench.sections as sections
    from bench.checks import check

    def fake_batch(reps, slow, checks, n_runs=1000):
        check(checks, "batch.fake", "a peer vs the generated code", measured, 0.5)
        return {"n": 1}

    monkeypatch.setattr(sections, "bench_batch", fake_batch)
    monkeypatch.setattr(bm.report, "write_all", lambda r: pytest.fail("a partial run rewrote the READMEs"))
    out = tmp_path / "r.json"
    assert bm.main(["--only", "batch", "--out", str(out)]) == status
    res = json.loads(out.read_text())
    assert [c["ok"] for c in res["checks"]] == [not status]


def test_differing_files_finds_one_changed_byte(tmp_path):
    from bench.generated_tree import differing_files
    from fjm_runtime.model import generated_root
    src = generated_root()
    a, b = tmp_path / "a", tmp_path / "b"
    shutil.copytree(src / "link1", a / "link1")
    shutil.copytree(src / "link1", b / "link1")
    assert differing_files(a, b, ["link1"]) == []
    c = b / "link1" / "link1.c"
    text = c.read_bytes()
    i = text.index(b"9.8") if b"9.8" in text else text.rindex(b"1.")
    c.write_bytes(text[:i] + b"8" + text[i + 1:])
    assert differing_files(a, b, ["link1"]) == ["link1/link1.c"]
    (b / "link1" / "alpha.casadi").unlink()
    assert differing_files(a, b, ["link1"]) == ["link1/alpha.casadi", "link1/link1.c"]


# -- the README tables are the report of the committed results --------------------------------

def test_readme_tables_equal_the_report_of_the_committed_results():
    from bench import report
    from bench.result_values import get, load
    r = load()
    assert r.get("quick") is False and r.get("checks"), "bench/results.json must come from a full run"
    assert all(c["ok"] for c in r["checks"])
    for path, block in report.targets(r).items():
        assert report.current_block(path.read_text()) == block, f"{path}: run python -m bench.report"
    assert report.main(["--check"]) == 0


def test_report_uses_the_results_and_flags_missed_targets():
    from bench import report
    from bench.result_values import get, load
    r = load()
    block = report.render_readme(r)
    speed = get(r, "closed_loop.speedup_vs_python")
    assert f"{speed:.0f}x faster" in block
    worse = json.loads(json.dumps(r))
    worse["batch"]["speedup_vs_numpy"] = 1.5
    worse["checks"][0]["ok"] = False
    text = report.render_readme(worse)
    assert "1.5x faster" in text and "**missed**" in text and "peer checks failed" in text
    with pytest.raises(ValueError, match="bench:begin"):
        report.replace_block("no markers here", block)
    doc = f"a\n{report.BEGIN}\nold\n{report.END}\nb\n"
    assert report.current_block(report.replace_block(doc, block)) == block
