"""Control on the spatial arms (elbow3, panda): every simulate backend agrees, the batch and the
sweep sampling work on K1..Kn models, the runtime validates the spatial parameters, and the
demo's Panda section runs (quick mode)."""
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.experiments import panda as fs
from fjm_runtime.batch.runner import METRIC_NAMES, simulate_batch
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import Sinusoid
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.batch.sweep import run_chunk, sample_parameters, SweepSpec
from fjm_runtime.drives import ParameterInfo
from fjm_runtime.validation import FjmValueError, check_physical

from support.paths import REPO  # noqa: E402


def _stiffness(m, factors):
    return {f"K{i + 1}": m.default_params[f"K{i + 1}"] * f for i, f in enumerate(factors)}


def _ref(m):
    n = m.n
    return Sinusoid(np.linspace(0.1, 0.3, n), np.linspace(1.0, 2.0, n), n=n,
                    offset=np.asarray(fs.READY[:n]) if m.name == "panda" else 0.3)


# -- simulate: python, casadi (fused) and compiled give the same trajectories -----------------
@pytest.mark.parametrize("name,kind,duration", [
    ("elbow3", "ismc", 0.2), ("elbow3", "adaptive", 0.2), ("elbow3", "smc", 0.2), ("panda", "ismc", 0.02)])
def test_backends_agree_on_spatial_arms(name, kind, duration):
    m = fjm_runtime.load(name)
    kw = dict(lam=8.0, k_s=50.0, delta=0.5, u_max=5.0 if name == "elbow3" else np.array(fs.PANDA_EFFORT))
    if kind == "adaptive":
        K0 = np.array([m.default_params[f"K{i + 1}"] for i in range(m.n)])
        kw["K_bounds"] = (0.5 * K0, 1.5 * K0)
    ctrl = make_controller(kind, m, m.default_params, **kw)
    # TRUE plant differs from the nominal one; rest state holding gravity of the TRUE plant
    p_true = _stiffness(m, np.linspace(0.9, 1.1, m.n))
    if name == "panda":
        p_true["m_load"] = 0.5
    ref = _ref(m)
    x0 = fs.rest_state(m, ref(0.0)[0], p_true)
    runs = {b: simulate(m, ctrl, ref, duration=duration, dt=1e-3, true_params=p_true, x0=x0, backend=b)
            for b in ("python", "casadi", "compiled")}
    base = runs["python"]
    assert base.x.shape == (int(round(duration / 1e-3)) + 1, m.nx)
    assert np.all(np.isfinite(base.x)) and np.ptp(base.u, axis=0).max() > 0  # the law acts
    for b in ("casadi", "compiled"):
        np.testing.assert_allclose(runs[b].x, base.x, rtol=0, atol=1e-9, err_msg=b)
        np.testing.assert_allclose(runs[b].u, base.u, rtol=1e-9, atol=1e-9, err_msg=b)
        for k in METRIC_NAMES:
            assert getattr(runs[b].metrics, k) == pytest.approx(getattr(base.metrics, k), rel=1e-9, abs=1e-12), k


def test_rest_state_holds_gravity():
    """At ``rest_state`` the TRUE plant's links do not accelerate (spring torque = gravity)."""
    m = fjm_runtime.load("panda")
    p = _stiffness(m, [0.8, 1.2, 1.0, 0.9, 1.1, 0.7, 1.3])
    p["m_load"] = 1.5
    x = fs.rest_state(m, fs.READY, p)
    assert np.abs(x[2 * m.n:3 * m.n] - x[:m.n]).max() > 1e-5  # the springs are deflected
    np.testing.assert_allclose(np.asarray(m.f(x, p)).ravel()[m.n:2 * m.n], 0.0, atol=1e-9)


# -- batch and sweep ----------------------------------------------------------------------------
def test_batch_on_elbow3_rows_are_their_own_plants():
    m = fjm_runtime.load("elbow3")
    ctrl = make_controller("ismc", m, m.default_params, lam=8.0, k_s=50.0, delta=0.5, u_max=20.0)
    ref = _ref(m)
    P = sample_parameters(m, 3, seed=2, k_relative=(0.8, 1.2))
    batch = simulate_batch(m, ctrl, ref, P, duration=0.5, parallel=False)
    assert not batch.diverged.any()
    for i, row in enumerate(P):
        single = simulate(m, ctrl, ref, duration=0.5, true_params=row, backend="compiled",
                          substeps=batch.info["substeps"])
        for k in METRIC_NAMES:
            assert batch.metrics[k][i] == pytest.approx(getattr(single.metrics, k), rel=1e-9, abs=1e-12), k
        np.testing.assert_allclose(batch.x_final[i], single.x[-1], rtol=0, atol=1e-9)
    assert np.ptp(batch.metrics["rms_error"]) > 0


def test_relative_stiffness_sampling_and_sweep_chunk():
    m = fjm_runtime.load("elbow3")
    P = sample_parameters(m, 40, seed=5, k_relative=(0.7, 1.3))
    for i in range(m.n):
        j = m.param_names.index(f"K{i + 1}")
        ratio = P[:, j] / m.default_params[f"K{i + 1}"]
        assert ratio.min() >= 0.7 and ratio.max() <= 1.3 and ratio.std() > 0.05
    with pytest.raises(ValueError, match="k_relative"):
        sample_parameters(m, 2, k_relative=(1.3, 0.7))
    spec = SweepSpec(model="elbow3", controller="ismc", controller_options={"lam": 8.0, "k_s": 50.0, "delta": 0.5},
                     reference="sine", reference_options={"amplitude": 0.2, "omega": 1.0}, duration=0.3)
    Q = sample_parameters(m, 2, seed=5, k_relative=(0.95, 1.05), spread={})
    got = run_chunk(spec, Q)
    assert set(METRIC_NAMES) <= set(got) and not got["diverged"].any()
    assert np.all(np.isfinite(got["rms_error"]))


# -- validation of the spatial parameters -----------------------------------------------------
def test_payload_mass_must_be_non_negative_position_free():
    m = fjm_runtime.load("panda")
    with pytest.raises(FjmValueError, match="m_load"):
        m.params_array({"m_load": -0.1})
    p = m.params_array({"m_load": 0.0, "x_load": -2.0, "y_load": 3.0})
    assert p[m.param_names.index("x_load")] == -2.0
    with pytest.raises(ValueError, match="m_load"):
        simulate(m, make_controller("fl", m, m.default_params, lam=5.0), _ref(m), duration=0.01,
                 true_params={"m_load": -1.0}, backend="python")


def test_symbolic_link_inertials_are_checked():
    names = ("K1", "m_forearm", "cx_forearm", "ixx_forearm", "ixy_forearm", "ixz_forearm",
             "iyy_forearm", "iyz_forearm", "izz_forearm")
    good = np.array([100.0, 2.0, -0.3, 0.02, 0.001, 0.0, 0.03, 0.0, 0.01])
    info = {"K1": ParameterInfo("N m/rad", "stiffness", ">0"), "m_forearm": ParameterInfo("kg", "mass", ">0")}
    check_physical(names, good, info=info)
    for idx, value, pattern in ((1, 0.0, "m_forearm"), (1, -1.0, "m_forearm"),
                                (3, -0.02, "positive definite"), (4, 0.05, "positive definite")):
        bad = good.copy()
        bad[idx] = value
        with pytest.raises(FjmValueError, match=pattern):
            check_physical(names, bad, info=info)


# -- the demo's Panda section -----------------------------------------------------------------
def test_panda_limits_are_the_urdfs():
    root = ET.parse(REPO / "derive" / "robots" / "panda" / "panda.urdf").getroot()
    joints = {j.get("name"): j for j in root.iter("joint")}
    names = fjm_runtime.load("panda").manifest["source"]["joints"]
    for i, nm in enumerate(names):
        lim = joints[nm].find("limit")
        assert float(lim.get("effort")) == fs.PANDA_EFFORT[i]
        assert float(lim.get("lower")) == fs.PANDA_LOWER[i] and float(lim.get("upper")) == fs.PANDA_UPPER[i]
    # the reference stays inside the limits
    lo = np.asarray(fs.READY) - np.asarray(fs.AMPLITUDE)
    hi = np.asarray(fs.READY) + np.asarray(fs.AMPLITUDE)
    assert np.all(lo > np.asarray(fs.PANDA_LOWER)) and np.all(hi < np.asarray(fs.PANDA_UPPER))


def test_panda_section_quick(tmp_path):
    md = fs.panda_section(tmp_path, duration=10.0, quick=True)
    cases = fs.QUICK_CASES
    text = "\n".join(md)
    assert (tmp_path / "panda_tracking.png").stat().st_size > 1000
    rows = [ln for ln in md if ln.startswith("| ") and not ln.startswith("| controller")]
    assert len(rows) == len(fs.CONTROLLERS) * len(cases)
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        if cells[2].startswith("diverged"):
            continue
        peaks = [float(v) for v in cells[5].split("/")]
        assert peaks[0] <= max(fs.PANDA_EFFORT[:4]) + 1e-9 and peaks[1] <= max(fs.PANDA_EFFORT[4:]) + 1e-9
        assert all(np.isfinite(float(c)) for c in cells[2:5])
    assert re.search(r"Hold .*: .*; do not hold: ", text)
    csv_lines = (tmp_path / "panda_tracking.csv").read_text().splitlines()
    assert csv_lines[0].startswith("controller,case,joint")
