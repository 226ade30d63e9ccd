"""simulate_batch (THE sampled loop, ideal sensor): a batch of one equals a single run; each row is its own plant;
the SIMD path runs where the CPU has it, equals the scalar path, and never fails silently; loop='legacy' is retired."""
import warnings

import numpy as np
import pytest

import fjm_runtime
import fjm_runtime.batch.sampled_runner as sampled_runner
import fjm_runtime.batch.simd as batch_mod
from fjm_runtime.batch.runner import METRIC_NAMES, SimdFallbackWarning, simulate_batch
from fjm_runtime.batch.sampled import GainInput, jitter_half_width, sampled_metric_step
from fjm_runtime.ccache import DEFAULT_FLAGS, CompileError
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import Sinusoid, SmoothStep
from fjm_runtime.sim.step_layout import make_layout
from fjm_runtime.sim.sensor import SensorModel
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.validation import FjmValueError


pytestmark = pytest.mark.slow  # builds C, a wheel or derives in a subprocess: `pytest -m 'not slow'` skips it

def _link1_ctrl(m, kind="smc", **kw):
    kw.setdefault("k_s", 1008.0)
    kw.setdefault("delta", 5.04)
    return make_controller(kind, m, {"K": 150.0}, lam=8.0, beta_hat=0.015, **kw)


def _assert_same_metrics(single, batch, i, rel=1e-9):
    for k in METRIC_NAMES:
        a, b = getattr(single.metrics, k), batch.metrics[k][i]
        assert b == pytest.approx(a, rel=rel, abs=1e-12), k


def _single(m, ctrl, ref, batch, i, duration, backend):
    """Row ``i`` of ``batch`` as one :func:`simulate` run: same TRUE parameters, substeps and seed."""
    return simulate(m, ctrl, ref, duration=duration, true_params=batch.params[i], substeps=batch.info["substeps"],
                    sensor=SensorModel.ideal().with_seed(int(batch.seeds[i])), backend=backend)


def test_batch_of_one_equals_single_run():
    m = fjm_runtime.load("link1")
    ctrl = _link1_ctrl(m)
    ref = Sinusoid(0.5, 1.0)
    batch = simulate_batch(m, ctrl, ref, m.params_array({"K": 120.0})[None], duration=0.5)
    single = _single(m, ctrl, ref, batch, 0, 0.5, "python")
    _assert_same_metrics(single, batch, 0)
    assert np.max(np.abs(batch.x_final[0] - single.x[-1])) < 1e-9
    assert not batch.diverged[0]


@pytest.mark.parametrize("parallel,simd", [(True, True), (True, False), (False, True), (False, False)])
def test_each_row_is_its_own_plant(parallel, simd):
    m = fjm_runtime.load("link1")
    ctrl = _link1_ctrl(m, kind="ismc", u_max=20.0)
    ref = SmoothStep(1.0, rise_time=0.5)
    Ks = [100.0, 150.0, 200.0, 130.0, 170.0]
    P = np.array([m.params_array({"K": k}) for k in Ks])
    with warnings.catch_warnings():
        warnings.simplefilter("error", SimdFallbackWarning)
        batch = simulate_batch(m, ctrl, ref, P, duration=1.0, parallel=parallel, simd=simd)
    assert (batch.info["path"] != "scalar") == simd
    assert batch.info["threads"] == 1 or parallel
    for i in range(len(Ks)):
        single = _single(m, ctrl, ref, batch, i, 1.0, "compiled")
        _assert_same_metrics(single, batch, i)
        assert np.max(np.abs(batch.x_final[i] - single.x[-1])) < 1e-9
    assert len(set(np.round(batch.metrics["rms_error"], 12))) == len(Ks)


def test_planar2_batch_matches_single():
    m = fjm_runtime.load("planar2")
    ctrl = make_controller("smc", m, {}, lam=8.0, k_s=100.0, delta=2.0)
    ref = Sinusoid(0.5, 1.0, n=2)
    P = np.array([m.params_array({"K1": 120.0}), m.params_array({"K2": 190.0})])
    batch = simulate_batch(m, ctrl, ref, P, duration=0.5)
    for i in range(2):
        _assert_same_metrics(_single(m, ctrl, ref, batch, i, 0.5, "casadi"), batch, i)


def test_divergence_is_flagged_not_raised():
    m = fjm_runtime.load("link1")
    ctrl = _link1_ctrl(m)
    P = np.array([m.params_array({"K": 150.0}), m.params_array({"K": 150.0, "J_m": 1e-6})])
    batch = simulate_batch(m, ctrl, Sinusoid(0.5, 1.0), P, duration=1.0, max_state=1e3, substeps=1)
    assert not batch.diverged[0] and np.isfinite(batch.metrics["rms_error"][0])
    assert batch.diverged[1] and np.isnan(batch.metrics["rms_error"][1])
    assert 0 < batch.divergence_time[1] <= 1.0


def test_bad_params_shape_is_a_clear_error():
    m = fjm_runtime.load("link1")
    with pytest.raises(ValueError, match="params_true_array"):
        simulate_batch(m, _link1_ctrl(m), Sinusoid(0.5, 1.0), np.zeros((3, 2)), duration=1.0)


@pytest.mark.parametrize("loop", ["legacy", "fused"])
def test_only_the_sampled_loop_is_accepted(loop):
    """loop='sampled' is the one loop: the retired 'legacy' and any other name are a one-line error."""
    m = fjm_runtime.load("link1")
    with pytest.raises(FjmValueError) as exc:
        simulate_batch(m, _link1_ctrl(m), Sinusoid(0.5, 1.0), m.params_array({})[None], duration=0.1, loop=loop)
    msg = str(exc.value)
    assert "\n" not in msg and f"loop = {loop!r}" in msg
    assert msg.endswith("expected 'sampled'")


def _expected_simd_path():
    """The SIMD path this CPU should get, from /proc/cpuinfo read here (not by the code under test)."""
    flags = set()
    with open("/proc/cpuinfo") as fh:
        for ln in fh:
            if ln.startswith("flags"):
                flags = set(ln.split(":", 1)[1].split())
                break
    if {"avx512f", "avx512dq"} <= flags:
        return "simd-avx512"
    if "avx2" in flags:
        return "simd-avx2"
    if "sse2" in flags:
        return "simd-sse2"
    return "simd-generic"


def _padded_case():
    """11 runs: not a multiple of the lane count, so the last SIMD group is padded."""
    m = fjm_runtime.load("link1")
    P = np.array([m.params_array({"K": k}) for k in np.linspace(100.0, 200.0, 11)])
    return m, _link1_ctrl(m), Sinusoid(0.5, 1.0), P


def test_simd_path_runs_where_the_cpu_supports_it():
    m, ctrl, ref, P = _padded_case()
    with warnings.catch_warnings():
        warnings.simplefilter("error", SimdFallbackWarning)   # a fallback fails this test
        b = simulate_batch(m, ctrl, ref, P, duration=0.2)
    assert b.info["path"] == _expected_simd_path()
    assert b.info["reason"] is None and b.info["lanes"] == 8


def test_simd_lanes_and_padding_agree_with_scalar():
    """Each path forced explicitly (and checked in ``info``), then compared."""
    m, ctrl, ref, P = _padded_case()
    a = simulate_batch(m, ctrl, ref, P, duration=0.5, simd=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SimdFallbackWarning)
        b = simulate_batch(m, ctrl, ref, P, duration=0.5, simd=True)
    assert a.info["path"] == "scalar" and a.info["lanes"] == 1
    assert b.info["path"] == _expected_simd_path() and b.info["lanes"] == 8
    assert a.info["library"] != b.info["library"]
    for k in METRIC_NAMES:
        assert np.allclose(a.metrics[k], b.metrics[k], rtol=1e-9, atol=1e-12), k
    assert np.allclose(a.x_final, b.x_final, rtol=1e-9, atol=1e-12)
    assert len(set(np.round(b.metrics["rms_error"], 12))) == P.shape[0]   # no lane copied another


def _raise_unsupported(*args, **kwargs):
    raise ValueError("soa_source: operation 999 not supported (injected)")


def _broken_c(*args, **kwargs):
    return "this is not C (injected);\n"


@pytest.mark.parametrize("broken,exc,match", [(_raise_unsupported, ValueError, "operation 999"),
                                              (_broken_c, CompileError, "CompileError")])
def test_a_failing_simd_build_warns_names_the_reason_and_runs_scalar(monkeypatch, broken, exc, match):
    m, ctrl, ref, P = _padded_case()
    monkeypatch.setattr(batch_mod, "soa_source", broken)
    monkeypatch.setattr(sampled_runner, "_RUNNERS", {})     # no runner built by an earlier test
    L = make_layout(m, GainInput(ctrl), 1e-3, 1, SensorModel.ideal(), 0, False)
    step, A = sampled_metric_step(m, GainInput(ctrl), L, 1e6, 2 * jitter_half_width(1e-3) + 1)
    with pytest.raises(exc):                       # the explicit builder never falls back
        batch_mod.sampled_simd_runner(step, A.n_par, L.nm, DEFAULT_FLAGS, None)
    with pytest.warns(SimdFallbackWarning, match=match):
        b = simulate_batch(m, ctrl, ref, P, duration=0.2)
    assert b.info["path"] == "scalar"
    assert "SIMD build failed" in b.info["reason"] and match in b.info["reason"]
    ref_b = simulate_batch(m, ctrl, ref, P, duration=0.2, simd=False)
    assert np.array_equal(b.metrics["rms_error"], ref_b.metrics["rms_error"])


def test_a_step_beyond_the_simd_limit_warns(monkeypatch):
    m, ctrl, ref, P = _padded_case()
    monkeypatch.setattr(batch_mod, "SIMD_MAX_INSTRUCTIONS", 10)
    monkeypatch.setattr(sampled_runner, "_RUNNERS", {})
    with pytest.warns(SimdFallbackWarning, match="SIMD_MAX_INSTRUCTIONS = 10"):
        b = simulate_batch(m, ctrl, ref, P[:2], duration=0.1)
    assert b.info["path"] == "scalar" and b.info["instructions"] > 10


@pytest.mark.parametrize("simd", [True, False])
def test_thread_count_is_honoured_and_recorded(simd):
    m, ctrl, ref, P = _padded_case()
    one = simulate_batch(m, ctrl, ref, P, duration=0.2, simd=simd, threads=1)
    two = simulate_batch(m, ctrl, ref, P, duration=0.2, simd=simd, threads=2)
    assert one.info["threads"] == 1 and two.info["threads"] == 2
    assert one.info["openmp"] and two.info["openmp"]
    for k in METRIC_NAMES:
        assert np.array_equal(one.metrics[k], two.metrics[k]), k
    with pytest.raises(ValueError, match="threads"):
        simulate_batch(m, ctrl, ref, P, duration=0.2, threads=0)
