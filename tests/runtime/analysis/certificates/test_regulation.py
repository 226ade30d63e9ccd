"""Closed-loop eigenvalues at rest (fjm_runtime.analysis.certificates.regulation)."""
import numpy as np
import pytest



def test_closed_loop_eigenvalues_exact_parameters_give_designed_poles(link1):
    from fjm_runtime.control.factory import make_controller
    from fjm_runtime.analysis.certificates.regulation import closed_loop_eigenvalues
    fl = make_controller("fl", link1, {}, lam=8.0)
    ev = closed_loop_eigenvalues(link1, fl, {})
    # quadruple pole at -8: a repeated root is ill-conditioned, so compare the characteristic polynomial
    assert np.real(np.poly(ev)) == pytest.approx([1, 32, 384, 2048, 4096], rel=1e-5)
    smc = make_controller("smc", link1, {}, lam=8.0, k_s=1000.0, delta=5.0)
    ev = closed_loop_eigenvalues(link1, smc, {})
    # inside the layer: triple pole at -8 and the s-pole at -k_s/delta = -200
    assert np.real(np.poly(ev)) == pytest.approx(np.poly([-8, -8, -8, -200]), rel=1e-5)
    # wrong stiffness moves the poles (and the chains can go unstable, see the demo)
    assert closed_loop_eigenvalues(link1, fl, {"K": 100.0})[0].real > -8.0 + 0.5
