"""The sample step of the sampled-data loop: ONE definition, used by every backend.

At sample ``k`` (``t_k = k T``), from the step state ``w_k`` (layout :class:`StepLayout`)::

    m_true = x_k                          (state sensing, 4n)
           = [q; dq; K (q_m - q); K (dq_m - dq); dq_m]   (torque sensing, 5n, K TRUE)
           = [q; dq; q_m; dq_m; K (q_m - q); K (dq_m - dq)]   (full sensing, 6n)
    m_k    = m_true + noise_k             (noise generated outside, sim/sensor.py)
             encoders: q (and q_m) -> step * floor(value / step + 0.5)
             tau_J + the run's constant offset (drawn from its seed, held in w)
             velocities 'differentiated': dq_k = v_{k-1} + a_v ((q_k - q_{k-1}) / T - v_{k-1}) of the
             MEASURED angle (the same for dq_m from the measured motor angle), a_v = 1 - exp(-w_v T)
             dtau_J 'filtered': d_k = d_{k-1} + a ((tau_k - tau_{k-1}) / T - d_{k-1}), a = 1 - exp(-w_c T)
    m_used = m_{k-d}                      (ring buffer of the d last measurements; d = 0: m_k)
             predict: x_hat from m_{k-d} (torque sensing: q_m = q + psi_nom^-1(tau_J)), integrated
             over d samples of the CONTROLLER'S NOMINAL model (its own f, g and p_nom, whatever
             the plant is) under u_{k-d} .. u_{k-1}, m_used = its measurement
    u_law, s_k, y_hat_k = law(m_used, z_k, r_k)          (NOMINAL parameters; saturation and
                                                          anti-windup inside the law)
    u_k    = clip(u_law, u_{k-1} - R T, u_{k-1} + R T)   (the torque-rate limit R, when finite)
    z_{k+1} = z_k + T z_dot(m_used, z_k, r_k, u_law)      (a digital controller: once per sample;
             with a rate limit, an error integral is frozen on a joint whose u_k lags u_law in the
             direction its error asks for: conditional integration, as at the torque limit)
    x_{k+1} = substeps RK4 steps of T / substeps of x' = f(x; p) + g(x; p) u_k   (TRUE p, u held)

The CasADi form (:func:`casadi_sample_step`) is ``fjm_sample_step(w, r, noise, p) -> (w_next, aux)``
with plain vectors: ``w`` (nw), ``r`` (5n, the reference rows at ``t_k`` stacked), ``noise`` (nm),
``p`` (n_params, TRUE), ``aux = [u; s; y_hat]`` (6n, ``u`` the APPLIED torque). A batch engine
folds it over samples. The numpy form (:func:`python_sample_step`) does the same arithmetic
through the models' ``f``/``g`` and the controller's ``evaluate``/``state_derivative``.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..drives import model_springs
from ..validation import FjmValueError
from .actuation import (actuated_plant, interface_command, nominal_gravity, plant_substeps, rate_windup,
                        rk4_stages, spring_torque)
from .interface import gravity_function
from .sensor import SensorModel, measurement_blocks, offset_normals
from .step import casadi_functions
from .step_layout import StepLayout, controller_model

__all__ = ["casadi_sample_step", "check_loop_settings", "command_ops", "initial_measurement", "initial_step_state",
           "predicted_measurement", "python_sample_step", "sample_step_function"]

# -- the arithmetic, written once for numpy and CasADi ------------------------------------------

class _NumpyOps:
    def __init__(self, model):
        self.model = model

    cat = staticmethod(lambda parts: np.concatenate([np.asarray(p, dtype=float).ravel() for p in parts]))
    floor = staticmethod(np.floor)
    fmin = staticmethod(np.minimum)
    fmax = staticmethod(np.maximum)

    def xdot(self, x, u, p):
        nx, n = int(self.model.nx), int(self.model.n)
        return np.asarray(self.model.f(x, p), dtype=float).reshape(nx) + \
            np.asarray(self.model.g(x, p), dtype=float).reshape(nx, n) @ u

    def take(self, p, idx):
        return np.asarray(p)[list(idx)]

    const = staticmethod(lambda a: np.asarray(a, dtype=float))

    def spring(self, phi, p):
        """``(psi(phi), psi'(phi))`` of the model's spring law, each shape (n,)."""
        out = model_springs(self.model)["spring"](np.asarray(phi, dtype=float), np.asarray(p, dtype=float))
        return tuple(np.asarray(v, dtype=float).reshape(-1) for v in out[:2])

    def spring_inverse(self, tau, p):
        """``phi_J = psi^-1(tau)``, shape (n,)."""
        fn = model_springs(self.model)["spring_inverse"]
        return np.asarray(fn(np.asarray(tau, dtype=float), np.asarray(p, dtype=float)), dtype=float).reshape(-1)

    def gravity(self, q):
        """The NOMINAL gravity ``g(q)`` the robot adds (joint_torque), shape (n,); set ``gravity_fn``,
        ``p_gravity`` first."""
        return np.asarray(self.gravity_fn(np.asarray(q, dtype=float), self.p_gravity), dtype=float).reshape(-1)


class _CasadiOps:
    def __init__(self, fns, nx, n, outline_h=None):
        import casadi as ca
        self.ca, self.fns, self.nx, self.n = ca, fns, nx, n
        self.substep = None if outline_h is None else self._substep_function(float(outline_h))
        self.substep_staged = None if outline_h is None else self._substep_function(float(outline_h), True)
        if outline_h is not None and "gravity" in fns:        # one call per substep, as the plant's
            g = fns["gravity"]
            q, p = ca.SX.sym("q", g.size1_in(0)), ca.SX.sym("p", g.size1_in(1))
            self.fns = dict(fns, gravity=ca.Function(g.name() + "_call", [q, p], [g(q, p)], {"never_inline": True}))

    def _substep_function(self, h: float, staged: bool = False):
        """One RK4 step of ``h`` as an SX Function kept as a call (``never_inline``): evaluated on SX
        it stays one call node, so a step of ``s`` substeps holds ``s`` calls, not ``s`` copies.
        ``staged``: the torque at the stages' times ``(u0, uh, u1)`` (a current loop's response)."""
        ca, nx, n = self.ca, self.nx, self.n
        x, u = ca.SX.sym("x", nx), ca.SX.sym("u", n)
        us = (u, ca.SX.sym("uh", n), ca.SX.sym("u1", n)) if staged else (u, u, u)
        p = ca.SX.sym("p", self.fns["f"].size1_in(1))
        x_next = rk4_stages(self.xdot, x, *us, p, h)
        name = f"fjm_rk4{'_staged' if staged else ''}_{self.fns['f'].name()}"
        ins = [x, *us, p] if staged else [x, u, p]
        names = ["x", "u", "uh", "u1", "p"] if staged else ["x", "u", "p"]
        return ca.Function(name, ins, [ca.cse(x_next)], names, ["x_next"], {"never_inline": True})

    def cat(self, parts):
        return self.ca.vertcat(*parts)

    def floor(self, v):
        return self.ca.floor(v)

    def fmin(self, a, b):
        return self.ca.fmin(a, b)

    def fmax(self, a, b):
        return self.ca.fmax(a, b)

    def xdot(self, x, u, p):
        ca = self.ca
        return self.fns["f"](x, p) + ca.mtimes(ca.reshape(self.fns["g"](x, p), self.nx, self.n), u)

    def take(self, p, idx):
        return self.ca.vertcat(*[p[i] for i in idx])

    def const(self, a):
        return self.ca.DM(np.asarray(a, dtype=float))

    def spring(self, phi, p):
        out = self.fns["spring"](phi, p)
        return out[0], out[1]

    def spring_inverse(self, tau, p):
        return self.fns["spring_inverse"](tau, p)

    def gravity(self, q):
        return self.fns["gravity"](q, self.p_gravity)


def _slot(L: StepLayout, signal: str) -> int:
    """The block of ``signal`` (a name of :data:`fjm_runtime.sim.sensor.SIGNALS`) in the measurement."""
    return measurement_blocks(L.sensing).index(signal)


def _measure(ops, L: StepLayout, x, p):
    """The measurement of ``x`` with the spring law of ``ops``'s model at parameters ``p``: state sensing ``x``;
    torque ``[q; dq; psi(q_m - q); psi'(q_m - q) (dq_m - dq); dq_m]``; full ``[q; dq; q_m; dq_m; psi; psi' (dq_m
    - dq)]`` (``K (q_m - q)``, ``K (dq_m - dq)`` for a linear spring)."""
    if L.sensing == "state":
        return x
    n = L.n
    q, dq, qm, dqm = x[0:n], x[n:2 * n], x[2 * n:3 * n], x[3 * n:4 * n]
    tau, dtau = spring_torque(ops, x, p, n)
    return ops.cat([q, dq, qm, dqm, tau, dtau] if L.sensing == "full" else [q, dq, tau, dtau, dqm])


def _quantize(ops, v, step: float):
    return v if step == 0 else step * ops.floor(v / step + 0.5)


def _difference(L: StepLayout, angle, prev, v_prev):
    """The filtered difference of an angle: ``v_prev + a ((angle - prev) / T - v_prev)``."""
    return v_prev + L.a_velocity * ((angle - prev) / L.T - v_prev)


def _reading(ops, L: StepLayout, w, noise, p):
    """The raw reading of sample k (nm): what the robot hands the controller, before any filter.

    The noisy measurement with quantized angles and the tau_J offset; with
    ``velocity_mode='differentiated'`` the velocity slots are not read (the controller differentiates
    the angles) except that, with torque sensing, the dq_m slot carries the measured MOTOR ANGLE
    (the angle dq_m is differentiated from; state sensing reads q_m in its own slot).
    """
    n = L.n
    x = w[0:L.nx]
    m = _measure(ops, L, x, p) + noise
    parts = [m[b * n:(b + 1) * n] for b in range(L.nm // n)]
    parts[0] = _quantize(ops, parts[0], L.q_quant)
    if L.sensing != "torque":  # the motor angle is read in its own slot
        parts[2] = _quantize(ops, parts[2], L.q_m_quant)
    if L.offset:
        parts[_slot(L, "tau_J")] = parts[_slot(L, "tau_J")] + w[L.extra_slices()[1]]
    if L.differentiated and L.sensing == "torque":
        # the dq_m slot of a torque measurement carries the motor ANGLE's noise (sensor.noise_slots)
        parts[4] = _quantize(ops, x[2 * n:3 * n] + noise[4 * n:5 * n], L.q_m_quant)
    return parts


def _condition(ops, L: StepLayout, parts, venc, filt):
    """The controller's sensor pre-processing of a raw reading (blocks ``parts``, :func:`_reading`):
    ``(m_k, filt_next, venc_next)`` with the differentiated velocities and the filtered dtau_J."""
    n = L.n
    parts = list(parts)
    venc_next = venc
    if L.differentiated:
        qm = parts[2] if L.sensing != "torque" else parts[4]
        enc = venc_next
        dq = _difference(L, parts[0], enc[0:n], enc[n:2 * n])
        dqm = _difference(L, qm, enc[2 * n:3 * n], enc[3 * n:4 * n])
        parts[1] = dq
        parts[_slot(L, "dq_m")] = dqm
        venc_next = ops.cat([parts[0], dq, qm, dqm])
    filt_next = filt
    if L.filtered:
        tau, tau_prev, d_prev = parts[_slot(L, "tau_J")], filt_next[0:n], filt_next[n:2 * n]
        d = d_prev + L.a_filter * ((tau - tau_prev) / L.T - d_prev)
        parts[_slot(L, "dtau_J")] = d
        filt_next = ops.cat([tau, d])
    return ops.cat(parts), filt_next, venc_next


def _sense(ops, L: StepLayout, w, noise, p):
    """``(m_k, filt_next, venc_next)``: the noisy, quantized, filtered measurement of sample k."""
    return _condition(ops, L, _reading(ops, L, w, noise, p), w[L.extra_slices()[0]], w[L.slices()[4]])


def _predict(nom_ops, L: StepLayout, m_old, u_buf, p_nom):
    """The measurement predicted ``d`` samples ahead from ``m_old`` with the controller's NOMINAL model
    (torque sensing: ``q_m = q + psi^-1(tau_J)`` by its spring law at ``p_nom``), each sample on
    ``L.predictor_substeps`` RK4 substeps (an outlined ``nom_ops`` holds the substep of that count). Under
    a ``joint_torque`` interface the commands ``u_buf`` are the robot's ``c`` (without gravity): the predictor
    runs the robot's torque loop on the nominal model too (its gravity and spring law; no current loop, as
    for a motor interface)."""
    n = L.n
    steps = L if L.predictor_substeps == L.substeps else replace(L, substeps=L.predictor_substeps)
    if L.interface == "joint_torque":
        steps = replace(steps, current_decay=0.0)
    if L.sensing == "state":
        x = m_old
    elif L.sensing == "full":  # the state is read: only the prediction's own measurement needs psi
        x = m_old[0:4 * n]
    else:
        q, dq, tau, dqm = m_old[0:n], m_old[n:2 * n], m_old[2 * n:3 * n], m_old[4 * n:5 * n]
        x = nom_ops.cat([q, dq, q + nom_ops.spring_inverse(tau, p_nom), dqm])
    x_old = x
    for j in range(L.delay):
        x = actuated_plant(nom_ops, steps, x, None, u_buf[j * n:(j + 1) * n], p_nom)[0] \
            if L.interface == "joint_torque" else plant_substeps(nom_ops, steps, x, u_buf[j * n:(j + 1) * n], p_nom)
    if L.sensing == "full":
        # the reading plus the nominal model's predicted CHANGE: the torque keeps the sensor's scale (a torque
        # from K_nom (q_m - q) would scale the law's torque feedback by K_nom / K: -0.7 became -1 at K x0.7)
        return m_old + _measure(nom_ops, L, x, p_nom) - _measure(nom_ops, L, x_old, p_nom)
    return _measure(nom_ops, L, x, p_nom)


def predicted_measurement(model, L: StepLayout, m_old, u_buf, p_nom) -> np.ndarray:
    """The predictor of the sample step in numpy: ``m_old`` (nm,) predicted ``L.delay`` samples ahead under
    the torques ``u_buf`` (delay * n,) with ``model`` (the controller's) at ``p_nom``, shape (nm,)."""
    ops = _NumpyOps(model)
    ops.gravity_fn, ops.p_gravity = gravity_function(model), np.asarray(p_nom, dtype=float)
    return np.asarray(_predict(ops, L, np.asarray(m_old, dtype=float), np.asarray(u_buf, dtype=float),
                               np.asarray(p_nom, dtype=float)), dtype=float)


def _delayed(ops, nom_ops, L: StepLayout, m_k, buf, u_buf, p_nom):
    """The delay buffer and the prediction: ``(m_used, m_buf_next)`` (``buf``, ``u_buf`` the buffers)."""
    if L.delay == 0:
        return m_k, buf
    m_old = buf[0:L.nm]
    m_buf_next = ops.cat([buf[L.nm:], m_k]) if L.delay > 1 else m_k
    m_used = _predict(nom_ops, L, m_old, u_buf, p_nom) if L.predict else m_old
    return m_used, m_buf_next


def _pre_law(ops, nom_ops, L: StepLayout, w, noise, p, p_nom):
    """Sensor, delay and prediction: ``(m_used, m_buf_next, filt_next, venc_next)``."""
    _, _, sb, su, _ = L.slices()
    m_k, filt_next, venc_next = _sense(ops, L, w, noise, p)
    m_used, m_buf_next = _delayed(ops, nom_ops, L, m_k, w[sb], w[su], p_nom)
    return m_used, m_buf_next, filt_next, venc_next


def _post_law(ops, L: StepLayout, w, u, zdot, m_buf_next, filt_next, venc_next, p):
    """``w_next`` from the interface's command ``u`` and the controller-state rate."""
    sx, sz, _, su, _ = L.slices()
    z_next = w[sz] + L.T * zdot if L.nz else w[sz]
    x_next, cur_next = actuated_plant(ops, L, w[sx], w[L.extra_slices()[3]], u, p)
    parts = [x_next, z_next]
    if L.delay:
        ub = w[su]
        parts += [m_buf_next, ops.cat([ub[L.n:], u]) if L.delay > 1 else u]
    if L.filtered:
        parts.append(filt_next)
    if L.differentiated:
        parts.append(venc_next)
    if L.offset:
        parts.append(w[L.extra_slices()[1]])
    if L.has_last:
        parts.append(u)
    if L.current_decay:
        parts.append(cur_next)
    return ops.cat(parts)


def python_sample_step(model, controller, L: StepLayout, w, t: float, r, noise, p):
    """One sample in numpy: ``(w_next, sample)`` (the controller's ControlSample, ``u`` the APPLIED torque)."""
    ops = command_ops(model, controller, L)   # the robot adds the controller model's gravity (joint_torque)
    nom_ops = _NumpyOps(controller_model(controller, model)) if L.predict else None
    p_nom = np.asarray(controller.p_nom, dtype=float) if L.predict else None
    if nom_ops is not None and L.interface == "joint_torque":   # and so does its predictor
        nom_ops.gravity_fn, nom_ops.p_gravity = ops.gravity_fn, ops.p_gravity
    m_used, m_buf_next, filt_next, venc_next = _pre_law(ops, nom_ops, L, w, noise, p, p_nom)
    sz = L.slices()[1]
    z = w[sz]
    r = np.asarray(r, dtype=float).reshape(5, L.n)
    sample = controller.evaluate(t, m_used, z, r)
    zdot = np.asarray(controller.state_derivative(t, m_used, z, r, sample), dtype=float) if L.nz else None
    u, u_filtered = interface_command(ops, L, w[L.extra_slices()[2]], np.asarray(sample.u, dtype=float))
    if L.integral:
        zdot = rate_windup(ops, L, zdot, u_filtered, u, m_used[:L.n] - r[0])
    w_next = _post_law(ops, L, w, u, zdot, m_buf_next, filt_next, venc_next, p)
    return w_next, (sample._replace(u=u) if L.has_last else sample)


def command_ops(model, controller, L: StepLayout):
    """The numpy arithmetic of the command side for ``model`` (a plant outside the sample step, e.g.
    MuJoCo): ``ops`` for :func:`fjm_runtime.sim.actuation.motor_command` and ``interface_command``,
    with the controller's nominal gravity when ``L``'s interface adds it (``joint_torque``)."""
    ops = _NumpyOps(model)
    if L.interface == "joint_torque":
        ops.gravity_fn, ops.p_gravity = nominal_gravity(controller, model)
    return ops


def casadi_sample_step(fns, controller, L: StepLayout, n_par: int, nominal_fns=None, outline: bool = False):
    """``fjm_sample_step(w, r, noise, p) -> (w_next, aux)`` as a CasADi Function (MX graph).

    Parameters
    ----------
    fns : dict
        The plant model's CasADi Functions ``f``, ``g`` of ``(x, p)``.
    controller
        Has ``symbolic_evaluate(m, z, r)`` and ``symbolic_state_derivative(m, z, r, out)``.
    L : StepLayout
    n_par : int
    nominal_fns : dict, optional
        The controller's model's ``f``, ``g`` (the predictor's); default ``fns``.
    outline : bool
        Keep each RK4 substep (plant and predictor) a call of one ``never_inline`` SX Function, so
        that the step evaluated on SX (a batch engine's) grows by one call per substep instead of
        one copy of the dynamics: code size and compiler memory independent of substeps and delay.

    Returns
    -------
    casadi.Function
        Inputs ``w`` (nw,), ``r`` (5n,), ``noise`` (nm,), ``p`` (n_par,); outputs ``w_next`` (nw,),
        ``aux = [u; s; y_hat]`` (6n,), ``u`` the applied (rate-limited) torque.
    """
    import casadi as ca
    h = L.T / L.substeps if outline else None
    h_pred = L.T / L.predictor_substeps if outline else None
    ops = _CasadiOps(_expanded(fns), L.nx, L.n, h)
    nom_ops = ops if (nominal_fns is None and h_pred == h) else \
        _CasadiOps(_expanded(fns if nominal_fns is None else nominal_fns), L.nx, L.n, h_pred)
    w, r = ca.MX.sym("w", L.nw), ca.MX.sym("r", 5 * L.n)
    noise, p = ca.MX.sym("noise", L.nm), ca.MX.sym("p", n_par)
    p_nom = ca.DM(np.asarray(controller.p_nom, dtype=float)) if L.predict else None
    if L.interface == "joint_torque":  # the robot adds the controller model's gravity (and so does its predictor)
        ops.p_gravity = nom_ops.p_gravity = ca.DM(np.asarray(controller.p_nom, dtype=float))
    m_used, m_buf_next, filt_next, venc_next = _pre_law(ops, nom_ops, L, w, noise, p, p_nom)
    z = w[L.slices()[1]]
    out = controller.symbolic_evaluate(m_used, z, r)
    zdot = controller.symbolic_state_derivative(m_used, z, r, out) if L.nz else None
    u, u_filtered = interface_command(ops, L, w[L.extra_slices()[2]], out["u"])
    if L.integral:
        zdot = rate_windup(ops, L, zdot, u_filtered, u, m_used[:L.n] - r[:L.n])
    w_next = _post_law(ops, L, w, u, zdot, m_buf_next, filt_next, venc_next, p)
    return ca.Function("fjm_sample_step", [w, r, noise, p],
                       [w_next, ca.vertcat(u, out["s"], out["y_hat"])],
                       ["w", "r", "noise", "p"], ["w_next", "aux"])


def _expanded(fns):
    """``f``, ``g``, ``spring`` and ``spring_inverse`` as SX Functions (MX ones expanded) so that each substep
    is one call."""
    out = {}
    for k in ("f", "g", "spring", "spring_inverse", "gravity"):
        if k not in fns:
            continue
        fn = fns[k]
        try:
            out[k] = fn.expand() if fn.is_a("MXFunction") else fn
        except Exception:  # noqa: BLE001 - keep a Function that cannot be expanded as it is
            out[k] = fn
    return out


def initial_step_state(model, L: StepLayout, x0, z0, p_true, seed: int = 0, sensor=None,
                       controller=None) -> np.ndarray:
    """``w_0``: the plant and controller states and the loop's memory before sample 0.

    The plant rests at ``x0`` before ``t = 0``: the delay buffers hold the noise-free measurement
    of ``x0`` and the commands that held it there (the true spring torque ``K (q_m - q)``: a robot
    hands over to the controller while holding; zeros would make the predictor see the arm fall
    for ``d`` samples and kick the law at start), the dtau_J filter the true ``tau_J(x0)``, ``dtau_J(x0)``, the
    velocity filters the true angles and velocities, the last command (rate limit, vendor filter) and
    the current loop's motor torque the true spring torque ``K (q_m - q)`` at ``x0`` (what holds a rest
    state), and the run's tau_J offset is ``sensor.tau_J_offset * offset_normals(seed)`` (``sensor``
    needed only when ``L.offset``). With a ``joint_torque`` interface the commands exclude the
    gravity the robot adds: ``K (q_m - q) - g_nom(q)`` (``controller`` needed: its model's gravity).
    """
    ops = _NumpyOps(model)
    n = L.n
    x0 = np.asarray(x0, dtype=float)
    m0 = np.asarray(_measure(ops, L, x0, p_true), dtype=float)
    parts = [x0, z0]
    # the spring torque that holds x0 (delay buffer, the interface's last command, the current loop's torque)
    spring = ops.spring(x0[2 * n:3 * n] - x0[:n], p_true)[0] if (L.delay or L.has_last or L.current_decay) \
        else None
    command = spring
    if L.interface == "joint_torque":
        if controller is None:
            raise FjmValueError("initial_step_state: a joint_torque interface adds the nominal gravity; pass the "
                                "controller")
        ops.gravity_fn, ops.p_gravity = nominal_gravity(controller, model)
        command = spring - ops.gravity(x0[:n])
    if L.delay:
        parts += [np.tile(m0, L.delay), np.tile(command, L.delay)]
    if L.filtered:
        parts.append(m0[_slot(L, "tau_J") * n:(_slot(L, "dtau_J") + 1) * n])
    if L.differentiated:
        parts.append(x0[:4 * n])
    if L.offset:
        if sensor is None:
            raise FjmValueError("initial_step_state: this layout has a tau_J offset; pass the sensor")
        parts.append(sensor.offsets(n) * offset_normals(int(seed), n))
    if L.has_last:
        parts.append(command)
    if L.current_decay:
        parts.append(spring)
    return ops.cat(parts)


def initial_measurement(model, L: StepLayout, x0, p_true) -> np.ndarray:
    """The noise-free measurement of ``x0`` (what the controller's ``initial_state`` is given)."""
    ops = _NumpyOps(model)
    return np.asarray(_measure(ops, L, np.asarray(x0, dtype=float), p_true), dtype=float)


def sample_step_function(model, controller, L: StepLayout, outline: bool = False):
    """The CasADi sample step of ``(model, controller, layout)`` (rebuilt per call: gains are baked in).

    The predictor integrates the controller's own model (:func:`controller_model`), which differs
    from the plant when the plant is, e.g., a complete model (:mod:`fjm_runtime.control.coupling`).
    ``outline``: see :func:`casadi_sample_step`.
    """
    nominal = controller_model(controller, model)
    nominal_fns = casadi_functions(nominal, ("f", "g")) if (L.predict and nominal is not model) else None
    if L.predict and nominal is not model and nominal_fns is None:
        raise FjmValueError(f"predict: the controller's model {getattr(nominal, 'name', nominal)!r} has no CasADi "
                            "Functions to predict with")
    torque = L.sensing != "state"  # only a torque (or full) sensor and its predictor evaluate the spring law
    springs = torque or L.interface == "joint_torque"  # the robot's torque loop reads its torque sensor too
    if nominal_fns is not None and springs:
        nominal_fns.update(model_springs(nominal))
    if nominal_fns is not None and L.interface == "joint_torque":
        nominal_fns["gravity"] = gravity_function(nominal)
    fns = dict(casadi_functions(model), **(model_springs(model) if springs else {}))
    if L.interface == "joint_torque":
        fns["gravity"] = gravity_function(nominal)
    return casadi_sample_step(fns, controller, L, len(model.param_names), nominal_fns, outline=outline)


def check_loop_settings(sensor, delay_samples, predict, loop="sampled"):
    """The sensor (default ideal), the delay, the prediction flag and the loop name of a sampled-data loop, checked.

    Shared by :func:`fjm_runtime.sim.simulate.simulate` and the batch engine.

    Returns
    -------
    sensor : SensorModel
    delay_samples : int

    Raises
    ------
    FjmValueError
        One line naming the bad setting and what was expected.
    """
    if sensor is None:
        sensor = SensorModel.ideal()
    if not isinstance(sensor, SensorModel):
        raise FjmValueError(f"sensor = {sensor!r}: expected a SensorModel (e.g. SensorModel.panda_white())")
    if isinstance(delay_samples, bool) or not isinstance(delay_samples, (int, np.integer)) or delay_samples < 0:
        raise FjmValueError(f"delay_samples = {delay_samples!r}: expected an integer >= 0 (samples of delay)")
    if not isinstance(predict, (bool, np.bool_)):
        raise FjmValueError(f"predict = {predict!r}: expected True or False")
    if loop != "sampled":  # the keyword of simulate and simulate_batch: one loop remains
        raise FjmValueError(f"loop = {loop!r}: expected 'sampled'")
    return sensor, int(delay_samples)
