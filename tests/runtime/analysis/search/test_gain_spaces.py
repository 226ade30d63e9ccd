"""Each law's gain space (fjm_runtime.analysis.search.gain_spaces) and the laws compared side by side
(fjm_runtime.analysis.search.compare, ``fjm design --law auto``).

* The impedance grid places the motor's mode with the link held (``J_m s^2 + K_d s + K_p + (1 + K_T) K``) at
  the stated damping ratios and ``K_p`` at the stated share of the spring the motor feels; ``K_T`` moves keep
  ``K_T`` in [-0.8, 0].
* The impedance search meets the default thresholds on planar2 with Panda-like drives (K 5000 N m/rad,
  J_m 0.3 kg m^2; the planar models' own K 150 / J_m 2 leave the link mode undamped through the motor: about
  22 mrad) in a few draws.
* ``--law auto`` on that case prints one row per law and ships the law with the smallest worst RMS among
  those that meet; the file records the choice and the table, and its worst case is the chosen row's.
"""
import json

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.analysis.search.draws import default_spread
from fjm_runtime.analysis.search.gain_spaces import (GAIN_SPACES, IMPEDANCE_DAMPING, IMPEDANCE_K_T, IMPEDANCE_OMEGA_I,
                                                     IMPEDANCE_SHARES)
from fjm_runtime.analysis.search.settings import SearchSettings
from fjm_runtime.sim.sensor import SensorModel

#: Panda-like drives on planar2 (the controller's nominal and the draws' centre).
DRIVES = {"K1": 5000.0, "K2": 5000.0, "Jm1": 0.3, "Jm2": 0.3}


def test_impedance_grid_places_the_motor_mode():
    m = fjm_runtime.load("planar2")
    p = m.params_array(DRIVES)
    cands = GAIN_SPACES["impedance"].grid(m, p)
    assert len(cands) == len(IMPEDANCE_K_T) * len(IMPEDANCE_SHARES) * len(IMPEDANCE_DAMPING)
    seen = set()
    for g in cands:
        for j in range(2):
            K, Jm = 5000.0, 0.3
            k_t, K_p, K_d = g["K_T"][j], g["K_p"][j], g["K_d"][j]
            stiff = K_p + (1 + k_t) * K                       # the motor's spring with the link held still
            roots = np.roots([Jm, K_d, stiff])
            omega = abs(roots[0])
            zeta = -roots[0].real / omega
            assert omega == pytest.approx(np.sqrt(stiff / Jm), rel=1e-7)   # np.roots: about 1e-8
            seen.add((round(k_t, 6), round(K_p / ((1 + k_t) * K), 6), round(zeta, 6)))
            assert g["K_i"][j] == pytest.approx(IMPEDANCE_OMEGA_I * K_p, rel=1e-12)
    want = {(round(a, 6), round(b, 6), round(c, 6)) for a in IMPEDANCE_K_T for b in IMPEDANCE_SHARES
            for c in IMPEDANCE_DAMPING}
    assert seen == want


def test_torque_feedback_moves_stay_in_range():
    space = GAIN_SPACES["impedance"]
    g = {"K_p": [1.0, 2.0], "K_d": [3.0, 4.0], "K_T": [-0.7, 0.0], "K_i": [5.0, 6.0]}
    up = space.move(g, ("K_T", 1), 2.0)       # share 1 x 2 clipped to 1: K_T stays 0
    assert up["K_T"] == [-0.7, 0.0] and g["K_T"] == [-0.7, 0.0]
    down = space.move(g, ("K_T", 0), 0.5)     # share 0.3 x 0.5 = 0.15 clipped to 0.2: K_T = -0.8
    assert down["K_T"][0] == pytest.approx(-0.8, abs=1e-15)
    mid = space.move(g, ("K_T", 0), 2.0)      # share 0.6: K_T = -0.4
    assert mid["K_T"][0] == pytest.approx(-0.4, abs=1e-15)
    assert space.move(g, ("K_d", 1), 2.0)["K_d"] == [3.0, 8.0]
    assert space.coords(2) == [("K_p", 0), ("K_p", 1), ("K_d", 0), ("K_d", 1), ("K_T", 0), ("K_T", 1),
                               ("K_i", 0), ("K_i", 1)]


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_impedance_search_meets_on_planar2():
    from fjm_runtime.analysis.search.search import design
    from fjm_runtime.control.design import task_start
    from fjm_runtime.control.references import make_reference
    m = fjm_runtime.load("planar2")
    spread = default_spread(m, DRIVES)
    ref = make_reference("sine", 2, amplitude=0.5, omega=1.0)
    rec = design(m, SearchSettings(kind="impedance", sensor=SensorModel.panda_white(seed=5), draws=4, duration=2.0,
                                   spread=spread, screen_draws=3, screen_duration=1.0, rounds=1, max_extra_delay=1,
                                   recheck_draws=4, predict=True, threads=1, seed=5, reference=ref,
                                   x0=task_start(m, ref, "holding gravity", m.params_array(spread.nominal)),
                                   task={"kind": "sine"}), progress=lambda msg: None)
    print(f"planar2 impedance: worst RMS {rec['worst_case']['rms_second_half']}, "
          f"re-check {rec['recheck']['worst_case']['rms_second_half']}, gains {rec['gains']}")
    assert rec["kind"] == "impedance" and rec["sensing"] == "full"
    assert rec["meets"] is True and rec["recheck"]["meets"] is True and rec["worst_case"]["diverged"] == 0
    assert max(rec["worst_case"]["rms_second_half"] + rec["recheck"]["worst_case"]["rms_second_half"]) <= 2e-3
    assert all(-0.8 - 1e-12 <= k <= 0.0 for k in rec["gains"]["K_T"])


@pytest.mark.slow  # builds the batch steps (C) on a cold cache
def test_law_auto_prints_the_table_and_ships_the_best(tmp_path, capsys):
    from fjm_runtime.cli.main import main
    params = tmp_path / "drives.toml"
    params.write_text("[parameters]\n" + "".join(f"{k} = {v}\n" for k, v in DRIVES.items()))
    out = tmp_path / "d.json"
    rc = main(["design", "planar2", "--params", str(params), "--predict", "--draws", "3", "--duration", "1.5",
               "--screen-draws", "2", "--screen-duration", "0.5", "--rounds", "0", "--seed", "5",
               "--recheck-draws", "2", "--threads", "1", "--out", str(out)])
    err = capsys.readouterr().err
    rec = json.loads(out.read_text())
    rows = rec["comparison"]
    assert [r["law"] for r in rows] == ["impedance", "ismc", "fl"]
    assert rec["law_choice"] == {"asked": "auto", "laws": ["impedance", "ismc", "fl"], "chosen": rec["kind"]}
    meeting = [r for r in rows if r["meets"]]
    assert meeting and rc == 0 and rec["meets"] is True
    best = min(meeting, key=lambda r: r["rms"])
    assert rec["kind"] == best["law"]
    chosen = [r for r in rows if r["law"] == rec["kind"]][0]
    worst = max(rec["worst_case"]["rms_second_half"] + rec["recheck"]["worst_case"]["rms_second_half"])
    assert chosen["rms"] == worst and chosen["runs"] == 5 and chosen["diverged"] == 0
    table = [ln for ln in err.splitlines() if ln.startswith("fjm design: ") and " mrad" in ln]
    assert len(table) == 3
    for r, ln in zip(rows, table):
        assert ln.split()[2] == r["law"] and f"{r['rms'] * 1e3:.3g} mrad" in ln
        assert ("<- shipped" in ln) is (r["law"] == rec["kind"])
