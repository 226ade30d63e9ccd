"""The link1 case of the certificate tests: the demo's stiffness box and tasks, and alpha_hat - alpha by hand."""
import numpy as np

from fjm_runtime.control.references import Sinusoid, SmoothStep

#: Nominal stiffness of the controller (N m/rad).
K_NOM = 150.0
#: The paper's stiffness interval (N m/rad).
K_BOX = {"K": (100.0, 200.0)}
#: (reference, error region E (4,)) of the demo's regulation task.
REG = (SmoothStep(1.0, rise_time=2.0), (0.05, 0.1, 0.5, 1.0))
#: (reference, error region E (4,)) of the demo's tracking task.
TRK = (Sinusoid(0.5, 1.0), (0.05, 0.5, 0.5, 0.5))


def delta_alpha_closed_form(y1, y2, y3, K, Kn, Jl=1.0, Jm=2.0, mgl=9.8):
    """alpha(x; Kn) - alpha(x; K) at x = T^-1(y; K) for link1 with B_m = 0 (derived by hand)."""
    G = mgl / Jl
    d = 1.0 / K - 1.0 / Kn
    return d * (Jl * Jm * G * np.sin(y1) * (y2 ** 2 + G * np.cos(y1)) + Kn * (Jl + Jm) * (y3 + G * np.sin(y1)))

