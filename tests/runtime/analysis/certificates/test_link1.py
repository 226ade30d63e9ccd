"""The link1 closed forms (fjm_runtime.analysis.certificates.link1) against the generated model."""
import numpy as np
import pytest

from fjm_runtime.analysis.certificates.link1 import link1_alpha, link1_T_inverse


def test_closed_forms_match_generated_model(link1):
    rng = np.random.default_rng(0)
    for _ in range(20):
        p = {"K": rng.uniform(80, 250), "J_l": rng.uniform(0.5, 2), "J_m": rng.uniform(1, 3), "B_m": rng.uniform(0, 1)}
        x = rng.normal(size=4)
        assert link1_alpha(x, p) == pytest.approx(link1.alpha(x, p)[0], rel=1e-10, abs=1e-10)
        assert link1_T_inverse(link1.T(x, p), p) == pytest.approx(x, abs=1e-10)
        # errata 2: beta = J_l J_m / K (the paper's T3/T4 with K/J_m would give something else)
        assert link1.beta(x, p)[0, 0] == pytest.approx(p["J_l"] * p["J_m"] / p["K"], rel=1e-12)
