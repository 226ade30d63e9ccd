"""The shipped motor-side impedance designs under franka_like sensing (the Panda, panda_hd, Baxter), and fjm
simulate picking them.

``fjm simulate panda --noise franka_like`` (no gains, law or sensing asked) runs the shipped design made with
that sensor (1 kHz, one sample of delay, prediction, full sensing), as ``--gains FILE`` would: the same
torques and errors as the design's controller simulated directly, tracking within the design's own
thresholds. Each shipped impedance file records that it met them on its final check and its re-check
(200 + 200 draws), with a worst RMS at most 0.5 mrad.
"""
import json
from importlib import resources

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.cli.main import main
from fjm_runtime.control.design import Design
from fjm_runtime.sim.sensor import SensorModel

SHIPPED = sorted(p.name for p in resources.files("fjm_runtime.control").joinpath("designed").iterdir()
                 if "_impedance_" in p.name and "_joint_impedance_" not in p.name)


def test_the_arms_of_the_real_interface_have_their_impedance_design():
    assert {n.split("_impedance_")[0] for n in SHIPPED} == {"panda", "panda_hd", "baxter"}


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_impedance_designs_met_on_400_draws(name):
    d = Design.load(resources.files("fjm_runtime.control").joinpath("designed", name))
    rep = d.report
    assert d.kind == "impedance" and d.sensing == "full" and d.meets is True and d.predict is True
    assert d.same_sensor(SensorModel.franka_like())[0]
    assert rep["draws"] == 200 and rep["recheck"]["draws"] == 200 and rep["recheck"]["meets"] is True
    worst = max(rep["worst_case"]["rms_second_half"] + rep["recheck"]["worst_case"]["rms_second_half"])
    assert worst <= 0.5e-3
    row = [r for r in rep["comparison"] if r["law"] == "impedance"][0]
    assert row["rms"] == worst and row["diverged"] == 0 and row["runs"] == 400
    # what fjm simulate panda --noise franka_like --rate R --delay-samples D picks
    picked = Design.shipped_for_sensor(d.model, SensorModel.franka_like(seed=7), d.rate, d.delay)
    assert picked is not None and picked.file.endswith(name) and picked == d
    from fjm_runtime.sim.interface import interface_from_spec
    assert Design.shipped_for_sensor(d.model, SensorModel.franka_like(), d.rate, d.delay,
                                     interface_from_spec("motor")) == d
    franka = Design.shipped_for_sensor(d.model, SensorModel.franka_like(), d.rate, d.delay,
                                       interface_from_spec("franka"))
    assert franka is None or franka.kind == "joint_impedance"          # a motor design is not a franka one
    white = Design.shipped_for_sensor(d.model, SensorModel.panda_white(), d.rate, d.delay)
    assert white is None or white.kind != "impedance"


@pytest.mark.slow  # builds the Panda's impedance loop (C) on a cold cache
@pytest.mark.parametrize("rate,delay", [(None, None), (1000, 2), (500, 1)])
def test_simulate_under_franka_like_picks_the_shipped_design(capsys, rate, delay):
    """Without --rate / --delay-samples the 1 kHz delay-1 design; with them the design for those."""
    name = f"panda_impedance_{rate or 1000}hz_d{delay or 1}.json"
    assert name in SHIPPED, f"fjm_runtime/control/designed/{name} is not shipped"
    flags = [] if rate is None else ["--rate", str(rate), "--delay-samples", str(delay)]
    assert main(["simulate", "panda", "--noise", "franka_like", "--duration", "2", "--json", "--seed", "3", *flags]) == 0
    captured = capsys.readouterr()
    rep = json.loads(captured.out)
    s = rep["settings"]
    assert s["gains"] == f"fjm_runtime/control/designed/{name}"
    assert (s["controller"], s["sensing"], s["rate"], s["delay_samples"], s["predict"]) == \
        ("impedance", "full", float(rate or 1000), delay or 1, True)
    assert rep["designed_for_these_conditions"] is True and rep["diverged"] is False
    d = Design.shipped_for_sensor("panda", SensorModel.franka_like(), rate or 1000.0, delay or 1)
    m = fjm_runtime.load("panda")
    from fjm_runtime.sim.metrics import rms_second_half
    from fjm_runtime.sim.simulate import simulate
    ref = d.reference(m)
    r = simulate(m, d.controller(m), ref, duration=2.0, dt=1.0 / d.rate, x0=d.start_state(m),
                 sensor=SensorModel.franka_like(seed=3), delay_samples=d.delay, predict=True)
    assert np.allclose(rep["rms_second_half"], rms_second_half(r), rtol=1e-9, atol=0)
    assert max(rep["rms_second_half"]) <= 0.5e-3 and max(rep["time_at_limit"]) == 0.0
    assert "using the shipped design" in captured.err


JOINT = "panda_joint_impedance_1000hz_d1.json"


@pytest.mark.slow  # builds the Panda's joint-impedance loop (C) on a cold cache
def test_franka_interface_picks_the_shipped_joint_impedance_design(capsys):
    """The joint impedance for the franka interface (libfranka's filter and 1 N m per tick limit) met on 400
    draws within 0.5 mrad; fjm simulate panda --interface franka --noise franka_like runs it as designed."""
    assert JOINT in {p.name for p in resources.files("fjm_runtime.control").joinpath("designed").iterdir()}, \
        f"fjm_runtime/control/designed/{JOINT} is not shipped"
    d = Design.load(resources.files("fjm_runtime.control").joinpath("designed", JOINT))
    rep = d.report
    worst = max(rep["worst_case"]["rms_second_half"] + rep["recheck"]["worst_case"]["rms_second_half"])
    assert d.kind == "joint_impedance" and d.meets is True and rep["recheck"]["draws"] == 200 and worst <= 0.5e-3
    assert main(["simulate", "panda", "--interface", "franka", "--noise", "franka_like", "--duration", "2", "--json",
                 "--seed", "3"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["settings"]["gains"] == f"fjm_runtime/control/designed/{JOINT}"
    assert out["settings"]["controller"] == "joint_impedance" and out["designed_for_these_conditions"] is True
    assert max(out["rms_second_half"]) <= 0.5e-3 and max(out["time_at_limit"]) == 0.0
