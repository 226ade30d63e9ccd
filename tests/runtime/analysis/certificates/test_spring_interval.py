"""Lemma 1 for a nonlinear spring (fjm_runtime.analysis.certificates.spring_interval): what `fjm tune` certifies.

The certificate evaluates the law that runs at the states of its box, so it carries over to a spring
``psi`` with the paper's stiffness interval replaced by ``psi' in [k_min, k_max]`` over the deflections
those states reach and the parameter box, provided the deflections stay in the declared range. Checked
here independently of the code under test: the largest deflection from link1_hd's equations (the
cubic's real root), ``k_min``, ``k_max`` from ``psi' = k1 + 3 k3 phi^2`` written out, the reaching
condition on simulated trajectories at the corners of the box, and the refusal of a box that leaves
the declared range.
"""
import numpy as np
import pytest

import fjm_runtime as fjm
from fjm_runtime.analysis.certificates.certify import synthesize_gains
from fjm_runtime.cli.main import main
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import Sinusoid
from fjm_runtime.sim.simulate import simulate
from support.reaching import state_at, trajectory_check

BOX = {"k1": (60.0, 90.0), "k3": (2000.0, 3000.0)}
REF, E = Sinusoid(0.5, 1.0), (0.05, 0.5, 0.5, 0.5)


@pytest.fixture(scope="module")
def hd():
    return fjm.load("link1_hd")


@pytest.fixture(scope="module")
def gain(hd):
    return synthesize_gains(hd, None, param_box=BOX, reference_bounds=REF.derivative_bounds()[:, 0],
                            error_bounds=E, lam=8.0)


def test_stiffness_interval_is_the_springs_over_the_deflections_reached(hd, gain):
    assert gain.feasible, gain.reason
    d = hd.default_params
    R = REF.derivative_bounds()[:, 0]
    # the largest |phi| of a state in the box: J_l y3 = psi(phi) - M g0 L sin(q) at the box's extremes
    torque = d["J_l"] * (R[2] + E[2]) + d["M"] * d["g0"] * d["L"] * np.sin(min(R[0] + E[0], np.pi / 2))
    roots = np.roots([d["k3"], 0.0, d["k1"], -torque])
    phi = float(roots[np.argmin(np.abs(roots.imag))].real)
    st = gain.stiffness
    assert st["deflection"][0] == pytest.approx([-phi, phi], rel=1e-9)
    assert st["declared"] == [0.25] and st["outside"] == ""
    assert st["k_min"][0] == pytest.approx(60.0, rel=1e-12)                       # at phi = 0, k1 low
    assert st["k_max"][0] == pytest.approx(90.0 + 3 * 3000.0 * phi ** 2, rel=1e-9)  # at |phi| max, k1, k3 high
    assert fjm.load("link1") and synthesize_gains(
        fjm.load("link1"), None, param_box={"K": (100.0, 200.0)}, reference_bounds=R, error_bounds=E,
        lam=8.0).stiffness is None                                                # a linear spring: nothing to add


@pytest.mark.parametrize("true", [{"k1": 60.0, "k3": 2000.0}, {"k1": 90.0, "k3": 3000.0}])
def test_certified_gain_reaches_on_trajectories_at_the_corners(hd, gain, true):
    """The paper surface's sign law at the certified k_s, thin layer: sgn(s) s' <= -eta/2 inside the box."""
    dt = 1e-5
    delta = 5 * dt * gain.k_s
    ctrl = make_controller("smc", hd, None, lam=8.0, k_s=gain.k_s, delta=delta)
    x0 = state_at(hd, None, REF(0.0)[:4, 0] + 0.8 * np.asarray(E))
    res = simulate(hd, ctrl, REF, duration=0.05, dt=dt, true_params=true, x0=x0, backend="casadi",
                   interface="ideal")   # the certificate is for Spong's model with the torque applied at once
    trajectory_check(res, E, gain.eta[0], ctrl.c)


def test_a_box_beyond_the_declared_range_is_refused(capsys):
    """E3 = 60 rad/s^2 takes the states to |phi| = 0.26 rad > 0.25: no certificate, one stderr line, exit 1."""
    status = main(["tune", "link1_hd", "--param-box", "k1=60:90", "--param-box", "k3=2000:3000",
                   "--error-box", "0.05,0.5,60,5"])
    err = capsys.readouterr().err.strip()
    assert status == 1 and "\n" not in err
    assert "reach the deflection q_m - q = 0.26" in err and "beyond the declared range |phi| <= 0.25 rad" in err
