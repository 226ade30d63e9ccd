"""Run an exported MJCF in MuJoCo with fjm's state and input (``mujoco`` is imported on first use only).

:class:`MujocoPlant` loads a file written by :func:`fjm_runtime.export.mjcf.write_mjcf`
and maps by name (the MJCF contract): fjm's ``x = [q; dq; q_m; dq_m]`` to
MuJoCo's ``qpos``/``qvel`` (link joints ``<j>``, rotor joints ``<j>_rotor`` at
``theta = N q_m``) and ``u`` to the motors ``<j>_motor``. Motor friction and three-segment springs
that the file states as custom numerics (:data:`fjm_runtime.export.mjcf.FRICTION_NUMERIC`,
:data:`~fjm_runtime.export.mjcf.SPRING_NUMERIC`) are applied by a passive-force callback installed around each ``mj_forward`` / ``mj_step`` of the plant (and removed after it:
MuJoCo's callbacks are global). MuJoCo is an
optional dependency of fjm (the ``dev`` extra); nothing in the runtime imports
this module.
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..drives import model_springs
from ..sim.actuation import interface_command, motor_command
from ..sim.interface import interface_from_spec
from ..sim.sample_step import command_ops, initial_step_state
from ..sim.sensor import SensorModel
from ..sim.step_layout import make_layout
from ..validation import FjmValueError, as_vector
from .mjcf import FRICTION_NUMERIC, SPRING_NUMERIC, gear_ratios, load_chain, resolve_params

__all__ = ["Actuation", "MujocoPlant", "run_closed_loop"]


def _mujoco():
    try:
        import mujoco
    except ImportError:  # pragma: no cover - mujoco is in the dev extra
        raise FjmValueError("the mujoco package is not installed (expected `pip install mujoco`, or "
                            "`pip install 'fjm[dev]'`)") from None
    return mujoco


class MujocoPlant:
    """An exported MJCF loaded in MuJoCo, with fjm's state layout.

    Parameters
    ----------
    model : fjm_runtime.Model
        The model the file was exported from.
    path : str or pathlib.Path
        The MJCF file (loaded as it is, ``mujoco.MjModel.from_xml_path``).
    params : dict or array, optional
        The parameters it was exported with (for the gear ratios).
    gear_ratio : float or sequence, optional
        Reduced model: the gear ratio it was exported with (default 1).

    Attributes
    ----------
    mj, data : mujoco.MjModel, mujoco.MjData
    N : numpy.ndarray, shape (n,)
        Gear ratios (rotor angle = ``N q_m``).
    """

    def __init__(self, model, path, params=None, gear_ratio=None):
        mujoco = _mujoco()
        self.model = model
        self.mj = mujoco.MjModel.from_xml_path(str(Path(path)))
        self.data = mujoco.MjData(self.mj)
        chain = load_chain(model)
        p = resolve_params(model, params)
        self.params = np.array([p[k] for k in model.param_names], dtype=float)  # validated by resolve_params
        self.N = gear_ratios(model, p, "rotors" in chain, gear_ratio)
        joints = [e["joint"] for e in chain["elastic"]]
        names = joints + [f"{j}_rotor" for j in joints]
        self.qpos = np.array([self.mj.joint(j).qposadr[0] for j in names])
        self.qvel = np.array([self.mj.joint(j).dofadr[0] for j in names])
        self.ctrl = np.array([self.mj.actuator(f"{j}_motor").id for j in joints])
        self.scale = np.concatenate([np.ones(model.n), self.N])
        # (rotor dof, F_c, F_s, v_s, v_c, N) per rotor whose friction the file states, and
        # (spring tendon, link dof, rotor dof, N, joint index) per spring the file states as numerics; their
        # torque is the model's spring law at the file's coefficients (put into the parameter vector)
        self.friction, self.springs = [], []
        self._p = self.params.copy()
        for i in range(self.mj.nnumeric):
            num = self.mj.numeric(i)
            if num.name.startswith(FRICTION_NUMERIC):
                dof = self.mj.joint(num.name[len(FRICTION_NUMERIC):]).dofadr[0]
                self.friction.append((int(dof), *(float(v) for v in num.data)))
            elif num.name.startswith(SPRING_NUMERIC):
                tendon = num.name[len(SPRING_NUMERIC):]
                j = tendon[:-len("_spring")]
                k = joints.index(j)
                self.springs.append((self.mj.tendon(tendon).id, int(self.mj.joint(j).dofadr[0]),
                                     int(self.mj.joint(f"{j}_rotor").dofadr[0]), float(self.N[k]), k))
                self._p[list(model.drives[k].spring)] = [float(v) for v in num.data]  # the law's order
        self._spring = model_springs(model)["spring"] if self.springs else None

    def _passive(self, m, d) -> None:
        """MuJoCo's passive-force callback: ``qfrc_passive -= F(v) / N`` on each rotor, ``v = qvel / N``;
        the numerics springs' tendon force ``-psi(phi)`` (the model's law) at MuJoCo's tendon length ``phi``."""
        for dof, F_c, F_s, v_s, v_c, N in self.friction:
            v = d.qvel[dof] / N
            d.qfrc_passive[dof] -= (F_c + (F_s - F_c) * np.exp(-(v / v_s) ** 2)) * np.tanh(v / v_c) / N
        if not self.springs:
            return
        phi = np.zeros(self.model.n)
        for tendon, _, _, _, k in self.springs:
            phi[k] = d.ten_length[tendon]
        psi = np.asarray(self._spring(phi, self._p)[0], dtype=float).ravel()  # one call for every joint
        for _, link, rotor, N, k in self.springs:
            d.qfrc_passive[link] += psi[k]       # tendon coefficient -1 on q
            d.qfrc_passive[rotor] -= psi[k] / N  # tendon coefficient 1/N on theta

    @contextmanager
    def _callbacks(self):
        """The passive-force callback installed for the duration (nothing without friction or such springs)."""
        if not (self.friction or self.springs):
            yield
            return
        mujoco = _mujoco()
        mujoco.set_mjcb_passive(self._passive)
        try:
            yield
        finally:
            mujoco.set_mjcb_passive(None)

    def set_state(self, x) -> None:
        """Set MuJoCo's ``qpos``, ``qvel`` from fjm's ``x`` (shape (4n,))."""
        n = self.model.n
        xv = as_vector("x", x, 4 * n)
        self.data.qpos[self.qpos] = self.scale * np.concatenate([xv[:n], xv[2 * n:3 * n]])
        self.data.qvel[self.qvel] = self.scale * np.concatenate([xv[n:2 * n], xv[3 * n:]])

    def state(self) -> np.ndarray:
        """fjm's ``x = [q; dq; q_m; dq_m]`` from MuJoCo's state, shape (4n,)."""
        n = self.model.n
        pos = self.data.qpos[self.qpos] / self.scale
        vel = self.data.qvel[self.qvel] / self.scale
        return np.concatenate([pos[:n], vel[:n], pos[n:], vel[n:]])

    def xdot(self, x, u) -> np.ndarray:
        """``x'`` from MuJoCo's ``qacc`` (``mj_forward`` at ``x``, ``ctrl = u``), shape (4n,)."""
        mujoco = _mujoco()
        n = self.model.n
        self.set_state(x)
        self.data.ctrl[self.ctrl] = as_vector("u", u, n)
        with self._callbacks():
            mujoco.mj_forward(self.mj, self.data)
        acc = self.data.qacc[self.qvel] / self.scale
        xv = as_vector("x", x, 4 * n)
        return np.concatenate([xv[n:2 * n], acc[:n], xv[3 * n:], acc[n:]])

    def step(self, u, steps: int = 1) -> np.ndarray:
        """Hold ``ctrl = u`` over ``steps`` MuJoCo steps (``mj_step``); returns the new fjm state (4n,)."""
        mujoco = _mujoco()
        self.data.ctrl[self.ctrl] = as_vector("u", u, self.model.n)
        with self._callbacks():
            for _ in range(int(steps)):
                mujoco.mj_step(self.mj, self.data)
        return self.state()

    def sensors(self) -> dict:
        """The named sensors ``<j>_q, _dq, _q_m, _dq_m, _tau_J`` after the last forward/step: name -> float."""
        return {self.mj.sensor(i).name: float(self.data.sensordata[self.mj.sensor_adr[i]])
                for i in range(self.mj.nsensor)}


def run_closed_loop(plant: MujocoPlant, controller, reference, *, duration: float, dt: float, substeps: int,
                    x0=None, interface=None):
    """The sampled-data loop of :func:`fjm_runtime.simulate` with MuJoCo as the plant.

    At ``t_k = k dt`` the law sees the state ``x_k`` (ideal state sensing, no delay), its
    state advances once per sample (``z += dt z_dot``), and its output goes through the command
    interface (:mod:`fjm_runtime.sim.interface`, the arithmetic of :mod:`fjm_runtime.sim.actuation`):
    the interface's command ``c_k`` (vendor filter, rate limit) once per sample, then per MuJoCo step
    the motor command (``joint_torque``: the nominal gravity and the inner torque loop on MuJoCo's
    state, the spring torque at the file's parameters) and the current loop, whose exact mean over
    the step is MuJoCo's ``ctrl`` (held over the step: MuJoCo's RK4 cannot take the torque at its
    stages' times, so with a current loop the run differs from :func:`fjm_runtime.simulate` by the
    quadrature of the lag, not by rounding). The file's timestep must be ``dt / substeps``.

    Parameters
    ----------
    plant : MujocoPlant
    controller : a controller of :func:`fjm_runtime.make_controller`
    reference : Reference
    duration, dt : float
        s; ``round(duration / dt)`` samples.
    substeps : int
        MuJoCo steps per sample.
    x0 : array_like, shape (4n,), optional
        Default: at rest with ``q = q_m = q_d(0)``.
    interface : CommandInterface or str, optional
        Default ``'motor'``; ``'ideal'``: ``ctrl = u_k`` held over the sample.

    Returns
    -------
    t : numpy.ndarray, shape (N+1,)
    x : numpy.ndarray, shape (N+1, 4n)
    u : numpy.ndarray, shape (N+1, n)
        The interface's command ``c_k`` held over ``[t_k, t_k + dt)`` (the law's torque with ``ideal``).
    """
    n = plant.model.n
    step = float(plant.mj.opt.timestep)
    if abs(step * substeps - dt) > 1e-12 * dt:
        raise FjmValueError(f"MuJoCo timestep {step!r} s x {substeps} substeps != dt = {dt!r} s (expected "
                            "timestep = dt / substeps: export with --timestep)")
    steps = int(round(duration / dt))
    r0 = np.asarray(reference(0.0), dtype=float).reshape(5, n)
    if x0 is None:
        x0 = np.concatenate([r0[0], np.zeros(n), r0[0], np.zeros(n)])
    x = as_vector("x0", x0, 4 * n)
    plant.set_state(x)
    z = np.asarray(controller.initial_state(0.0, x, r0), dtype=float)
    act = Actuation(plant, controller, dt, substeps, x, z, interface)
    t = np.arange(steps + 1) * dt
    X, U = np.zeros((steps + 1, 4 * n)), np.zeros((steps + 1, n))
    for k in range(steps + 1):
        x = plant.state()
        r = np.asarray(reference(t[k]), dtype=float).reshape(5, n)
        sample = controller.evaluate(t[k], x, z, r)
        X[k], U[k] = x, act.command(np.asarray(sample.u, dtype=float))
        if k == steps:
            break
        if z.size:
            z = z + dt * np.asarray(controller.state_derivative(t[k], x, z, r, sample), dtype=float)
        act.run(U[k])
    return t, X, U


class Actuation:
    """The command interface between a law and a MuJoCo plant (the sample step's arithmetic, numpy).

    Parameters
    ----------
    plant : MujocoPlant
    controller : a controller of :func:`fjm_runtime.make_controller`
        Its nominal model gives the interface's gravity (``joint_torque``) and its layout.
    dt : float
        Sample period, s.
    substeps : int
        MuJoCo steps per sample.
    x0 : array_like, shape (4n,)
        The state the loop starts from (the current loop starts at the torque holding it).
    z0 : array_like, shape (nz,)
        The law's initial state.
    interface : CommandInterface or str or None
        Default ``'motor'``.
    """

    def __init__(self, plant: MujocoPlant, controller, dt: float, substeps: int, x0, z0, interface):
        self.plant, self.substeps = plant, int(substeps)
        L = make_layout(plant.model, controller, dt, substeps, SensorModel.ideal(), 0, False,
                        interface=interface_from_spec(interface, what="interface"))
        self.L, self.ops = L, command_ops(plant.model, controller, L)
        w0 = initial_step_state(plant.model, L, x0, z0, plant.params, controller=controller)
        _, _, last, cur = L.extra_slices()
        self.last, self.cur = w0[last], w0[cur]

    def command(self, u_law):
        """``c_k``: the law's output through the interface's sample-rate stage."""
        if not self.L.has_last:
            return u_law
        self.last = interface_command(self.ops, self.L, self.last, u_law)[0]
        return self.last

    def run(self, c) -> None:
        """One sample of MuJoCo steps under the command ``c``."""
        L = self.L
        if L.interface == "motor" and not L.current_decay:
            self.plant.step(c, self.substeps)
            return
        for _ in range(self.substeps):
            u_c = motor_command(self.ops, L, self.plant.state(), c, self.plant.params)
            u = u_c
            if L.current_decay:
                u = u_c + (self.cur - u_c) * L.current_mean
                self.cur = u_c + (self.cur - u_c) * L.current_decay
            self.plant.step(u, 1)
