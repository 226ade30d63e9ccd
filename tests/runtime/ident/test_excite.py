"""fjm excite: the chosen series beats a random one on conditioning and keeps within the limits."""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.cli.main import main as fjm_main
from fjm_runtime.ident.excite import (FourierReference, design_excitation, load_excitation, nominal_motion,
                                      regressor_condition)
from fjm_runtime.validation import FjmValueError


def test_derivatives_are_those_of_q_d():
    """Rows 1..4 are the time derivatives of row 0 (central differences), and q_d(0) = q0."""
    rng = np.random.default_rng(0)
    ref = FourierReference([0.2, -0.1], rng.standard_normal((2, 3)), rng.standard_normal((2, 3)), 2.0)
    np.testing.assert_allclose(ref(0.0)[0], [0.2, -0.1], atol=1e-15)
    t, h = 0.37, 1e-4
    R = ref.sample([t - h, t, t + h])
    for k in range(4):
        np.testing.assert_allclose((R[2, k] - R[0, k]) / (2 * h), R[1, k + 1], rtol=1e-6, atol=1e-6)


def test_best_of_many_beats_a_random_draw_and_respects_the_panda_limits():
    m = fjm_runtime.load("panda")
    one = design_excitation(m, 3.0, candidates=1, seed=3)
    best = design_excitation(m, 3.0, candidates=8, seed=3)
    assert best.condition <= one.condition
    t = np.arange(0.0, 3.0, 1e-3)
    motion = nominal_motion(m, best.reference, t, m.params_array())
    assert np.all(np.abs(motion["dq"]) <= 0.5 * m.velocity_limits + 1e-12)
    assert np.all(np.abs(motion["u"]) <= 0.8 * m.effort_limits + 1e-12)
    lo, hi = m.position_limits[:, 0], m.position_limits[:, 1]
    assert np.all(motion["q"] >= lo) and np.all(motion["q"] <= hi)
    assert regressor_condition(motion) == pytest.approx(best.condition)


def test_impossible_limits_are_refused():
    with pytest.raises(FjmValueError, match="smaller --amplitude or --base-freq"):
        design_excitation(fjm_runtime.load("panda"), 2.0, amplitude=0.5, base_freq=20.0, candidates=3)


def test_cli_writes_csv_and_coefficients(tmp_path, capsys):
    out = tmp_path / "traj.csv"
    assert fjm_main(["excite", "link1", "--duration", "4", "--out", str(out), "--candidates", "5"]) == 0
    text = capsys.readouterr().out
    assert "condition number" in text and "closed-loop check" in text
    data = np.genfromtxt(out, delimiter=",", names=True)
    ref = load_excitation(out)
    np.testing.assert_allclose(data["q_d_1"], ref.sample(data["t"])[:, 0, 0], rtol=0, atol=1e-12)
