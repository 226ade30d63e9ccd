"""The typed design (a gains file): reading and writing, the checks, the task's start and the controller."""
import json
from importlib import resources

import numpy as np
import pytest

from fjm_runtime.control.design import Design, task_start
from fjm_runtime.control.factory import make_controller
from fjm_runtime.sim.sensor import SensorModel
from fjm_runtime.validation import FjmValueError

SHIPPED = sorted(p.name for p in resources.files("fjm_runtime.control").joinpath("designed").iterdir()
                 if p.name.endswith(".json"))


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_designs_round_trip_key_for_key(name, tmp_path):
    """Every shipped file reads into a Design whose JSON is the file's, key for key and in order; a saved
    copy reads back equal."""
    raw = json.loads(resources.files("fjm_runtime.control").joinpath("designed", name).read_text())
    design = Design.shipped(raw["model"], raw["kind"], raw["sensing"], raw["rate"], raw["delay"])
    assert design is not None and design.file.endswith(name)
    assert design.as_dict() == raw and list(design.as_dict()) == list(raw)
    design.save(tmp_path / "copy.json")
    assert json.loads((tmp_path / "copy.json").read_text()) == raw
    assert Design.load(tmp_path / "copy.json") == design


def test_shipped_lookup_rounds_the_rate_and_refuses_what_is_not_shipped():
    a = Design.shipped("panda", None, "torque", 1000.4, 1)
    assert a is not None and a.kind == "ismc" and a.rate == 1000.0
    assert Design.shipped("panda", "ismc", "state", 1000.0, 1) is None
    assert Design.shipped("panda", "ismc", "torque", 500.0, 1) is None
    assert Design.shipped("panda", None, "torque", float("nan"), 1) is None


def test_shipped_lookup_of_any_kind_reads_the_kinds_from_the_files():
    """Every shipped file is found by its own conditions, with its kind or with none; with none, the kind
    is the first by name among the files at those conditions (a kind may hold an underscore, and the
    panda's files share a prefix with panda_hd's)."""
    from importlib import resources
    folder = resources.files("fjm_runtime.control").joinpath("designed")
    raws = [json.loads(p.read_text()) for p in folder.iterdir() if p.name.endswith(".json")]
    for raw in raws:
        cond = (raw["sensing"], raw["rate"], raw["delay"])
        own = Design.shipped(raw["model"], raw["kind"], *cond)
        assert own is not None and own.kind == raw["kind"] and own.model == raw["model"]
        same = sorted(r["kind"] for r in raws if r["model"] == raw["model"] and (r["sensing"], r["rate"],
                                                                                   r["delay"]) == cond)
        assert Design.shipped(raw["model"], None, *cond).kind == same[0]
    assert any("_" in r["kind"] for r in raws)  # the case a name split got wrong is shipped


def test_shipped_lookup_of_any_kind_finds_a_kind_with_an_underscore_alone(tmp_path, monkeypatch):
    """A folder holding only the joint impedance design: found with no kind given."""
    import shutil
    import types
    from importlib import resources
    import fjm_runtime.control.design as design_module
    name = "panda_joint_impedance_1000hz_d1.json"
    (tmp_path / "designed").mkdir()
    shutil.copy(resources.files("fjm_runtime.control").joinpath("designed", name), tmp_path / "designed" / name)
    monkeypatch.setattr(design_module, "resources", types.SimpleNamespace(files=lambda package: tmp_path))
    found = Design.shipped("panda", None, "full", 1000.0, 1)
    assert found is not None and found.kind == "joint_impedance"


def test_start_state_holds_gravity_at_the_tasks_first_sample(panda):
    """The shipped Panda task starts at READY - A (sines with phase -pi/2) at rest: the links do not
    accelerate (the spring torque carries gravity) and the motors are wound up."""
    design = Design.shipped("panda", "ismc", "torque", 1000.0, 1)
    x0 = design.start_state(panda)
    n = panda.n
    q0 = np.subtract(design.task["offset"], design.task["amplitude"])
    np.testing.assert_allclose(x0[:n], q0, rtol=0, atol=1e-15)
    assert np.all(x0[n:2 * n] == 0) and np.all(x0[3 * n:] == 0)
    assert np.max(np.abs(x0[2 * n:3 * n] - x0[:n])) > 1e-4
    f = np.asarray(panda.f(x0, panda.default_params), dtype=float).ravel()
    assert np.max(np.abs(f[n:2 * n])) < 1e-9                            # link accelerations vanish
    # without "holding gravity" the motors sit on the links
    plain = Design(kind="ismc", gains={}, task={**design.task, "start": "at rest"})
    x1 = plain.start_state(panda)
    np.testing.assert_array_equal(x1[2 * n:3 * n], x1[:n])
    assert Design(kind="ismc", gains={}).start_state(panda) is None


def test_task_start_takes_the_nominal_parameters(panda):
    """Holding gravity with a heavier nominal payload winds the motors further (the nominal model's G)."""
    design = Design.shipped("panda", "ismc", "torque", 1000.0, 1)
    ref = design.reference(panda)
    light = task_start(panda, ref, design.task["start"], None)
    heavy = task_start(panda, ref, design.task["start"], {**panda.default_params, "m_load": 2.0})
    assert np.max(np.abs(heavy[14:21] - light[14:21])) > 1e-6
    np.testing.assert_array_equal(heavy[:14], light[:14])
    np.testing.assert_array_equal(light, design.start_state(panda))


def test_checks_name_the_file_and_key(panda):
    with pytest.raises(FjmValueError, match=r"^g.json: expected \{\"kind\""):
        Design.from_dict({"kind": "nope", "gains": {}}, "g.json")
    with pytest.raises(FjmValueError, match=r"g.json: rate = -1"):
        Design.from_dict({"kind": "smc", "gains": {}, "rate": -1}, "g.json")
    with pytest.raises(FjmValueError, match=r"g.json: delay = 1.5"):
        Design.from_dict({"kind": "smc", "gains": {}, "delay": 1.5}, "g.json")
    bad_sign = Design.from_dict({"kind": "smc", "gains": {"lam": 8.0, "k_s": -1.0, "delta": 1.0}}, "g.json")
    with pytest.raises(FjmValueError, match=r"g.json: gains.k_s = -1.0; expected .* >= 0"):
        bad_sign.check(panda)
    two = Design.from_dict({"kind": "smc", "model": "planar2", "gains": {"lam": 8.0, "k_s": [1.0, 2.0],
                                                                         "delta": 1.0}}, "g.json")
    with pytest.raises(FjmValueError, match=r"gains are for model 'planar2' with 2 joints; panda has 7"):
        two.check(panda)
    with pytest.raises(FjmValueError, match=r"gains.delta is missing"):
        Design(kind="smc", gains={"lam": 8.0, "k_s": 1.0}, source="g.json").check(panda)


def test_mismatches_list_each_differing_condition(panda):
    design = Design.shipped("panda", "ismc", "torque", 1000.0, 1)
    sensor = design.sensor_model()
    cond = {"model": "panda", "kind": "ismc", "sensing": "torque", "rate": 1000.0, "delay": 1,
            "predict": True, "sensor": sensor}
    assert design.mismatches(cond) == []
    got = design.mismatches({**cond, "rate": 500.0, "delay": 2, "sensor": SensorModel.ideal()})
    assert len(got) == 3 and "500 Hz" in got[0] and "delay of 1" in got[1]
    bare = Design(kind="ismc", gains={}).mismatches(cond)              # a hand-written file records none
    assert len(bare) == 6 and "'unrecorded'" in bare[-1]


def test_controller_has_the_files_gains(panda):
    """``controller(model)`` is make_controller with the file's kind, sensing and gains: same gain vector."""
    design = Design.shipped("panda", "ismc", "torque", 1000.0, 1)
    ctrl = design.controller(panda)
    ref = make_controller("ismc", panda, {}, sensing="torque", **design.gains)
    np.testing.assert_array_equal(np.asarray(ctrl.gains), np.asarray(ref.gains))
    assert ctrl.sensing == "torque" and "u_max" not in design.law_gains()
    np.testing.assert_array_equal(ctrl.u_max, np.asarray(design.gains["u_max"], dtype=float))


def test_nominal_values_come_from_params(panda):
    d = Design(kind="smc", gains={}, params={"nominal": {"K1": 120}})
    assert d.nominal(panda) == {"K1": 120.0}
    with pytest.raises(FjmValueError, match="params.nominal.K9"):
        Design(kind="smc", gains={}, params={"nominal": {"K9": 1.0}}).nominal(panda)


def test_a_null_condition_stays_in_the_file(tmp_path):
    """Keys an older writer left null (``reference``: no task) are written back as null, in place."""
    raw = {"model": "link1", "kind": "ismc", "reference": None, "gains": {"lam": 8.0, "k_s": 1.0, "delta": 1.0},
           "draws": 3}
    d = Design.from_dict(raw)
    assert d.task is None and d.as_dict() == raw and list(d.as_dict()) == list(raw)
    d.save(tmp_path / "g.json")
    assert json.loads((tmp_path / "g.json").read_text()) == raw


def test_a_run_on_another_command_interface_is_not_the_designs():
    from fjm_runtime.control.design import Design
    from fjm_runtime.sim.interface import CommandInterface
    d = Design.shipped("panda", "ismc", "torque", 1000.0, 1)
    cond = {"model": "panda", "kind": "ismc", "sensing": "torque", "rate": 1000.0, "delay": 1, "predict": True,
            "sensor": d.sensor_model()}
    # the shipped record predates the interface: the motor interface without a rate limit is its own
    assert d.mismatches({**cond, "interface": CommandInterface.motor()}) == []
    why = d.mismatches({**cond, "interface": CommandInterface.ideal()})
    assert len(why) == 1 and "'ideal'" in why[0]
    limited = CommandInterface.motor().with_rate_limit(1000.0)
    assert d.mismatches({**cond, "interface": limited}) != []
