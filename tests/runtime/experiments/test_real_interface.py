"""The demo's real-interface section (fjm_runtime.experiments.real_interface) in quick mode.

The section runs every law on its interface over the nominal plant and one random draw (0.3 s, casadi
backend): the impedance laws do not diverge on the nominal plant, every finished row's metrics are finite
and are the worst over the plants computed here by hand, the motor interface never rate-limits (it has no
limit), and the table and the figure are written. The documented numbers come from ``make demo``.
"""
import numpy as np
import pytest

from fjm_runtime.control.design import Design
from fjm_runtime.experiments import real_interface as ri
from fjm_runtime.experiments.settings import DemoContext


def test_plants_are_the_nominal_one_then_draws_and_corners(panda):
    cases = ri.plants(panda, 2)
    assert [c["label"] for c in cases][0] == "nominal" and len(cases) == 5
    assert cases[0]["params"] == panda.default_params
    p0 = panda.default_params
    k = [np.array([c["params"][f"K{i}"] / p0[f"K{i}"] for i in range(1, 8)]) for c in cases]
    np.testing.assert_allclose(k[-2], 0.7)
    np.testing.assert_allclose(k[-1], 1.3)
    assert all(np.all((r >= 0.7 - 1e-12) & (r <= 1.3 + 1e-12)) for r in k)
    assert len({c["seed"] for c in cases}) == 5


def test_laws_are_built_for_their_interface_on_the_nominal_model(panda):
    design = Design.shipped("panda", "ismc", "torque", ri.RATE, ri.DELAY)
    for label, (kind, interface) in ri.LAWS.items():
        ctrl, iface = ri.controller(label, panda)
        assert iface == interface
        np.testing.assert_array_equal(ctrl.u_max, panda.limits.effort)
    ismc, _ = ri.controller("ismc_tau (shipped design)", panda)
    np.testing.assert_allclose(ismc.delta, design.gains["delta"], rtol=1e-12)
    assert ismc.sensing == "torque"
    assert ri.LAWS["joint_impedance (shipped design)"][1] == "franka"
    for label in ("impedance (shipped design)", "joint_impedance (shipped design)"):
        kind = ri.LAWS[label][0]
        shipped = Design.shipped("panda", kind, "full", ri.RATE, ri.DELAY)
        for name, value in shipped.law_gains().items():
            np.testing.assert_allclose(getattr(ri.controller(label, panda)[0], name), value, rtol=1e-12)
    assert {i for k, i in ri.LAWS.values() if k != "joint_impedance"} == {"motor"}


@pytest.fixture(scope="module")
def section(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    ctx = DemoContext(out=out, duration=1.0, quick=True, n_mc=1, progress=lambda msg: None, results={})
    md, figs = ri.real_interface_section(ctx)
    return ctx, md, figs


def test_quick_section_rows_are_sane(section):
    ctx, md, figs = section
    rows = ctx.results["real_interface"]
    assert list(rows) == list(ri.LAWS)
    for label in ("impedance (shipped design)", "joint_impedance (shipped design)"):
        assert rows[label]["diverged"] == 0, label
    for label, r in rows.items():
        assert r["runs"] == 2
        if r["diverged"] < r["runs"]:
            for key in ("rms", "jitter_14", "at_torque_limit", "at_rate_limit"):
                assert np.isfinite(r[key]), (label, key)
            assert 0.0 <= r["at_torque_limit"] <= 1.0 and 0.0 <= r["at_rate_limit"] <= 1.0
        if r["interface"] == "motor":
            assert r["at_rate_limit"] == 0.0, label
    sens = ctx.results["real_interface_sensing"]
    assert set(sens) == {f"{law}, {name}" for law in ri.FOURTH_ORDER for name in ri.SENSORS}
    assert sens["ismc_tau (shipped design), ideal"]["diverged"] == 0  # the design holds without noise
    assert np.isfinite(sens["ismc_tau (shipped design), ideal"]["rms"])
    # the impedance laws hold the task from rest: well below a degree over 0.3 s
    assert rows["impedance (shipped design)"]["rms"] < 2e-3 and rows["joint_impedance (shipped design)"]["rms"] < 5e-3
    assert figs[0].name == "real_arm_laws.png" and figs[0].stat().st_size > 5_000
    table = [line for line in md if line.startswith("| ")]
    from fjm_runtime.experiments.shipped_designs import rechecked_files
    assert len(table) == 2 + len(ri.LAWS) + len(ri.SENSORS) * len(ri.FOURTH_ORDER) + 1 + len(rechecked_files())
    imp = "impedance (shipped design)"
    assert table[1 + list(rows).index(imp)].split(" | ")[2] == f"{1e3 * rows[imp]['rms']:.3g}"
    # the stated pdg gains are the section's numbers, not the source text of an f-string without its f
    text = "\n".join(md)
    assert f"k_p = {list(ri.PDG_GAINS['k_p'])} N m/rad" in text and "{" not in text


def test_metrics_are_the_worst_over_plants(panda):
    cases = ri.plants(panda, 1)[:2]
    res = ri.run_all(panda, cases, 0.1, backend="casadi")
    rows = ri.summary_rows(panda, res)
    for label, runs in res.items():
        done = [r for r in runs if not ri.diverged(r)]
        if not done:
            continue
        rms = max(np.max(np.sqrt(np.mean(r.e1 ** 2, axis=0))) for r in done)
        np.testing.assert_allclose(rows[label]["rms"], rms, rtol=1e-12)
        lim = np.asarray(panda.limits.effort)
        at = max(np.max(np.mean(np.abs(r.u[:-1]) >= lim * (1 - 1e-9), axis=0)) for r in done)
        np.testing.assert_allclose(rows[label]["at_torque_limit"], at)
