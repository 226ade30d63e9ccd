"""fjm design on nonlinear springs: the TRUE plants scale each joint's whole spring curve.

A design draws each joint's stiffness; for a nonlinear law the drawn quantity is its small-deflection stiffness
(``K_1_j``, ``k1``) and every other coefficient that scales the torque follows it (``K_2``, ``K_3``, ``T_1``,
``T_2``; the blend width stays), so ``psi_j -> g_j psi_j`` exactly, the curve's shape and breakpoints kept.
Checked here on panda_hd's rows against the spring Function (the physics identity, not the code's rule), and
the helpers the design's analysis uses (input-gain scaling, respringing a state), and a design that runs on
arm1_hd end to end.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.analysis.search.draws import default_spread, draw_params
from fjm_runtime.analysis.sampled.sampled_linear import respring, scaled_stiffness
from fjm_runtime.cli.main import main

N = 7


@pytest.fixture(scope="module")
def hd():
    return fjm_runtime.load("panda_hd")


def _psi(m, phi, p):
    return np.asarray(m.spring_functions["spring"](phi, np.asarray(p, dtype=float))[0]).ravel()


def test_draws_scale_every_curve_by_one_factor(hd):
    p0 = np.asarray(hd.params_array(hd.default_params), dtype=float)
    rows = draw_params(hd, 30, seed=3, spread=default_spread(hd))
    names = list(hd.param_names)
    phi = np.linspace(-6e-3, 6e-3, 7) + 1.1e-3  # through both breakpoints of every curve
    seen = []
    for r, p in enumerate(rows):
        g = np.array([p[names.index(f"K_1_{j}")] / p0[names.index(f"K_1_{j}")] for j in range(1, N + 1)])
        seen.append(g)
        assert np.all((g >= 0.7 - 1e-12) & (g <= 1.3 + 1e-12))
        for v in phi:
            assert np.allclose(_psi(hd, np.full(N, v), p), g * _psi(hd, np.full(N, v), p0), rtol=1e-12, atol=1e-9)
        assert all(p[names.index(f"w_blend_{j}")] == p0[names.index(f"w_blend_{j}")] for j in range(1, N + 1))
        hd.f(np.zeros(4 * N), dict(zip(names, p)))  # every row is a valid drive (K order, blend limits)
    seen = np.array(seen)
    assert np.allclose(seen[0], 0.7) and np.allclose(seen[1], 1.3)  # the box's corners come first
    assert np.ptp(seen[9:], axis=0).min() > 0.3  # then independent draws per joint


def test_input_gain_scaling_and_respring_keep_the_physics(hd):
    p0 = np.asarray(hd.params_array(hd.default_params), dtype=float)
    rng = np.random.default_rng(1)
    for g in (0.4, 1.7):
        p = scaled_stiffness(hd, p0, g)
        phi = rng.uniform(-6e-3, 6e-3, N)
        assert np.allclose(_psi(hd, phi, p), g * _psi(hd, phi, p0), rtol=1e-12, atol=1e-9)
        q = rng.uniform(-1, 1, N)
        x = np.concatenate([q, rng.normal(0, 1, N), q + phi, rng.normal(0, 1, N)])
        y = respring(hd, x, p0, p)
        assert np.array_equal(y[:2 * N], x[:2 * N]) and np.array_equal(y[3 * N:], x[3 * N:])
        assert np.allclose(_psi(hd, y[2 * N:3 * N] - q, p), _psi(hd, phi, p0), rtol=1e-10, atol=1e-9)


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_design_runs_on_a_datasheet_spring(tmp_path, capsys):
    out = tmp_path / "g.json"
    rc = main(["design", "arm1_hd", "--law", "ismc", "--noise", "ideal", "--draws", "3", "--duration", "0.5", "--screen-draws", "3",
               "--screen-duration", "0.3", "--rounds", "1", "--seed", "2", "--recheck-draws", "0", "--out", str(out)])
    capsys.readouterr()
    rec = json.loads(out.read_text())
    assert rc in (0, 1) and rec["model"] == "arm1_hd" and rec["draws"] == 3
    assert set(rec["params"]["relative"]) == {"K_1", "Jm1"}  # the curve drawn by its first segment
    assert rec["margins"]["input_gain_range"] is not None and np.isfinite(rec["worst_case"]["cost"])
