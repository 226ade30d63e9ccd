"""MuJoCo as the robot of an identification: the TRUE plant exported, driven and logged like a real arm.

The true plant is the model's defaults with the stiffness x :data:`K_FACTOR`, the rotor inertia x
:data:`JM_FACTOR`, motor damping :data:`B_M` and MuJoCo's dry friction ``frictionloss``
(:data:`FRICTION`, a constraint-based Coulomb friction, not fjm's tanh) on every rotor, written by
:func:`fjm_runtime.export.mjcf.write_mjcf` and run through :class:`fjm_runtime.export.bridge.MujocoPlant`
(``mujoco`` is imported there, on first use). It follows an excitation under a PD on the motor angle
plus the nominal feedforward (stable whatever the spring), at 1 kHz with the torque held on fjm's
substeps, and the log holds what a torque-sensed arm records with the ``franka_like`` sensor levels:
quantized noisy encoder angles, ``tau_J`` with noise and a constant offset, the commanded torque.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..drives import linear_stiffness_indices, role_names
from ..sim.sensor import SensorModel
from ..sim.substeps import resolve_substeps
from .excite import nominal_motion
from .log import Log

__all__ = ["RATE", "K_FACTOR", "JM_FACTOR", "B_M", "FRICTION", "PD_OMEGA", "true_params",
           "with_rotor_friction", "mujoco_plant", "mujoco_log", "tau_J_offsets"]

RATE = 1000.0
K_FACTOR, JM_FACTOR, B_M, FRICTION = 1.15, 0.9, 0.3, 0.4
#: Motor-side PD of the logging loop: natural frequency (rad/s), damping 0.7 on the nominal J_m.
PD_OMEGA = 30.0


def true_params(model) -> dict:
    """The TRUE plant of the module docstring, as a parameter dict."""
    linear_stiffness_indices(model, "the MuJoCo robot")     # its TRUE plant scales a linear K
    K, J, B = (role_names(model, role) for role in ("stiffness", "rotor_inertia", "damping"))
    p = dict(model.default_params)
    for k, j, b in zip(K, J, B):
        p[k], p[j], p[b] = K_FACTOR * p[k], JM_FACTOR * p[j], B_M
    return p


def with_rotor_friction(xml: str, friction) -> str:
    """The MJCF with MuJoCo's dry friction ``frictionloss`` (N m) on the rotor hinges (gear ratio 1).

    ``friction``: one value for every rotor, or a sequence of n values in joint order (0: none)."""
    rotors = re.findall(r'<joint name="([^"]*_rotor)" type="hinge"', xml)
    levels = np.broadcast_to(np.asarray(friction, dtype=float), (len(rotors),))
    for name, f in zip(rotors, levels):
        if f > 0:
            xml = xml.replace(f'<joint name="{name}" type="hinge"',
                              f'<joint name="{name}" type="hinge" frictionloss="{float(f)!r}"', 1)
    return xml


def mujoco_plant(model, p: dict, work: Path, substeps: int, friction=FRICTION):
    """A :class:`~fjm_runtime.export.bridge.MujocoPlant` of ``model`` at ``p`` with rotor friction
    (:func:`with_rotor_friction`)."""
    from ..export.bridge import MujocoPlant
    from ..export.mjcf import write_mjcf
    path = write_mjcf(model, Path(work) / f"{model.name}_true.xml", p, timestep=1.0 / RATE / substeps)
    path.write_text(with_rotor_friction(path.read_text(), friction))
    return MujocoPlant(model, path, p)


def tau_J_offsets(n: int, seed: int = 0) -> np.ndarray:
    """The torque sensors' constant offsets of :func:`mujoco_log`'s run ``seed``, N m, shape (n,) (the
    ``franka_like`` level; the truth an identified ``tau_J_offset<i>`` is checked against)."""
    return SensorModel.franka_like(seed=seed).offsets(n) * np.random.default_rng([seed, 1]).standard_normal(n)


def _quantize(v, step: float):
    return v if step <= 0 else step * np.floor(v / step + 0.5)


def mujoco_log(model, exc_ref, duration: float, work: Path, seed: int = 0, friction=FRICTION,
               p_true=None) -> Log:
    """The TRUE plant in MuJoCo along ``exc_ref`` (a :class:`~fjm_runtime.ident.excite.FourierReference`),
    logged at :data:`RATE` (module docstring).

    ``p_true``: the true parameters (default :func:`true_params`); ``friction``: MuJoCo's
    ``frictionloss``, N m, one value or one per joint (:func:`with_rotor_friction`)."""
    p_true, n = (true_params(model) if p_true is None else dict(p_true)), model.n
    t = np.arange(0.0, duration, 1.0 / RATE)
    nom = nominal_motion(model, exc_ref, t, model.params_array())
    x0 = np.concatenate([nom["q"][0], nom["dq"][0], nom["qm"][0], nom["dqm"][0]])
    subs = resolve_substeps(None, model, x0, model.params_array(p_true), 1.0 / RATE)
    plant = mujoco_plant(model, p_true, work, subs, friction)
    plant.set_state(x0)
    sensor, rng = SensorModel.franka_like(seed=seed), np.random.default_rng(seed)
    K = np.array([p_true[model.param_names[i]] for i in linear_stiffness_indices(model, "the MuJoCo robot")])
    Jm = np.array([model.default_params[j] for j in role_names(model, "rotor_inertia")])
    kp, kd = Jm * PD_OMEGA ** 2, 2 * 0.7 * PD_OMEGA * Jm
    offset = tau_J_offsets(n, seed)
    Q, QM, TAU, U = (np.zeros((t.size, n)) for _ in range(4))
    for k in range(t.size):
        x = plant.state()
        Q[k] = _quantize(x[:n] + sensor.q * rng.standard_normal(n), sensor.q_quant)
        QM[k] = _quantize(x[2 * n:3 * n] + sensor.q_m * rng.standard_normal(n), sensor.q_m_quant)
        TAU[k] = K * (x[2 * n:3 * n] - x[:n]) + sensor.tau_J * rng.standard_normal(n) + offset
        U[k] = nom["u"][k] + kp * (nom["qm"][k] - x[2 * n:3 * n]) + kd * (nom["dqm"][k] - x[3 * n:])
        plant.step(U[k], subs)
    return Log(t, Q, QM, U, TAU, f"MuJoCo {model.name} (true plant), {duration:g} s")
