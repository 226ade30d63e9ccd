"""The predictor's substeps chosen by accuracy (fjm_runtime.sim.predictor), from first principles.

The choice is checked with this file's own arithmetic: the delayed measurement turned into a state
(``q_m = q + K_nom^-1 tau_J``), a plain RK4 over each of the ``d`` samples under the held torque, the
torque measurement ``[q; dq; K (q_m - q); K (dq_m - dq); dq_m]`` of the result, against 64 substeps.
"""
import numpy as np
import pytest

import fjm_runtime

from fjm_runtime.control.design import Design
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import Sinusoid
from fjm_runtime.export.controller import design_controller
from fjm_runtime.sim import predictor
from fjm_runtime.sim.sensor import SensorModel
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.drives import linear_stiffness_indices
from fjm_runtime.sim.step_layout import make_layout
from fjm_runtime.sim.substeps import resolve_substeps
from fjm_runtime.validation import FjmValueError
from support.numerics import rk4


def _predicted(model, p, m_old, U_row, T, substeps):
    """This file's predictor: state from the torque measurement, RK4 per sample, measurement again."""
    n = model.n
    K = p[linear_stiffness_indices(model, "torque sensing")]
    q, dq, tau, dqm = m_old[:n], m_old[n:2 * n], m_old[2 * n:3 * n], m_old[4 * n:]
    x = np.concatenate([q, dq, q + tau / K, dqm])
    for j in range(len(U_row) // n):
        u = U_row[j * n:(j + 1) * n]
        x = rk4(lambda s: model.f(s, p) + model.g(s, p) @ u, x, T / substeps, substeps)[-1]
    q, dq, qm, dqm = x[:n], x[n:2 * n], x[2 * n:3 * n], x[3 * n:]
    return np.concatenate([q, dq, K * (qm - q), K * (dqm - dq), dqm])


def _worst_over_tolerance(model, p, X, U, sensor, T, substeps):
    """max over starts and slots of |prediction - 64-substep prediction| / tolerance."""
    n = model.n
    K = p[linear_stiffness_indices(model, "torque sensing")]
    exact = np.array([np.concatenate([x[:n], x[n:2 * n], K * (x[2 * n:3 * n] - x[:n]),
                                      K * (x[3 * n:] - x[n:2 * n]), x[3 * n:]]) for x in X])
    normals = np.random.default_rng(predictor.NOISE_SEED).standard_normal(exact.shape)
    noisy = exact + sensor.levels("torque", n) * normals
    levels = np.concatenate([np.broadcast_to(np.asarray(getattr(sensor, b), dtype=float), (n,))
                             for b in ("q", "dq", "tau_J", "dtau_J", "dq_m")])
    tol = np.maximum(1e-3 * levels, 1e-9)
    worst = 0.0
    for m_old, u in zip(np.vstack([exact, noisy]), np.vstack([U, U])):
        err = np.abs(_predicted(model, p, m_old, u, T, substeps) - _predicted(model, p, m_old, u, T, 64))
        worst = max(worst, float(np.max(err / tol)))
    return worst


def test_chosen_substeps_meet_the_bound_and_one_fewer_does_not(planar2):
    """planar2, torque-sensed ismc at 250 Hz, delay 2, noise-free: the bound is the 1e-9 floor in every slot
    (stricter than the plant's rule, which gives 3 substeps here: the choice is 5)."""
    ctrl = make_controller("ismc", planar2, {}, sensing="torque", lam=20.0, k_s=200.0, delta=5.0)
    ref, T, d, sensor = Sinusoid(0.5, 2.0, n=2), 4e-3, 2, SensorModel.ideal()
    x0 = np.concatenate([ref(0.0)[0], np.zeros(2), ref(0.0)[0], np.zeros(2)])
    s = predictor.loop_predict_substeps(planar2, ctrl, sensor, T, d, ref, x0)
    assert s >= 2
    p = np.asarray(ctrl.p_nom, dtype=float)
    X, U = predictor.task_points(planar2, ref, x0, p, T, d)
    assert X.shape == (predictor.TASK_POINTS + 1, 8) and U.shape == (predictor.TASK_POINTS + 1, 4)
    assert _worst_over_tolerance(planar2, p, X, U, sensor, T, s) <= 1.0
    assert _worst_over_tolerance(planar2, p, X, U, sensor, T, s - 1) > 1.0


@pytest.mark.exhaustive  # about 22 s of CPU: with the exhaustive checks of .ci/run (planar2's case runs in make test)
def test_panda_shipped_design_records_its_choice(panda):
    """The Panda's shipped design (panda_white noise, 1 kHz, delay 1): the recorded count is the choice,
    within 1e-3 of the noise level of every slot, and one fewer is not; the plant's rule needs more."""
    design = Design.shipped("panda", "ismc", "torque", 1000.0, 1)
    ctrl, sensor = design.controller(panda), design.sensor_model()
    x0 = design.start_state(panda, ctrl.p_nom)
    s = predictor.loop_predict_substeps(panda, ctrl, sensor, 1e-3, 1, design.reference(panda), x0)
    assert design.predict_substeps == s
    assert s < resolve_substeps(None, panda, x0, ctrl.p_nom, 1e-3)
    p = np.asarray(ctrl.p_nom, dtype=float)
    X, U = predictor.task_points(panda, design.reference(panda), x0, p, 1e-3, 1)
    assert _worst_over_tolerance(panda, p, X, U, sensor, 1e-3, s) <= 1.0
    assert _worst_over_tolerance(panda, p, X, U, sensor, 1e-3, s - 1) > 1.0
    assert design_controller(panda, design).layout.predictor_substeps == s


def test_numpy_casadi_and_compiled_steps_use_the_predictor_substeps(planar2):
    """Plant on 3 substeps, predictor on 1: the three backends agree; 1 predictor substep is not 3."""
    ctrl = make_controller("ismc", planar2, {}, sensing="torque", lam=20.0, k_s=200.0, delta=5.0)
    ref = Sinusoid(0.5, 2.0, n=2)
    kw = dict(duration=0.05, dt=4e-3, substeps=3, delay_samples=2, predict=True)
    runs = {b: simulate(planar2, ctrl, ref, backend=b, predict_substeps=1, **kw)
            for b in ("python", "casadi", "compiled")}
    for b in ("casadi", "compiled"):
        assert np.max(np.abs(runs[b].x - runs["python"].x)) < 1e-9
        assert np.max(np.abs(runs[b].u - runs["python"].u)) < 1e-9
    same = simulate(planar2, ctrl, ref, backend="casadi", **kw)
    assert same.settings["predict_substeps"] == 3 and runs["python"].settings["predict_substeps"] == 1
    assert np.max(np.abs(same.u - runs["casadi"].u)) > 1e-9


def test_export_uses_the_recorded_count_and_old_files_keep_the_rule(link1):
    spec = {"model": "link1", "kind": "ismc", "sensing": "torque", "rate": 1000.0, "delay": 1, "predict": True,
            "noise": "panda_white", "gains": {"lam": 20.0, "k_s": 200.0, "delta": 5.0}}
    old = design_controller(link1, Design.from_dict(spec)).layout
    assert old.predict_substeps == 0 and old.predictor_substeps == old.substeps
    new = design_controller(link1, Design.from_dict({**spec, "predict_substeps": 2})).layout
    assert new.predictor_substeps == 2 and new.substeps == old.substeps
    assert Design.from_dict({**spec, "predict_substeps": 2}).as_dict()["predict_substeps"] == 2
    forced = design_controller(link1, Design.from_dict({**spec, "predict_substeps": 2}), substeps=5).layout
    assert forced.predictor_substeps == 5 == forced.substeps


@pytest.mark.parametrize("value", [0, -1, 2.5, True, "3"])
def test_bad_recorded_count_is_a_one_line_error(value):
    with pytest.raises(FjmValueError, match=r"predict_substeps = .*expected an integer >= 1") as e:
        Design.from_dict({"kind": "ismc", "gains": {"lam": 1.0, "k_s": 1.0, "delta": 1.0}, "predict_substeps": value})
    assert "\n" not in str(e.value)


def test_layout_refuses_a_bad_predictor_count(link1):
    ctrl = make_controller("ismc", link1, {}, lam=20.0, k_s=200.0, delta=5.0)
    with pytest.raises(FjmValueError, match="predict_substeps = 0"):
        make_layout(link1, ctrl, 1e-3, 2, SensorModel.ideal(), 1, True, predict_substeps=0)
    assert make_layout(link1, ctrl, 1e-3, 2, SensorModel.ideal(), 0, True, predict_substeps=4).predict_substeps == 0


def test_tolerance_is_a_thousandth_of_the_noise_with_a_floor():
    tol = predictor.prediction_tolerance(SensorModel.panda_white(), "torque", 2, 1e-3)
    sensor = SensorModel.panda_white()
    assert np.allclose(tol[:2], 1e-3 * sensor.q) and np.allclose(tol[4:6], 1e-3 * sensor.tau_J)
    assert np.all(predictor.prediction_tolerance(SensorModel.ideal(), "state", 3, 1e-3) == 1e-9)


def test_tolerance_of_differentiated_slots_is_their_read_noise_not_the_floor():
    """franka_like measures no velocity and no dtau_J: the loop differentiates noisy angles and tau_J. Those
    slots hold a thousandth of that noise (about 5.6e-3 rad/s on dq at 1 kHz), not the noise-free floor
    that only the finest prediction can meet."""
    from fjm_runtime.sim.sensor import read_noise_levels
    sensor, T = SensorModel.franka_like(), 1e-3
    tol = predictor.prediction_tolerance(sensor, "full", 2, T)
    assert np.allclose(tol, 1e-3 * read_noise_levels(sensor, "full", 2, T))
    assert np.all(tol[2:4] > 1e-6) and np.all(tol[10:12] > 1e-5)


@pytest.mark.slow
def test_design_search_records_the_choice(link1):
    """``fjm design --predict``'s record holds the predictor choice of its own loop; without prediction none."""
    from support.tiny_search import TINY, run_search
    from fjm_runtime.sim.sensor import SensorModel as Sensor
    rec = run_search(link1, delay=1, predict=True, sensor=Sensor.panda_white(seed=5), **TINY)
    design = Design.from_dict(rec)
    ctrl = design.controller(link1)
    x0 = design.start_state(link1, ctrl.p_nom)
    ref = design.reference(link1)
    if ref is None:  # the search's default task: 0.5 rad sines at 1 rad/s
        from fjm_runtime.control.references import make_reference
        ref = make_reference("sine", 1, amplitude=0.5, omega=1.0)
        x0 = np.concatenate([ref(0.0)[0], [0.0], ref(0.0)[0], [0.0]])
    assert design.predict_substeps == predictor.loop_predict_substeps(link1, ctrl, design.sensor_model(), 1e-3, 1,
                                                                      ref, x0)
    assert "predict_substeps" not in run_search(link1, delay=1, predict=False, **TINY)


def _shipped_files():
    from importlib import resources
    folder = resources.files("fjm_runtime.control").joinpath("designed")
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".json"))


def _recorded_is_the_choice(name):
    import json
    from importlib import resources
    raw = json.loads(resources.files("fjm_runtime.control").joinpath("designed", name).read_text())
    design = Design.from_dict(raw, name)
    model = fjm_runtime.load(design.model)
    ctrl = design.controller(model)
    x0 = design.start_state(model, ctrl.p_nom)
    s = predictor.loop_predict_substeps(model, ctrl, design.sensor_model(), 1.0 / design.rate, design.delay,
                                        design.reference(model), x0)
    assert design.predict_substeps == s, name
    assert s < predictor.REFERENCE_SUBSTEPS, f"{name}: the choice hit the reference's count"


def test_the_shipped_impedance_design_records_its_choice():
    """franka_like's differentiated slots are held to their read noise: the choice is a few substeps,
    not the 64 of the reference."""
    _recorded_is_the_choice("panda_impedance_1000hz_d1.json")


@pytest.mark.exhaustive  # 2-3 s of CPU per file
@pytest.mark.parametrize("name", _shipped_files())
def test_every_shipped_design_records_its_choice(name):
    _recorded_is_the_choice(name)
