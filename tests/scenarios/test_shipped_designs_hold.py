"""Every shipped design that records a re-check holds again when a user runs it: the first fresh draws of its
re-check (the same TRUE plants and noise seeds ``fjm design`` drew) through ``simulate``, the single-run loop
a user calls (not the batch engine the search ran), with the design's own conditions: its sensor, delay,
prediction with its recorded predictor substeps, command interface and task from its start state.

Each run meets the design's thresholds, and its worst-joint RMS stays within 5 % of the worst the re-check
recorded over its 200 draws (the single-run loop predicts on the recorded substeps, the search on the
plant's: the two predictions agree to 1e-3 of the noise, not bit for bit).
"""
import json
from importlib import resources

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.analysis.search.draws import default_spread, draw_params, load_params_file
from fjm_runtime.analysis.search.search import RECHECK_SEED_OFFSET
from fjm_runtime.control.design import Design
from fjm_runtime.control.references import make_reference
from fjm_runtime.sim.interface import interface_from_record
from fjm_runtime.sim.metrics import rms_second_half, time_at_limit, torque_jitter
from fjm_runtime.sim.simulate import simulate
from support.paths import REPO

FOLDER = resources.files("fjm_runtime.control").joinpath("designed")
RECHECKED = sorted(p.name for p in FOLDER.iterdir() if p.name.endswith(".json")
                   and json.loads(p.read_text()).get("recheck", {}).get("draws", 0) > 0)
#: Fresh draws re-run per design (the re-check's first ones).
DRAWS = 3
#: The design of the user-arm example (a model file, not a built-in model).
UR5E_DESIGN = REPO / "examples" / "ur5e" / "ur5e_impedance_1000hz_d1.json"


def test_the_real_interface_designs_are_rechecked_ones():
    assert {"panda_impedance_1000hz_d1.json", "panda_joint_impedance_1000hz_d1.json",
            "panda_hd_impedance_1000hz_d1.json", "baxter_impedance_1000hz_d1.json"} <= set(RECHECKED)


@pytest.mark.exhaustive  # a C build per design and 3 runs of 10 s: 20-60 s each
@pytest.mark.parametrize("name", RECHECKED)
def test_shipped_design_holds_on_its_first_fresh_draws(name):
    d = Design.load(FOLDER.joinpath(name))
    _holds_on_first_fresh_draws(d, fjm_runtime.load(d.model), name)


@pytest.mark.exhaustive  # derives the UR5e, a C build and 3 runs of 10 s
def test_the_user_arm_example_design_holds_on_its_first_fresh_draws(tmp_path):
    """examples/ur5e/'s design (the model file derived as a user derives it) holds as the shipped ones do."""
    from fjm_runtime.cli.main import main
    assert main(["derive", "--model-file", str(REPO / "examples" / "ur5e.toml"), "--out", str(tmp_path)]) == 0
    d = Design.load(UR5E_DESIGN)
    assert d.model == "ur5e" and d.meets is True and d.kind == "impedance"
    _holds_on_first_fresh_draws(d, fjm_runtime.load(str(tmp_path / "ur5e")), UR5E_DESIGN.name)


def _holds_on_first_fresh_draws(d, model, name):
    rep = d.report
    source = d.params["source"]   # the spread the design drew from: the default box or its parameter file
    spread = default_spread(model, d.nominal(model)) if source == "default" else load_params_file(REPO / source, model)
    P = draw_params(model, DRAWS, int(rep["seed"]), spread, fresh=True)
    ctrl, interface = d.controller(model), interface_from_record({"interface": d.interface, "sensor": d.sensor})
    # a design searched without a task of the model's ran fjm design's default: 0.5 rad sines at 1 rad/s about
    # q = 0 from rest (its record {"kind": "sine", ...}; Design.reference leaves it to simulate's flags)
    reference = d.reference(model) or make_reference("sine", int(model.n), amplitude=float(d.task["amplitude"]),
                                                     omega=float(d.task["omega"]))
    x0 = d.start_state(model) if d.reference(model) is not None else None
    thr = rep["thresholds"]
    joints = [j - 1 for j in thr["jitter_joints"]]
    recorded = max(rep["recheck"]["worst_case"]["rms_second_half"])
    for i in range(DRAWS):
        seed = int(rep["seed"]) + RECHECK_SEED_OFFSET + i
        r = simulate(model, ctrl, reference, duration=float(rep["duration"]), dt=1.0 / d.rate,
                     true_params=dict(zip(model.param_names, P[i])), x0=x0,
                     sensor=d.sensor_model().with_seed(seed), delay_samples=d.delay, predict=bool(d.predict),
                     predict_substeps=d.predict_substeps, interface=interface, backend="compiled")
        rms = rms_second_half(r)
        assert np.all(np.isfinite(rms)) and np.max(rms) <= thr["max_rms"], (name, i, rms)
        assert np.max(rms) <= 1.05 * recorded, (name, i, float(np.max(rms)), recorded)
        assert np.max(torque_jitter(r)[joints]) <= thr["max_jitter"], (name, i)
        assert np.max(time_at_limit(r, ctrl.u_max)) <= thr["max_at_limit"], (name, i)


def test_the_user_arm_wrist_mode_is_above_the_nyquist_frequency(tmp_path):
    """docs/real-interface.md: the UR5e's fastest open-loop mode at q = 0 is about 5.5e3 rad/s, above pi / T at
    1 kHz (central differences of the derived f; the mode's imaginary part)."""
    from fjm_runtime.cli.main import main
    assert main(["derive", "--model-file", str(REPO / "examples" / "ur5e.toml"), "--out", str(tmp_path)]) == 0
    m = fjm_runtime.load(str(tmp_path / "ur5e"))
    p, nx, eps = m.params_array(None), 4 * m.n, 1e-7
    f = lambda x: np.asarray(m.f(x, p), dtype=float).ravel()  # noqa: E731
    A = np.column_stack([(f(eps * e) - f(-eps * e)) / (2 * eps) for e in np.eye(nx)])
    fastest = float(np.max(np.abs(np.linalg.eigvals(A).imag)))
    assert fastest == pytest.approx(5.5e3, rel=0.02) and fastest > np.pi * 1000.0
