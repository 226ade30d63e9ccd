"""Motor-side PD with gravity compensation (Tomei): the regulation baseline.

The emitted ``<model>_control_pdg`` (``derive/emit/torque.py``) computes, with NOMINAL
parameters only::

    q_d  = r[0:n]                                  (set point; the other rows of r are unused)
    q_md = q_d + K_nom^-1 G(q_d)                   static motor set point
    u    = K_p (q_md - q_m) - K_d dq_m + G(q_d)    G(q) = h(q, 0): gravity torque

It reads only ``q_m`` and ``dq_m`` of ``x`` (a motor-side law: no link sensor, no
torque sensor). Its outputs follow the other laws' signature so every runtime path
calls it the same way: ``s = q_md - q_m`` (motor-position error, rad), ``z_dot`` empty,
``y_hat = [q; dq; 0; 0]`` (the measured link position and rate, a placeholder for the
linearizing coordinates: so ``e[0]`` of a sample is the link error ``q - q_d``).

At the set point with the true stiffness ``K`` the links rest at
``q = q_d + (K_nom^-1 - K^-1) G(q_d)`` to first order in the stiffness error (gravity
is balanced by the spring); with ``K = K_nom`` exactly at ``q_d``.
"""
from __future__ import annotations

import numpy as np

from ..validation import FjmValueError, joint_vector
from .laws import SlidingModeController

__all__ = ["MotorPDGravityController"]


class MotorPDGravityController(SlidingModeController):
    """Tomei's motor PD + gravity compensation for regulation (``make_controller('pdg', ...)``).

    Parameters
    ----------
    model : Model
        Loaded model (the emitted ``control_pdg`` is used).
    nominal_params : dict or array_like
        NOMINAL parameters (``K_nom`` and the gravity model).
    k_p : float or array_like, shape (n,)
        Motor position gain, N m/rad, > 0.
    k_d : float or array_like, shape (n,)
        Motor rate gain, N m s/rad, > 0.
    u_max : float or array_like, shape (n,), optional
        Torque limit in N m (> 0); ``None`` = unlimited.

    The controller is stateless (``n_states = 0``), reads the plant state
    (``sensing = 'state'``, ``measurement_size = 4n``) and uses only its ``q_m``, ``dq_m``.
    """

    def __init__(self, model, nominal_params, *, k_p, k_d, u_max=None):
        self.model = model
        self.n = n = int(model.n)
        self.p_nom = np.asarray(model.params_array(nominal_params, arg="nominal_params"), dtype=float)
        if not np.all(np.isfinite(self.p_nom)):
            raise FjmValueError(f"nominal_params = {self.p_nom.tolist()}: expected finite values")
        self.k_p = joint_vector(k_p, n, "k_p", minimum=0.0, strict=True)
        self.k_d = joint_vector(k_d, n, "k_d", minimum=0.0, strict=True)
        self.u_max = None if u_max is None else joint_vector(u_max, n, "u_max", minimum=0.0, strict=True)
        self.sensing = "state"
        self.mode = "pdg"
        self.integral = False
        self.n_states = 0

    @property
    def law_kind(self) -> str:
        return "pdg"

    def gain_values(self) -> dict:
        """The gains of ``control_pdg`` by the names of its manifest layout."""
        return {"k_p": self.k_p, "k_d": self.k_d,
                "u_max": self.u_max if self.u_max is not None else np.ones(self.n),
                "limit": float(self.u_max is not None)}
