"""simulate_batch: a batch of one equals a single run; each row is its own plant."""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.batch import METRIC_NAMES, simulate_batch
from fjm_runtime.controllers import make_controller
from fjm_runtime.references import Sinusoid, SmoothStep
from fjm_runtime.simulate import simulate

import os as _os
import shutil as _shutil

pytestmark = pytest.mark.skipif(not (_os.environ.get("CC") or _shutil.which("gcc") or _shutil.which("cc")),
                                reason="needs a C compiler")


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("FJM_CACHE", str(tmp_path / "cache"))


def _link1_ctrl(m, kind="smc", **kw):
    kw.setdefault("k_s", 1008.0)
    kw.setdefault("delta", 5.04)
    return make_controller(kind, m, {"K": 150.0}, lam=8.0, beta_hat=0.015, **kw)


def _assert_same_metrics(single, batch, i, rel=1e-9):
    for k in METRIC_NAMES:
        a, b = getattr(single.metrics, k), batch.metrics[k][i]
        assert b == pytest.approx(a, rel=rel, abs=1e-12), k


def test_batch_of_one_equals_single_run():
    m = fjm_runtime.load("link1")
    ctrl = _link1_ctrl(m)
    ref = Sinusoid(0.5, 1.0)
    p = m.params_array({"K": 120.0})
    single = simulate(m, ctrl, ref, duration=2.0, true_params=p, backend="python")
    batch = simulate_batch(m, ctrl, ref, p[None], duration=2.0)
    _assert_same_metrics(single, batch, 0)
    assert np.max(np.abs(batch.x_final[0] - single.x[-1])) < 1e-9
    assert not batch.diverged[0]


@pytest.mark.parametrize("parallel,simd", [(True, True), (True, False), (False, False)])
def test_each_row_is_its_own_plant(parallel, simd):
    m = fjm_runtime.load("link1")
    ctrl = _link1_ctrl(m, kind="ismc", u_max=20.0)
    ref = SmoothStep(1.0, rise_time=0.5)
    Ks = [100.0, 150.0, 200.0, 130.0, 170.0]
    P = np.array([m.params_array({"K": k}) for k in Ks])
    batch = simulate_batch(m, ctrl, ref, P, duration=1.0, parallel=parallel, simd=simd)
    for i, k in enumerate(Ks):
        single = simulate(m, ctrl, ref, duration=1.0, true_params={"K": k}, backend="compiled")
        _assert_same_metrics(single, batch, i)
    assert len(set(np.round(batch.metrics["rms_error"], 12))) == len(Ks)


def test_planar2_batch_matches_single():
    m = fjm_runtime.load("planar2")
    ctrl = make_controller("smc", m, {}, lam=8.0, k_s=100.0, delta=2.0)
    ref = Sinusoid(0.5, 1.0, n=2)
    P = np.array([m.params_array({"K1": 120.0}), m.params_array({"K2": 190.0})])
    batch = simulate_batch(m, ctrl, ref, P, duration=0.5)
    for i in range(2):
        single = simulate(m, ctrl, ref, duration=0.5, true_params=P[i], backend="python")
        _assert_same_metrics(single, batch, i)


def test_divergence_is_flagged_not_raised():
    m = fjm_runtime.load("link1")
    ctrl = _link1_ctrl(m)
    P = np.array([m.params_array({"K": 150.0}), m.params_array({"K": 150.0, "J_m": 1e-6})])
    batch = simulate_batch(m, ctrl, Sinusoid(0.5, 1.0), P, duration=1.0, max_state=1e3)
    assert not batch.diverged[0] and np.isfinite(batch.metrics["rms_error"][0])
    assert batch.diverged[1] and np.isnan(batch.metrics["rms_error"][1])
    assert 0 < batch.divergence_time[1] <= 1.0


def test_bad_params_shape_is_a_clear_error():
    m = fjm_runtime.load("link1")
    with pytest.raises(ValueError, match="params_true_array"):
        simulate_batch(m, _link1_ctrl(m), Sinusoid(0.5, 1.0), np.zeros((3, 2)), duration=1.0)


def test_simd_lanes_and_padding_agree_with_scalar():
    """11 runs: not a multiple of the lane count, so the last group is padded."""
    m = fjm_runtime.load("link1")
    ctrl = _link1_ctrl(m)
    ref = Sinusoid(0.5, 1.0)
    P = np.array([m.params_array({"K": k}) for k in np.linspace(100.0, 200.0, 11)])
    a = simulate_batch(m, ctrl, ref, P, duration=0.5, simd=False)
    b = simulate_batch(m, ctrl, ref, P, duration=0.5, simd=True)
    for k in METRIC_NAMES:
        assert np.allclose(a.metrics[k], b.metrics[k], rtol=1e-9, atol=1e-12), k
    assert np.allclose(a.x_final, b.x_final, rtol=1e-9, atol=1e-12)
