"""The examples in examples/ are built and run, and their numbers checked against the Python runtime.

- examples/c: a C program including generated/link1/link1.h, evaluating
  link1_alpha and link1_beta at a state from the command line (built with the
  example's Makefile into a temp dir); its output equals fjm_runtime to 1e-12.
- examples/opti_mpc.py: a CasADi Opti point-to-point problem on the generated
  f and g; the solution must reach the target, obey the input bound, be
  reproduced by an independent NumPy RK4 of the runtime's xdot, and end in an
  equilibrium held by the physically right torque (M g0 L sin(q) for link1).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import fjm_runtime

from support.paths import REPO, load_example  # noqa: E402
pytestmark = pytest.mark.slow  # builds C, a wheel or derives in a subprocess: `pytest -m 'not slow'` skips it

EXAMPLES = REPO / "examples"


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


@pytest.fixture(scope="module")
def c_example(tmp_path_factory):
    out = tmp_path_factory.mktemp("c_example")
    # The example's own source is built with -Werror; the generated source's strictness is
    # tested (and reported) by tests/generated/test_c_sources.py, so here it only has to build.
    proc = subprocess.run(
        ["make", "-C", str(EXAMPLES / "c"), "alpha_beta", f"OUT={out}", "CC=gcc",
         "GEN_WARN=-std=c99 -Wall -pedantic"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    exe = out / "link1_alpha_beta"
    assert exe.is_file()
    return exe


def _run(exe, *values):
    proc = subprocess.run([str(exe), *[repr(float(v)) for v in values]], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    out = dict(line.split(" = ") for line in proc.stdout.strip().splitlines())
    return float(out["alpha"]), float(out["beta"])


def test_c_example_matches_python(c_example):
    m = fjm_runtime.load("link1")
    rng = np.random.default_rng(3)
    states = [np.zeros(4), np.array([0.3, 0.1, 0.2, -0.4])] + [rng.uniform(-3, 3, 4) for _ in range(5)]
    for x in states:  # default parameters (the example's built-in table must equal the manifest's)
        alpha, beta = _run(c_example, *x)
        assert alpha == pytest.approx(m.alpha(x)[0], rel=1e-12, abs=1e-12)
        assert beta == pytest.approx(m.beta(x)[0, 0], rel=1e-12)
    for x in states[:3]:  # explicit parameters, damping on
        p = np.array([m.default_params[k] for k in m.param_names]) * rng.uniform(0.5, 1.5, 7)
        p[m.param_names.index("B_m")] = 0.3
        alpha, beta = _run(c_example, *x, *p)
        assert alpha == pytest.approx(m.alpha(x, p)[0], rel=1e-12, abs=1e-12)
        assert beta == pytest.approx(m.beta(x, p)[0, 0], rel=1e-12)


def test_c_example_rejects_bad_arguments(c_example):
    for args in ([], ["1", "2", "3"], ["0", "0", "zero", "0"]):
        proc = subprocess.run([str(c_example), *args], capture_output=True, text=True)
        assert proc.returncode == 2 and proc.stderr, (args, proc.stdout)


def test_opti_example(tmp_path):
    out = tmp_path / "opti.json"
    proc = subprocess.run([sys.executable, str(EXAMPLES / "opti_mpc.py"), "--json", str(out)],
                          capture_output=True, text=True, env=_env(), cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "solved" in proc.stdout
    res = json.loads(out.read_text())
    m = fjm_runtime.load(res["model"])
    p = np.array(res["p"])
    X, U, dt = np.array(res["X"]), np.array(res["U"]), res["dt"]
    n, N = m.n, U.shape[1]
    assert res["success"]
    q_target = np.array(res["q_target"])
    assert np.allclose(q_target, np.pi / 2)
    # starts at rest hanging down, ends at rest at the target
    np.testing.assert_allclose(X[:, 0], 0, atol=1e-12)
    np.testing.assert_allclose(X[:n, -1], q_target, atol=1e-8)
    np.testing.assert_allclose(X[n:2 * n, -1], 0, atol=1e-8)
    np.testing.assert_allclose(X[3 * n:, -1], 0, atol=1e-8)
    # input bound respected and cost consistent with the controls
    assert np.abs(U).max() <= res["u_max"] + 1e-8
    assert res["cost"] == pytest.approx(dt * np.sum(U ** 2), rel=1e-8)

    # an independent NumPy RK4 on the runtime's xdot reproduces the trajectory
    def rk4(x, u, h):
        k1 = m.xdot(x, u, p)
        k2 = m.xdot(x + h / 2 * k1, u, p)
        k3 = m.xdot(x + h / 2 * k2, u, p)
        k4 = m.xdot(x + h * k3, u, p)
        return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    x = X[:, 0].copy()
    for k in range(N):
        x = rk4(x, U[:, k], dt)
        np.testing.assert_allclose(x, X[:, k + 1], rtol=1e-8, atol=1e-8)
    # ... and the plan is physically right: a 20x finer integration lands near the target too
    x = X[:, 0].copy()
    for k in range(N):
        for _ in range(20):
            x = rk4(x, U[:, k], dt / 20)
    assert np.abs(x[:n] - q_target).max() < 1e-2, x

    # the final state is an equilibrium held by u_hold = M g0 L sin(q) (link1's static torque)
    u_hold = np.array(res["u_hold"])
    np.testing.assert_allclose(m.xdot(X[:, -1], u_hold, p), 0, atol=1e-8)
    if res["model"] == "link1":
        P = dict(zip(m.param_names, p))
        assert u_hold[0] == pytest.approx(P["M"] * P["g0"] * P["L"] * np.sin(q_target[0]), rel=1e-8)


def test_c_example_single_precision(tmp_path):
    """The example also builds with -Dcasadi_real=float and agrees with Python to float accuracy."""
    proc = subprocess.run(
        ["make", "-C", str(EXAMPLES / "c"), "alpha_beta", f"OUT={tmp_path}", "CC=gcc", "CFLAGS=-O2 -Dcasadi_real=float",
         "GEN_WARN=-std=c99 -Wall -pedantic"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    m = fjm_runtime.load("link1")
    x = np.array([0.3, 0.1, 0.2, -0.4], dtype=np.float32).astype(float)
    alpha, beta = _run(tmp_path / "link1_alpha_beta", *x)
    assert alpha == pytest.approx(m.alpha(x)[0], rel=1e-5)
    assert beta == pytest.approx(m.beta(x)[0, 0], rel=1e-5)
    assert alpha != m.alpha(x)[0], "single-precision build gave the double result: casadi_real=float ignored?"


def test_mujoco_closed_loop_example(capsys):
    """examples/mujoco_closed_loop.py (short run): the loop tracks, and MuJoCo's trajectory is fjm's plant's."""
    out = load_example("mujoco_closed_loop").main(["--duration", "0.3"])
    assert out["gap"] < 1e-8
    assert np.all(out["rms"][:4] < 1e-2) and out["max_error"] < 0.5
    assert "RMS tracking error" in capsys.readouterr().out


def test_nonlinear_spring_example_measures_what_the_docs_say(capsys):
    """examples/nonlinear_spring_laws.py (docs/real-drives.md): the law derived for the cubic spring beats both
    linear-spring laws, and on a plant with motor friction the nominal friction fed forward (30 % low)
    beats the same law without it; every law holds (none diverges). arm1_hd's section: see below."""
    out = load_example("nonlinear_spring_laws").main(["--draws", "3"])
    cubic = out["derived for the cubic spring"]
    linear = [v for k, v in out.items() if k.startswith("linear spring")]
    assert len(linear) == 2 and cubic < min(linear)
    fed, bare = out["friction fed forward (nominal 30 % low)"], out["no friction compensation"]
    assert fed < bare and max(fed, bare) < 2e-2
    assert "diverged" not in capsys.readouterr().out
    # arm1_hd, Franka-like loop: torque sensing holds whatever the law's spring; the friction feedforward
    # halves the worst case; the state-sensed law derived for the curve does not hold every drive
    curve, lin, bare = (out[f"torque: {k}"] for k in ("derived for the curve", "linear spring K_1",
                                                      "curve, no friction feedforward"))
    assert curve < 1e-2 and abs(curve - lin) < 0.5 * curve and bare > 1.5 * curve
    assert out["state: derived for the curve"] > 10 * curve
