"""The sample step of the sampled-data loop: ONE definition, used by every backend.

At sample ``k`` (``t_k = k T``), from the step state ``w_k`` (layout :class:`StepLayout`)::

    m_true = x_k                          (state sensing, 4n)
           = [q; dq; K (q_m - q); K (dq_m - dq); dq_m]   (torque sensing, 5n, K TRUE)
    m_k    = m_true + noise_k             (noise generated outside, sim/sensor.py)
             dtau_J 'filtered': d_k = d_{k-1} + a ((tau_k - tau_{k-1}) / T - d_{k-1}), a = 1 - exp(-w_c T)
             encoders: q (and q_m) -> step * floor(value / step + 0.5)
    m_used = m_{k-d}                      (ring buffer of the d last measurements; d = 0: m_k)
             predict: x_hat from m_{k-d} (torque sensing: q_m = q + K_nom^-1 tau_J), integrated
             over d samples of the NOMINAL model under u_{k-d} .. u_{k-1}, m_used = its measurement
    u_k, s_k, y_hat_k = law(m_used, z_k, r_k)            (NOMINAL parameters)
    z_{k+1} = z_k + T z_dot(m_used, z_k, r_k, u_k)        (a digital controller: once per sample)
    x_{k+1} = substeps RK4 steps of T / substeps of x' = f(x; p) + g(x; p) u_k   (TRUE p, u held)

The CasADi form (:func:`casadi_sample_step`) is ``fjm_sample_step(w, r, noise, p) -> (w_next, aux)``
with plain vectors: ``w`` (nw), ``r`` (5n, the reference rows at ``t_k`` stacked), ``noise`` (nm),
``p`` (n_params, TRUE), ``aux = [u; s; y_hat]`` (6n). A batch engine folds it over samples.
The numpy form (:func:`python_sample_step`) does the same arithmetic through the model's
``f``/``g`` and the controller's ``evaluate``/``state_derivative``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..validation import FjmValueError
from .sensor import SensorModel
from .step import casadi_functions

__all__ = ["StepLayout", "casadi_sample_step", "check_loop_settings", "initial_measurement", "initial_step_state", "make_layout",
           "python_sample_step", "sample_step_function",
           "stiffness_indices"]


def stiffness_indices(model):
    """Indices of ``K_i`` and ``J_mi`` in ``model.param_names``: ``(idx_K, idx_Jm)``, each shape (n,)."""
    names, n = list(model.param_names), int(model.n)
    groups = (["K"], ["J_m"]) if (n == 1 and "K" in names) else \
        ([f"K{i + 1}" for i in range(n)], [f"Jm{i + 1}" for i in range(n)])
    try:
        return tuple(np.array([names.index(g) for g in grp], dtype=int) for grp in groups)
    except ValueError:
        raise FjmValueError(f"model {getattr(model, 'name', '?')!r}: torque sensing needs the stiffness "
                            f"parameters {groups[0]} (found {names})") from None


@dataclass(frozen=True)
class StepLayout:
    """Sizes and settings of the sample step; ``w = [x | z | m_buf | u_buf | filt]``.

    Attributes
    ----------
    n, nx, nz : int
        Joints, plant states (4n), controller states.
    sensing : {'state', 'torque'}
    nm : int
        Measurement size (4n or 5n).
    delay : int
        ``d``: ``m_buf`` holds ``d`` measurements (oldest first), ``u_buf`` ``d`` torques.
    predict : bool
    filtered : bool
        dtau_J as a filtered difference; ``filt = [tau_prev; dtau_filtered]`` (2n), else empty.
    T : float
        Control period, s.
    substeps : int
    a_filter : float
        ``1 - exp(-cutoff T)``.
    q_quant, q_m_quant : float
    idx_K : tuple of int
        Where ``K_i`` sit in the parameter vector.
    K_nom : tuple of float
    """

    n: int
    nx: int
    nz: int
    sensing: str
    nm: int
    delay: int
    predict: bool
    filtered: bool
    T: float
    substeps: int
    a_filter: float
    q_quant: float
    q_m_quant: float
    idx_K: tuple
    K_nom: tuple

    @property
    def nw(self) -> int:
        return self.nx + self.nz + self.delay * (self.nm + self.n) + (2 * self.n if self.filtered else 0)

    def slices(self):
        """``(x, z, m_buf, u_buf, filt)`` slices of ``w``."""
        a = self.nx; b = a + self.nz; c = b + self.delay * self.nm; d = c + self.delay * self.n
        return slice(0, a), slice(a, b), slice(b, c), slice(c, d), slice(d, self.nw)


def make_layout(model, controller, T: float, substeps: int, sensor: SensorModel, delay: int,
                predict: bool) -> StepLayout:
    """The :class:`StepLayout` of a run (the controller's ``sensing`` decides the measurement)."""
    n = int(model.n)
    sensing = getattr(controller, "sensing", "state")
    if sensing not in ("state", "torque"):
        raise FjmValueError(f"controller.sensing = {sensing!r}: expected 'state' or 'torque'")
    torque = sensing == "torque"
    idx_K = stiffness_indices(model)[0] if (torque or predict) else np.zeros(0, dtype=int)
    p_nom = np.asarray(getattr(controller, "p_nom", model.params_array({})), dtype=float)
    return StepLayout(n=n, nx=int(model.nx), nz=int(getattr(controller, "n_states", 0)), sensing=sensing,
                      nm=5 * n if torque else 4 * n, delay=int(delay), predict=bool(predict and delay > 0),
                      filtered=torque and sensor.dtau_mode == "filtered", T=float(T), substeps=int(substeps),
                      a_filter=1.0 - math.exp(-sensor.dtau_cutoff * T), q_quant=sensor.q_quant,
                      q_m_quant=sensor.q_m_quant, idx_K=tuple(int(i) for i in idx_K),
                      K_nom=tuple(float(v) for v in p_nom[idx_K]))


# -- the arithmetic, written once for numpy and CasADi ------------------------------------------

class _NumpyOps:
    def __init__(self, model):
        self.model = model

    cat = staticmethod(lambda parts: np.concatenate([np.asarray(p, dtype=float).ravel() for p in parts]))
    floor = staticmethod(np.floor)

    def xdot(self, x, u, p):
        nx, n = int(self.model.nx), int(self.model.n)
        return np.asarray(self.model.f(x, p), dtype=float).reshape(nx) + \
            np.asarray(self.model.g(x, p), dtype=float).reshape(nx, n) @ u

    def take(self, p, idx):
        return np.asarray(p)[list(idx)]

    const = staticmethod(lambda a: np.asarray(a, dtype=float))


class _CasadiOps:
    def __init__(self, fns, nx, n):
        import casadi as ca
        self.ca, self.fns, self.nx, self.n = ca, fns, nx, n

    def cat(self, parts):
        return self.ca.vertcat(*parts)

    def floor(self, v):
        return self.ca.floor(v)

    def xdot(self, x, u, p):
        ca = self.ca
        return self.fns["f"](x, p) + ca.mtimes(ca.reshape(self.fns["g"](x, p), self.nx, self.n), u)

    def take(self, p, idx):
        return self.ca.vertcat(*[p[i] for i in idx])

    def const(self, a):
        return self.ca.DM(np.asarray(a, dtype=float))


def _measure(ops, L: StepLayout, x, K):
    """The true measurement of ``x`` (state: x; torque: [q; dq; K(q_m - q); K(dq_m - dq); dq_m])."""
    if L.sensing == "state":
        return x
    n = L.n
    q, dq, qm, dqm = x[0:n], x[n:2 * n], x[2 * n:3 * n], x[3 * n:4 * n]
    return ops.cat([q, dq, K * (qm - q), K * (dqm - dq), dqm])


def _quantize(ops, v, step: float):
    return v if step == 0 else step * ops.floor(v / step + 0.5)


def _sense(ops, L: StepLayout, x, filt, noise, p):
    """``(m_k, filt_next)``: noisy, filtered, quantized measurement of sample k."""
    n = L.n
    K = ops.take(p, L.idx_K) if L.sensing == "torque" else None
    m = _measure(ops, L, x, K) + noise
    parts = [m[b * n:(b + 1) * n] for b in range(L.nm // n)]
    parts[0] = _quantize(ops, parts[0], L.q_quant)
    if L.sensing == "state":
        parts[2] = _quantize(ops, parts[2], L.q_m_quant)
    filt_next = filt
    if L.filtered:
        tau, tau_prev, d_prev = parts[2], filt[0:n], filt[n:2 * n]
        d = d_prev + L.a_filter * ((tau - tau_prev) / L.T - d_prev)
        parts[3] = d
        filt_next = ops.cat([tau, d])
    return ops.cat(parts), filt_next


def _plant(ops, L: StepLayout, x, u, p):
    """``substeps`` RK4 steps of ``T / substeps`` under the held ``u``."""
    h = L.T / L.substeps
    for _ in range(L.substeps):
        k1 = ops.xdot(x, u, p)
        k2 = ops.xdot(x + 0.5 * h * k1, u, p)
        k3 = ops.xdot(x + 0.5 * h * k2, u, p)
        k4 = ops.xdot(x + h * k3, u, p)
        x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x


def _predict(ops, L: StepLayout, m_old, u_buf, p_nom):
    """The measurement predicted ``d`` samples ahead from ``m_old`` with the NOMINAL model."""
    n = L.n
    if L.sensing == "state":
        x = m_old
    else:
        K = ops.const(L.K_nom)
        q, dq, tau, dqm = m_old[0:n], m_old[n:2 * n], m_old[2 * n:3 * n], m_old[4 * n:5 * n]
        x = ops.cat([q, dq, q + tau / K, dqm])
    for j in range(L.delay):
        x = _plant(ops, L, x, u_buf[j * n:(j + 1) * n], p_nom)
    return _measure(ops, L, x, ops.const(L.K_nom))


def _pre_law(ops, L: StepLayout, w, noise, p, p_nom):
    """Sensor, delay and prediction: ``(m_used, m_buf_next, filt_next)``."""
    _, _, sb, su, sf = L.slices()
    x = w[0:L.nx]
    m_k, filt_next = _sense(ops, L, x, w[sf], noise, p)
    if L.delay == 0:
        return m_k, w[sb], filt_next
    buf = w[sb]
    m_old = buf[0:L.nm]
    m_buf_next = ops.cat([buf[L.nm:], m_k]) if L.delay > 1 else m_k
    m_used = _predict(ops, L, m_old, w[su], p_nom) if L.predict else m_old
    return m_used, m_buf_next, filt_next


def _post_law(ops, L: StepLayout, w, u, zdot, m_buf_next, filt_next, p):
    """``w_next`` from the law's torque and the controller-state rate."""
    sx, sz, _, su, _ = L.slices()
    z_next = w[sz] + L.T * zdot if L.nz else w[sz]
    parts = [_plant(ops, L, w[sx], u, p), z_next]
    if L.delay:
        ub = w[su]
        parts += [m_buf_next, ops.cat([ub[L.n:], u]) if L.delay > 1 else u]
    if L.filtered:
        parts.append(filt_next)
    return ops.cat(parts)


def python_sample_step(model, controller, L: StepLayout, w, t: float, r, noise, p):
    """One sample in numpy: ``(w_next, sample)`` (``sample`` the controller's ControlSample)."""
    ops = _NumpyOps(model)
    p_nom = np.asarray(controller.p_nom, dtype=float) if L.predict else None
    m_used, m_buf_next, filt_next = _pre_law(ops, L, w, noise, p, p_nom)
    sz = L.slices()[1]
    z = w[sz]
    r = np.asarray(r, dtype=float).reshape(5, L.n)
    sample = controller.evaluate(t, m_used, z, r)
    zdot = np.asarray(controller.state_derivative(t, m_used, z, r, sample), dtype=float) if L.nz else None
    return _post_law(ops, L, w, np.asarray(sample.u, dtype=float), zdot, m_buf_next, filt_next, p), sample


def casadi_sample_step(fns, controller, L: StepLayout, n_par: int):
    """``fjm_sample_step(w, r, noise, p) -> (w_next, aux)`` as a CasADi Function (MX graph).

    Parameters
    ----------
    fns : dict
        The model's CasADi Functions ``f``, ``g`` of ``(x, p)``.
    controller
        Has ``symbolic_evaluate(m, z, r)`` and ``symbolic_state_derivative(m, z, r, out)``.
    L : StepLayout
    n_par : int

    Returns
    -------
    casadi.Function
        Inputs ``w`` (nw,), ``r`` (5n,), ``noise`` (nm,), ``p`` (n_par,); outputs ``w_next`` (nw,),
        ``aux = [u; s; y_hat]`` (6n,).
    """
    import casadi as ca
    ops = _CasadiOps(_expanded(fns), L.nx, L.n)
    w, r = ca.MX.sym("w", L.nw), ca.MX.sym("r", 5 * L.n)
    noise, p = ca.MX.sym("noise", L.nm), ca.MX.sym("p", n_par)
    p_nom = ca.DM(np.asarray(controller.p_nom, dtype=float)) if L.predict else None
    m_used, m_buf_next, filt_next = _pre_law(ops, L, w, noise, p, p_nom)
    z = w[L.slices()[1]]
    out = controller.symbolic_evaluate(m_used, z, r)
    zdot = controller.symbolic_state_derivative(m_used, z, r, out) if L.nz else None
    w_next = _post_law(ops, L, w, out["u"], zdot, m_buf_next, filt_next, p)
    return ca.Function("fjm_sample_step", [w, r, noise, p],
                       [w_next, ca.vertcat(out["u"], out["s"], out["y_hat"])],
                       ["w", "r", "noise", "p"], ["w_next", "aux"])


def _expanded(fns):
    """``f`` and ``g`` as SX Functions (MX ones expanded) so that each substep is one call."""
    out = {}
    for k in ("f", "g"):
        fn = fns[k]
        try:
            out[k] = fn.expand() if fn.is_a("MXFunction") else fn
        except Exception:  # noqa: BLE001 - keep a Function that cannot be expanded as it is
            out[k] = fn
    return out


def initial_step_state(model, L: StepLayout, x0, z0, p_true) -> np.ndarray:
    """``w_0``: the plant and controller states, the buffers filled with the noise-free measurement of
    ``x0`` and zero torques (the plant rests at ``x0`` before ``t = 0``), the filter at the true
    ``tau_J(x0)``, ``dtau_J(x0)``."""
    ops = _NumpyOps(model)
    K = ops.take(p_true, L.idx_K) if L.sensing == "torque" else None
    m0 = np.asarray(_measure(ops, L, np.asarray(x0, dtype=float), K), dtype=float)
    parts = [x0, z0]
    if L.delay:
        parts += [np.tile(m0, L.delay), np.zeros(L.delay * L.n)]
    if L.filtered:
        parts.append(m0[2 * L.n:4 * L.n])
    return ops.cat(parts)


def initial_measurement(model, L: StepLayout, x0, p_true) -> np.ndarray:
    """The noise-free measurement of ``x0`` (what the controller's ``initial_state`` is given)."""
    ops = _NumpyOps(model)
    K = ops.take(p_true, L.idx_K) if L.sensing == "torque" else None
    return np.asarray(_measure(ops, L, np.asarray(x0, dtype=float), K), dtype=float)


def sample_step_function(model, controller, L: StepLayout):
    """The CasADi sample step of ``(model, controller, layout)`` (rebuilt per call: gains are baked in)."""
    return casadi_sample_step(casadi_functions(model), controller, L, len(model.param_names))


def check_loop_settings(sensor, delay_samples, predict):
    """The sensor (default ideal), the delay and the prediction flag of a sampled-data loop, checked.

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
        raise FjmValueError(f"sensor = {sensor!r}: expected a SensorModel (e.g. SensorModel.panda())")
    if isinstance(delay_samples, bool) or not isinstance(delay_samples, (int, np.integer)) or delay_samples < 0:
        raise FjmValueError(f"delay_samples = {delay_samples!r}: expected an integer >= 0 (samples of delay)")
    if not isinstance(predict, (bool, np.bool_)):
        raise FjmValueError(f"predict = {predict!r}: expected True or False")
    return sensor, int(delay_samples)
