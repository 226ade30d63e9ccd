"""Motor-side impedance with joint-torque feedback about the flatness feedforward (the ``motor`` interface).

The emitted ``<model>_control_impedance`` (``derive/emit/controls.py``) reads everything a torque-sensed
arm reports, ``m = [q; dq; q_m; dq_m; tau_J; dtau_J]`` (6n, ``sensing = 'full'``), and computes with
NOMINAL parameters only::

    (tau_Jd, theta_d, dtheta_d, _, u_ff) = feedforward(r; p_nom)          the flatness feedforward
    u_cmd = u_ff + K_p (theta_d - q_m) + K_d (dtheta_d - dq_m) + K_T (tau_Jd - tau_J) + K_i z
    u     = clip(u_cmd, -u_max, u_max),     z' = q_d - q  (frozen at the limit, conditional integration)

No jerk and no fourth derivative of a measured signal: the law is collocated on the motor (Albu-Schaeffer,
Ott and Hirzinger, "A unified passivity-based control framework for position, torque and impedance control
of flexible joint robots", IJRR 26(1), 2007), the reference reaches it through the feedforward. The torque
feedback ``K_T`` scales the spring torque the motor feels by ``1 + K_T``: with ``K_T = -0.7`` the motor
behaves as if ``1 / 0.3 = 3.3`` times heavier, which moves the motor-spring mode below the velocity
filter of a differentiated encoder (DESIGN notes: without it 6 of 11 Panda plants diverged).

Default gains (:func:`default_impedance_gains`), per joint from the nominal model (``K``: the spring's
small-deflection stiffness, ``J_m`` the rotor inertia)::

    K_T = -0.7
    K_p = (1 + K_T) K / 3                                   a third of the spring stiffness the motor feels
    K_d = 2 zeta sqrt(J_m (K_p + (1 + K_T) K)),  zeta = 0.7 the motor's mode with the link held still
    K_i = K_p omega_i,  omega_i = 2 pi rad/s                a slow link integral (1 Hz)

On the Panda (``K`` 1e4 / 3e3 N m/rad, ``J_m`` 0.3 / 0.1 kg m^2) this gives ``K_p`` 1000 / 300 N m/rad: the
prototype's joints 1-4 (K_p 1000, its torque-feedback -0.7) with its damping raised from 0.5 to 0.7.

Regulation (a constant reference ``q_d``): the feedforward is already the exact gravity compensation on the motor
side. With every derivative of ``q_d`` zero, the rigid inverse dynamics is ``tau_Jd = g(q_d)`` and
``theta_d = q_d + psi^-1(g(q_d))``, ``u_ff = tau_Jd``: the motor position whose spring holds the link at ``q_d``
against gravity, the fixed point ``theta_d = q_bar + psi^-1(g(q_bar))`` at ``q_bar = q_d`` that Ott, Albu-Schaeffer,
Kugi and Hirzinger ("On the passivity-based impedance control of flexible joint robots", IEEE TRO 24(2), 2008)
reach by iterating ``q_bar <- theta - psi^-1(g(q_bar))`` (no iteration is needed when ``q_d`` is given). That
equilibrium is the link's unique one near ``q_d`` when the iteration contracts there,
``rho = || diag(psi'(phi_d))^-1 dg/dq(q_d) ||_2 < 1`` (the spring dominates the gravity gradient):
:func:`regulation_contraction` gives ``rho``, :func:`regulation_motor_position` refuses a set point where it fails.
"""
from __future__ import annotations

import math

import numpy as np

from ..drives import drive_indices, model_springs
from ..validation import REDERIVE, FjmValueError, joint_vector
from .laws import SlidingModeController

__all__ = ["DEFAULT_DAMPING", "DEFAULT_INTEGRAL_RATIO", "DEFAULT_K_T", "DEFAULT_OMEGA_I", "DEFAULT_STIFFNESS_SHARE",
           "ImpedanceController", "JointImpedanceController", "default_impedance_gains",
           "default_joint_impedance_gains", "regulation_contraction", "regulation_motor_position"]

#: Joint-torque feedback of the default gains (1): the motor feels 0.3 of the spring torque.
DEFAULT_K_T = -0.7
#: Damping ratio of the motor's mode with the link held still.
DEFAULT_DAMPING = 0.7
#: Corner of the link integral, rad/s (``K_i = K_p omega_i``).
DEFAULT_OMEGA_I = 2 * math.pi


def default_impedance_gains(model, nominal_params) -> dict:
    """The default ``K_p``, ``K_d``, ``K_T``, ``K_i`` per joint (module docstring), each shape (n,).

    Parameters
    ----------
    model : Model
    nominal_params : dict or array_like
        Nominal parameters (their stiffness and rotor inertia per joint are used).

    Returns
    -------
    dict
        ``K_p`` (N m/rad), ``K_d`` (N m s/rad), ``K_T`` (1), ``K_i`` (N m/(rad s)).
    """
    p = np.asarray(model.params_array(nominal_params, arg="nominal_params"), dtype=float)
    K = p[drive_indices(model, "stiffness")]
    Jm = p[drive_indices(model, "rotor_inertia")]
    K_T = np.full(model.n, DEFAULT_K_T)
    K_p = (1 + K_T) * K / 3
    K_d = 2 * DEFAULT_DAMPING * np.sqrt(Jm * (K_p + (1 + K_T) * K))
    return {"K_p": K_p, "K_d": K_d, "K_T": K_T, "K_i": K_p * DEFAULT_OMEGA_I}


class ImpedanceController(SlidingModeController):
    """Motor-side impedance with torque feedback and a link integral (``make_controller('impedance', ...)``).

    Parameters
    ----------
    model : Model
        Loaded reduced model (its emitted ``control_impedance`` and ``feedforward`` are used).
    nominal_params : dict or array_like
        NOMINAL parameters (the feedforward's model).
    K_p, K_d, K_i : float or array_like, shape (n,), optional
        Motor position gain (N m/rad), motor rate gain (N m s/rad), link-integral gain (N m/(rad s)), each
        >= 0; default :func:`default_impedance_gains`.
    K_T : float or array_like, shape (n,), optional
        Joint-torque feedback (1), > -1 (``1 + K_T`` is the share of the spring torque the motor feels);
        default -0.7.
    u_max : float or array_like, shape (n,), optional
        Torque limit in N m (> 0); ``None`` = unlimited.
    anti_windup : bool
        Freeze joint ``i``'s integral while ``u_cmd_i`` is beyond ``u_max_i`` and ``q_d_i - q_i`` pushes it
        further (default True).

    The controller reads ``m = [q; dq; q_m; dq_m; tau_J; dtau_J]`` (``sensing = 'full'``,
    ``measurement_size = 6n``) and holds ``z`` (n), the integral of ``q_d - q``.
    """

    def __init__(self, model, nominal_params, *, K_p=None, K_d=None, K_T=None, K_i=None, u_max=None,
                 anti_windup: bool = True):
        self.model = model
        self.n = n = int(model.n)
        if self.law_kind not in (model.manifest.get("controls") or {}):
            raise FjmValueError(f"model {model.name}: no emitted {self.law_kind} law (a complete model, or "
                                f"generated by an older fjm: {REDERIVE})")
        self.p_nom = np.asarray(model.params_array(nominal_params, arg="nominal_params"), dtype=float)
        if not np.all(np.isfinite(self.p_nom)):
            raise FjmValueError(f"nominal_params = {self.p_nom.tolist()}: expected finite values")
        defaults = default_impedance_gains(model, self.p_nom)
        given = {"K_p": K_p, "K_d": K_d, "K_i": K_i}
        for name, value in given.items():
            v = defaults[name] if value is None else value
            setattr(self, name, joint_vector(v, n, name, minimum=0.0, strict=False))
        self.K_T = joint_vector(defaults["K_T"] if K_T is None else K_T, n, "K_T", minimum=-1.0, strict=True)
        self.u_max = None if u_max is None else joint_vector(u_max, n, "u_max", minimum=0.0, strict=True)
        self.anti_windup = bool(anti_windup)
        self.sensing = "full"
        self.mode = "impedance"
        self.integral = True
        self.n_states = n

    @property
    def law_kind(self) -> str:
        return "impedance"

    def gain_values(self) -> dict:
        """The gains of ``control_impedance`` by the names of its manifest layout."""
        return {"K_p": self.K_p, "K_d": self.K_d, "K_T": self.K_T, "K_i": self.K_i,
                "u_max": self.u_max if self.u_max is not None else np.ones(self.n),
                "limit": float(self.u_max is not None), "anti_windup": float(self.anti_windup)}


#: Joint-impedance default stiffness as a share of the joint's spring (Panda: 1667 / 500 N m/rad, near 3x
#: Franka's example 600 / 250 / 150 / 50 N m/rad, with which a modelled Franka layer reached 0.44-0.47 mrad).
DEFAULT_STIFFNESS_SHARE = 1.0 / 6.0
#: Integral gain of the joint-impedance default as a multiple of its stiffness (the same prototype's 3 K_q), 1/s.
DEFAULT_INTEGRAL_RATIO = 3.0


def default_joint_impedance_gains(model, nominal_params) -> dict:
    """The default ``K_q``, ``D_q``, ``K_i`` of :class:`JointImpedanceController` per joint, each shape (n,).

    ``K_q = K / 6`` (``K`` the spring's small-deflection stiffness), ``D_q = 2 zeta sqrt(K_q D_ii(0))`` with
    ``zeta = 0.7`` and ``D_ii(0)`` the link inertia's diagonal at ``q = 0`` (each joint a mass-spring on its own),
    ``K_i = 3 K_q``.

    Returns
    -------
    dict
        ``K_q`` (N m/rad), ``D_q`` (N m s/rad), ``K_i`` (N m/(rad s)).
    """
    p = np.asarray(model.params_array(nominal_params, arg="nominal_params"), dtype=float)
    K_q = p[drive_indices(model, "stiffness")] * DEFAULT_STIFFNESS_SHARE
    inertia = np.diag(model.inertia(np.zeros(model.nx), p))
    return {"K_q": K_q, "D_q": 2 * DEFAULT_DAMPING * np.sqrt(K_q * inertia), "K_i": DEFAULT_INTEGRAL_RATIO * K_q}


class JointImpedanceController(ImpedanceController):
    """Joint impedance for a joint-torque interface (``make_controller('joint_impedance', ...)``).

    The emitted ``<model>_control_joint_impedance`` (``derive/emit/impedance.py``) outputs the desired
    LINK-side joint torque WITHOUT gravity (the robot's layer adds it, e.g. libfranka's), from the NOMINAL
    rigid model and the link error::

        tau_d = D(q_d) q_d'' + C(q_d, q_d') q_d' + K_q (q_d - q) + D_q (q_d' - dq) + K_i z,   z' = q_d - q

    clipped at ``u_max`` with conditional integration there. It reads the full measurement (``sensing =
    'full'``), of which it uses ``q`` and ``dq``. Its ``u`` is a command for a joint-torque interface, not a
    motor torque: run it through one.

    Parameters
    ----------
    model : Model
    nominal_params : dict or array_like
    K_q, D_q, K_i : float or array_like, shape (n,), optional
        Link stiffness (N m/rad), damping (N m s/rad), integral gain (N m/(rad s)), each >= 0; default
        :func:`default_joint_impedance_gains`.
    u_max : float or array_like, shape (n,), optional
        Torque limit in N m (> 0); ``None`` = unlimited.
    anti_windup : bool
    """

    def __init__(self, model, nominal_params, *, K_q=None, D_q=None, K_i=None, u_max=None, anti_windup: bool = True):
        super().__init__(model, nominal_params, u_max=u_max, anti_windup=anti_windup)
        defaults = default_joint_impedance_gains(model, self.p_nom)
        for name, value in (("K_q", K_q), ("D_q", D_q), ("K_i", K_i)):
            v = defaults[name] if value is None else value
            setattr(self, name, joint_vector(v, self.n, name, minimum=0.0, strict=False))
        self.mode = "joint_impedance"

    @property
    def law_kind(self) -> str:
        return "joint_impedance"

    def gain_values(self) -> dict:
        """The gains of ``control_joint_impedance`` by the names of its manifest layout."""
        return {"K_q": self.K_q, "D_q": self.D_q, "K_i": self.K_i,
                "u_max": self.u_max if self.u_max is not None else np.ones(self.n),
                "limit": float(self.u_max is not None), "anti_windup": float(self.anti_windup)}


def regulation_contraction(model, q_d, nominal_params) -> float:
    """The contraction factor at the set point ``q_d`` of the fixed-point iteration
    ``q_bar <- theta_d - psi^-1(g(q_bar))`` (module docstring): ``|| diag(psi'(phi_d))^-1 dg/dq(q_d) ||_2`` with
    ``phi_d = psi^-1(g(q_d))`` the deflection holding gravity (``psi' = K`` for a linear spring).

    Parameters
    ----------
    model : Model
    q_d : array_like, shape (n,)
        Link set point, rad.
    nominal_params : dict or array_like
        Nominal parameters (gravity and spring of the controller's model).

    Returns
    -------
    float
        ``rho`` (dimensionless); ``< 1``: the iteration contracts near ``q_d`` and the link's equilibrium under the
        motor position ``theta_d`` is unique there.
    """
    import casadi as ca
    from ..sim.interface import gravity_function
    n = int(model.n)
    p = np.asarray(model.params_array(nominal_params, arg="nominal_params"), dtype=float)
    q = np.asarray(joint_vector(q_d, n, "q_d"), dtype=float)
    g = gravity_function(model)
    qs = ca.SX.sym("q", n)
    dg = np.asarray(ca.Function("dg", [qs], [ca.jacobian(g(qs, p), qs)])(q), dtype=float)
    springs = model_springs(model)
    phi = springs["spring_inverse"](np.asarray(g(q, p), dtype=float).ravel(), p)
    dpsi = np.asarray(springs["spring"](phi, p)[1], dtype=float).ravel()
    return float(np.linalg.norm(dg / dpsi[:, None], 2))


def regulation_motor_position(model, q_d, nominal_params, where: str = "q_d") -> np.ndarray:
    """The motor position ``theta_d = q_d + psi^-1(g(q_d))`` (rad, shape (n,)) that holds the link at the set point
    ``q_d`` against gravity: the feedforward's ``theta_d`` at a constant reference, after checking that the
    fixed-point iteration contracts there (:func:`regulation_contraction` < 1).

    Raises
    ------
    FjmValueError
        One line naming ``where``, the set point and the factor, where ``rho >= 1``.
    """
    rho = regulation_contraction(model, q_d, nominal_params)
    q = np.asarray(joint_vector(q_d, int(model.n), "q_d"), dtype=float)
    if not rho < 1.0:
        raise FjmValueError(f"{where} = {np.round(q, 4).tolist()}: the nominal spring does not dominate gravity there "
                            f"(||psi'^-1 dg/dq|| = {rho:.3g}, expected < 1): under the motor position holding it the link's "
                            "equilibrium is not assured unique; expected another set point or stiffer nominal springs")
    r = np.concatenate([q, np.zeros(4 * q.size)])
    return np.asarray(model.feedforward(r, nominal_params)[1], dtype=float)
