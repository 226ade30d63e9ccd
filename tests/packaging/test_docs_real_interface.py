"""docs/real-interface.md quotes the demo's real-interface section, not numbers typed from memory.

* Its two marked tables (``<!-- fjm:demo:real-interface -->``, ``<!-- fjm:demo:real-interface-sensing -->``)
  list the section's laws in its order, on their interfaces, with numeric cells; the exhaustive test re-runs
  the section at its documented scale (what ``make demo`` writes into out/summary.md) and requires the
  blocks to equal its tables line for line.
* The settings the page states (plants, duration, pole of fl_tau) are the section's constants.
* The sensed jerk it quotes (about 71 N m/s) is the standard deviation of the 1 ms difference of the
  franka_like tau_J noise, from the preset's level and from the generated noise itself.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from fjm_runtime.experiments import real_interface as ri
from fjm_runtime.experiments.settings import DemoContext
from fjm_runtime.sim.sensor import SensorModel, noise_array
from support.paths import REPO

PAGE = REPO / "docs" / "real-interface.md"


def block(text: str, name: str) -> list:
    """The lines between ``<!-- fjm:demo:NAME -->`` and its closing marker."""
    m = re.search(rf"<!-- fjm:demo:{name} -->\n(.*?)\n<!-- /fjm:demo:{name} -->", text, re.S)
    assert m, f"docs/real-interface.md has no block {name}"
    return m.group(1).splitlines()


def cells(line: str) -> list:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def test_blocks_list_the_sections_laws_with_numbers():
    text = PAGE.read_text(encoding="utf-8")
    main = block(text, "real-interface")
    assert main[:2] == ri.table({})
    rows = [cells(line) for line in main[2:]]
    assert [(r[0], r[1]) for r in rows] == [(label, iface) for label, (_k, iface) in ri.LAWS.items()]
    sensing = [cells(line) for line in block(text, "real-interface-sensing")[2:]]
    assert [r[0] for r in sensing] == [f"{law}, {name}" for law in ri.FOURTH_ORDER for name in ri.SENSORS]
    for r in rows + sensing:
        values = [float(c) for c in r[2:6]]
        assert all(math.isfinite(v) and v >= 0 for v in values), r
        done, runs = (int(v) for v in r[6].split(" / "))
        assert 0 <= done <= runs
    # the impedance laws hold on every plant; the table says so
    for r in rows:
        if r[0] in ("impedance (shipped design)", "joint_impedance (shipped design)"):
            assert r[6] == f"0 / {ri.N_RANDOM + 3}", r


def test_stated_settings_are_the_sections(panda):
    text = PAGE.read_text(encoding="utf-8")
    n = len(ri.plants(panda, ri.N_RANDOM))
    words = {3: "three", 4: "four", 5: "five", 6: "six", 7: "Seven"}
    assert f"{words[n]} TRUE plants" in text and f"{words[ri.N_RANDOM]} random draws" in text
    assert f"{ri.DURATION:g} s per run" in text and f"{ri.FL_LAM:g} rad/s" in text
    assert f"{ri.RATE / 1000:g} kHz, one sample of computation delay with prediction" in text


def test_sensed_jerk_is_the_difference_of_the_torque_noise():
    text = PAGE.read_text(encoding="utf-8")
    quoted = float(re.search(r"about\s+(\d+) N m/s", text).group(1))
    sensor = SensorModel.franka_like(seed=11)
    T = 1.0 / ri.RATE
    assert quoted == round(math.sqrt(2.0) * sensor.tau_J / T)
    levels = sensor.levels("torque", 7)
    noise = noise_array(sensor, "torque", 7, 20001)[:, levels == sensor.tau_J]
    measured = float(np.std(np.diff(noise, axis=0)) / T)
    assert abs(measured - quoted) <= 0.03 * quoted  # 7 x 20000 samples: about 0.3 % standard error


@pytest.mark.exhaustive
def test_blocks_equal_the_section_at_its_documented_scale(tmp_path):
    """The section as ``make demo`` runs it (compiled backend, 7 plants, 3 s): its two tables are the blocks."""
    ctx = DemoContext(out=tmp_path, duration=1.0, quick=False, n_mc=1, progress=lambda msg: None, results={})
    ri.real_interface_section(ctx)
    text = PAGE.read_text(encoding="utf-8")
    assert block(text, "real-interface") == ri.table(ctx.results["real_interface"]), \
        "docs/real-interface.md: copy the table of out/summary.md (section 'Which law on which interface')"
    assert block(text, "real-interface-sensing") == ri.table(ctx.results["real_interface_sensing"])


def test_shipped_designs_block_is_read_from_the_files():
    """The page's table of shipped designs is the one rendered from the design files, row for row."""
    from fjm_runtime.experiments import shipped_designs
    text = PAGE.read_text(encoding="utf-8")
    assert block(text, "shipped-designs") == shipped_designs.table(), \
        "docs/real-interface.md: copy the shipped-designs table of out/summary.md"


def test_user_arm_design_block_is_read_from_the_example_file():
    """The UR5e row is the example design file's record; the time the page quotes is the file's own."""
    from fjm_runtime.experiments import shipped_designs
    path = REPO / "examples" / "ur5e" / "ur5e_impedance_1000hz_d1.json"
    text = PAGE.read_text(encoding="utf-8")
    assert block(text, "user-arm-design") == shipped_designs.table([path])
    rec = __import__("json").loads(path.read_text())
    assert f"{rec['wall_seconds']:.0f} s on a cold cache" in text
    assert f"needs {rec['predict_substeps']} RK4 substeps" in text
    compared = [r for r in rec["comparison"] if r["law"] in ("ismc", "fl")]
    assert all(r["compared"] and not r["meets"] for r in compared)
    assert f"{max(100 * r['at_limit'] for r in compared):.0f} % of the time at a torque limit" in text
