"""Plant draws of the gain search (fjm_runtime.analysis.search.draws): corners then the box, the default spread,
the parameter file's nominal and spread, and its one-line errors."""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.analysis.search.draws import draw_params, load_params_file
from fjm_runtime.drives import drive_indices, linear_stiffness_indices
from fjm_runtime.validation import FjmValueError


def test_draws_corners_then_box():
    m = fjm_runtime.load("panda")
    P = draw_params(m, 40, seed=3)
    p0 = np.asarray(m.params_array({}))
    iK, iJ = linear_stiffness_indices(m, "the draws"), drive_indices(m, "rotor_inertia")
    kr, jr = P[:, iK] / p0[iK], P[:, iJ] / p0[iJ]
    assert np.allclose(kr[0], 0.7) and np.allclose(kr[1], 1.3)
    assert np.allclose(kr[2], [0.7, 1.3] * 3 + [0.7])
    assert np.allclose(jr[3:6], 0.8) and np.allclose(jr[6:9], 1.2)
    iL = m.param_names.index("m_load")
    assert np.all(P[:3, iL] == 0) and np.all(P[3:9, iL] == 1.0)
    assert np.all((kr[9:] >= 0.7) & (kr[9:] <= 1.3)) and np.all((jr[9:] >= 0.8) & (jr[9:] <= 1.2))
    assert np.all((P[9:, iL] >= 0) & (P[9:, iL] <= 1)) and np.ptp(kr[9:]) > 0.3
    assert np.array_equal(P, draw_params(m, 40, seed=3)) and not np.array_equal(P, draw_params(m, 40, seed=4))


def _former_draws(model, count, seed):
    """The hard-coded box of the former design.py, verbatim: the reference the default spread must equal."""
    n = int(model.n)
    iK, iJ = linear_stiffness_indices(model, "the draws"), drive_indices(model, "rotor_inertia")
    p0 = np.asarray(model.params_array({}), dtype=float)
    iL = list(model.param_names).index("m_load") if "m_load" in model.param_names else None
    alt = np.where(np.arange(n) % 2 == 0, 0.7, 1.3)
    corners = [(np.full(n, 0.7), 1.0, 0.0), (np.full(n, 1.3), 1.0, 0.0), (alt, 1.0, 0.0)]
    corners += [(k, jm, 1.0) for jm in (0.8, 1.2) for k in (np.full(n, 0.7), np.full(n, 1.3), alt)]
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(count):
        if i < len(corners):
            ks, js, load = corners[i][0], np.full(n, corners[i][1]), corners[i][2]
        else:
            ks, js, load = rng.uniform(0.7, 1.3, n), rng.uniform(0.8, 1.2, n), rng.uniform(0.0, 1.0)
        p = p0.copy()
        p[iK] *= ks
        p[iJ] *= js
        if iL is not None:
            p[iL] = load
        rows.append(p)
    return np.vstack(rows)


@pytest.mark.parametrize("name", ["panda", "link1", "planar2"])
def test_default_spread_draws_the_former_box_bit_for_bit(name):
    m = fjm_runtime.load(name)
    assert np.array_equal(draw_params(m, 30, seed=3), _former_draws(m, 30, 3))


def _write(tmp_path, text, name="p.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_params_file_sets_the_nominal_and_the_spread(tmp_path):
    m = fjm_runtime.load("planar2")
    path = _write(tmp_path, """
[parameters]
K1 = { default = 300.0, unit = "N m/rad" }
Jm2 = 1.5

[spread]
stiffness = 0.1
K2 = 0.25
Jm1 = [1.0, 3.0]
m1 = 0.05
""")
    s = load_params_file(path, m)
    assert s.nominal["K1"] == 300.0 and s.nominal["Jm2"] == 1.5 and s.nominal["K2"] == 150.0
    assert s.overrides == {"K1": 300.0, "Jm2": 1.5} and s.source == str(path)
    P = draw_params(m, 400, seed=1, spread=s)
    col = {k: P[:, m.param_names.index(k)] for k in ("K1", "K2", "Jm1", "Jm2", "m1", "m2")}
    # corners: stiffness low, high, alternating (K1 by its group's 0.1, K2 by its own 0.25)
    assert col["K1"][:3] == pytest.approx([270.0, 330.0, 270.0])
    assert col["K2"][:3] == pytest.approx([112.5, 187.5, 187.5])
    assert col["Jm1"][:3] == pytest.approx([1.0] * 3) and col["Jm1"][3:9] == pytest.approx([3.0] * 6)  # absolute
    assert col["Jm2"][3:6] == pytest.approx([1.2] * 3) and col["Jm2"][6:9] == pytest.approx([1.8] * 3)
    assert col["m1"][:3] == pytest.approx([1.0] * 3) and col["m1"][3:6] == pytest.approx([0.95] * 3)
    r = slice(9, None)
    assert 270 <= col["K1"][r].min() and col["K1"][r].max() <= 330 and np.ptp(col["K1"][r]) > 50
    assert 112.5 <= col["K2"][r].min() and col["K2"][r].max() <= 187.5 and np.ptp(col["K2"][r]) > 60
    assert 1.0 <= col["Jm1"][r].min() and col["Jm1"][r].max() <= 3.0 and np.ptp(col["Jm1"][r]) > 1.8
    assert 0.95 <= col["m1"][r].min() and col["m1"][r].max() <= 1.05 and np.ptp(col["m1"][r]) > 0.09
    assert np.all(col["m2"] == 1.0)                                    # not in [spread]: the nominal
    fresh = draw_params(m, 40, seed=1, spread=s, fresh=True)
    assert not np.any(np.all(np.isclose(fresh[:, None, :], P[None, :40, :]), axis=2))   # no row shared
    assert 270 <= fresh[:, m.param_names.index("K1")].min()


@pytest.mark.parametrize("text, must", [
    ("[parameters]\nK9 = 1.0\n", ["p.toml:2: parameters.K9", "not a parameter of planar2"]),
    ("[parameters]\nK1 = \"stiff\"\n", ["p.toml:2: parameters.K1", "expected a finite number"]),
    ("[parameters]\nK1 = { default = 200.0, unit = \"Nm/deg\" }\n", ["p.toml:2: parameters.K1", "'N m/rad'"]),
    ("[parameters]\nK1 = -5.0\n", ["p.toml:2: parameters.K1", "> 0"]),
    ("\n[spread]\nstiffness = 1.5\n", ["p.toml:3: spread.stiffness", "0 <= s < 1"]),
    ("[spread]\nstiffness = [0.5, 1.5]\n", ["p.toml:2: spread.stiffness", "relative half-width"]),
    ("[spread]\nJm1 = [3.0, 1.0]\n", ["p.toml:2: spread.Jm1", "lo <= hi"]),
    ("[spread]\nbogus = 0.1\n", ["p.toml:2: spread.bogus", "not a group"]),
    ("[nominal]\nK1 = 1.0\n", ["p.toml:1: [nominal]", "[parameters] and/or [spread]"]),
    ("[parameters\nK1 = 1.0\n", ["p.toml", "not valid TOML"]),
])
def test_params_file_errors_are_one_line_naming_file_line_key(tmp_path, text, must):
    m = fjm_runtime.load("planar2")
    path = _write(tmp_path, text)
    with pytest.raises(FjmValueError) as info:
        load_params_file(path, m)
    msg = str(info.value)
    assert "\n" not in msg, msg
    for word in must:
        assert word.replace("p.toml", str(path)) in msg or word in msg, (word, msg)
    assert str(path) in msg
