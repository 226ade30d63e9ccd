"""The controller half of THE sample step as CasADi Functions: what ``fjm export controller`` compiles.

The sample step (:mod:`fjm_runtime.sim.sample_step`) is a plant and a digital controller. The
controller half, from the raw reading of sample ``k`` on, is::

    m_k      = condition(m_raw)            differentiated velocities, filtered dtau_J (as the step)
    m_used   = delay buffer / prediction   over d samples of the NOMINAL model, RK4 substeps
    u_law    = law(m_used, z, r; p_nom, gains)    saturation and anti-windup inside the law
    u        = clip(u_law, u_last - R T, u_last + R T)
    z_next   = z + T zdot  (error integral frozen while the rate limit holds the torque back)

Two Functions, both of plain vectors (``nc`` = controller-state size, :class:`ControllerLayout`):

``<name>_ctrl_step(c, m, r, p, gains) -> (u, c_next, s, y_hat, held)``
    ``c`` (nc) the controller state, ``m`` (nm) the raw reading (:func:`raw_reading`), ``r`` (5n)
    the reference rows at ``t_k`` stacked, ``p`` the NOMINAL parameters (``model.param_names``),
    ``gains`` the law's gains vector (manifest layout, ``controller.gains``); ``u`` the applied
    torque, ``held`` per joint: 1 if the torque limit clipped it, + 2 if the rate limit did.
``<name>_ctrl_reset(m0, p) -> (c0, u0)``
    The rest state of :func:`fjm_runtime.sim.sample_step.initial_step_state` from a reading of the
    arm at rest: buffers full of ``m0``, the torques that hold it (torque sensing: the measured
    tau_J; state sensing: the spring law ``psi_nom(q_m - q)``, ``K_nom (q_m - q)`` for a linear spring), filters at
    the reading, zero integral.

The arithmetic is the sample step's own helpers (``_condition``, ``_delayed``, ``_rate_limited``,
``_rate_windup``), so the library and the simulator cannot drift apart; only ``p`` and ``gains``
are inputs here instead of constants.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..drives import model_springs
from ..sim import sample_step as ss
from ..sim.actuation import rate_limited, rate_windup
from ..sim.interface import gravity_function
from ..sim.step import casadi_functions
from ..sim.step_layout import StepLayout
from ..validation import FjmValueError

__all__ = ["ControllerLayout", "controller_functions", "raw_reading", "rest_reading"]


@dataclass(frozen=True)
class ControllerLayout:
    """Where things sit in the controller state ``c = [z | m_buf | u_buf | filt | venc | u_last]``.

    It is the sample step's ``w`` without the robot's parts: the plant state ``x``, the sensor's
    offset, the current loop's motor torque and, with a ``joint_torque`` interface, the vendor layer's
    last command (the robot filters and limits ``tau_d``; the library outputs ``tau_d``):
    ``c = w[robot_mask()]`` (:meth:`from_step_state`). ``u_last`` is the last torque of a ``motor``
    interface's rate limit, which the library applies.
    """

    step: StepLayout

    @property
    def nc(self) -> int:
        L = self.step
        return int(np.count_nonzero(self.robot_mask()))

    def blocks(self):
        """``[(name, offset, size)]`` of ``c`` in order (sizes may be 0)."""
        L = self.step
        sizes = [("z", L.nz), ("m_buf", L.delay * L.nm), ("u_buf", L.delay * L.n),
                 ("filt", 2 * L.n if L.filtered else 0), ("venc", L.n_venc),
                 ("u_last", L.n if self.limits_rate else 0)]
        out, o = [], 0
        for name, size in sizes:
            out.append((name, o, size))
            o += size
        return out

    def split(self, c):
        """The blocks of ``c`` by name (slices of a CasADi vector or ndarray)."""
        return {name: c[o:o + size] for name, o, size in self.blocks()}

    @property
    def limits_rate(self) -> bool:
        """True when the library applies the rate limit (a ``motor`` interface with one)."""
        return bool(self.step.rate_step) and self.step.interface == "motor"

    def robot_mask(self) -> np.ndarray:
        """Which entries of the step state ``w`` (nw,) are the controller's (False: the robot's)."""
        L = self.step
        keep = np.ones(L.nw, dtype=bool)
        keep[:L.nx] = False
        _, off, last, cur = L.extra_slices()
        keep[off] = keep[cur] = False
        if not self.limits_rate:
            keep[last] = False
        return keep

    def from_step_state(self, W) -> np.ndarray:
        """``c`` of step states ``W`` (nw,) or (N, nw): the controller's entries (:meth:`robot_mask`)."""
        return np.asarray(W, dtype=float)[..., self.robot_mask()]


def raw_reading(model, L: StepLayout, w, noise, p_true) -> np.ndarray:
    """The raw reading of sample k that the robot hands the controller (NumPy), shape (nm,).

    Noise, quantization and the tau_J offset included; with ``velocity_mode='differentiated'`` and
    torque sensing the dq_m slot carries the measured motor angle (:func:`~fjm_runtime.sim.sample_step._reading`).
    """
    ops = ss._NumpyOps(model)
    return np.asarray(ops.cat(ss._reading(ops, L, np.asarray(w, dtype=float), np.asarray(noise, dtype=float),
                                          np.asarray(p_true, dtype=float))), dtype=float)


def rest_reading(model, L: StepLayout, x0, p_true) -> np.ndarray:
    """The exact reading of a rest state ``x0`` (no noise, quantization or offset), shape (nm,).

    What ``initial_step_state`` starts the simulator's buffers from, in the raw-reading layout
    (torque sensing with differentiated velocities: the motor angle in the dq_m slot).
    """
    ops = ss._NumpyOps(model)
    x0 = np.asarray(x0, dtype=float)
    p_true = np.asarray(p_true, dtype=float)
    m = np.array(ss._measure(ops, L, x0, p_true), dtype=float)
    if L.differentiated and L.sensing == "torque":
        m[4 * L.n:] = x0[2 * L.n:3 * L.n]
    return m


class _RuntimeLaw:
    """The emitted law with the nominal parameters and gains as symbols (not constants)."""

    def __init__(self, controller, p, gains):
        self.law, self.zdot = controller.law_functions()
        self.p, self.gains = p, gains

    def evaluate(self, m, z, r):
        u, s, _, u_cmd, y_hat = self.law(m, z, r, self.p, self.gains)
        return {"u": u, "u_cmd": u_cmd, "s": s, "y_hat": y_hat}

    def state_derivative(self, m, z, r, out):
        return self.zdot(m, z, r, self.p, self.gains, out["u_cmd"], out["u"])


def _blocks(v, L: StepLayout):
    n = L.n
    return [v[b * n:(b + 1) * n] for b in range(L.nm // n)]


def controller_functions(model, controller, L: StepLayout, name: str):
    """``(step, reset)``: the controller's CasADi Functions (SX, each RK4 substep one outlined call).

    Parameters
    ----------
    model : Model
        The controller's (nominal) model: its ``f``, ``g`` predict, its ``param_names`` order ``p``.
    controller : SlidingModeController
        Supplies the emitted law (``law_functions``) and ``law_kind``; its gains are NOT baked in.
    L : StepLayout
        The design's loop (period, substeps, sensor pre-processing, delay, prediction, rate limit).
    name : str
        C prefix: the Functions are ``<name>_ctrl_step`` and ``<name>_ctrl_reset``.

    Returns
    -------
    (casadi.Function, casadi.Function)
    """
    if not hasattr(controller, "law_functions") or getattr(controller, "_law_z_offset", lambda: 0)() != 0:
        raise FjmValueError(f"controller {type(controller).__name__}: expected a sliding-mode controller with an "
                            "emitted law (smc, ismc, fl, sign, torque-sensed or not)")
    fns = casadi_functions(model)
    if fns is None:
        raise FjmValueError(f"model {model.name!r}: no CasADi Functions f, g to predict with")
    fns = dict(fns, **model_springs(model))  # the spring law's psi, psi^-1 (prediction, rest torque)
    if L.interface == "joint_torque":        # the predictor runs the robot's torque loop with its gravity
        fns["gravity"] = gravity_function(model)
    n, n_par = L.n, len(model.param_names)
    CL = ControllerLayout(L)
    n_gains = int(np.asarray(controller.gains).size)
    h = L.T / L.predictor_substeps  # the ops integrate only the predictor here
    ops = ss._CasadiOps(ss._expanded(fns), L.nx, n, h)
    c, m_raw = ca.MX.sym("c", CL.nc), ca.MX.sym("m", L.nm)
    r, p, gains = ca.MX.sym("r", 5 * n), ca.MX.sym("p", n_par), ca.MX.sym("gains", n_gains)
    b = CL.split(c)
    m_k, filt_next, venc_next = ss._condition(ops, L, _blocks(m_raw, L), b["venc"], b["filt"])
    ops.p_gravity = p                        # the library's nominal parameters (joint_torque's gravity)
    m_used, m_buf_next = ss._delayed(ops, ops, L, m_k, b["m_buf"], b["u_buf"], p)
    law = _RuntimeLaw(controller, p, gains)
    out = law.evaluate(m_used, b["z"], r)
    u_law = out["u"]
    u = rate_limited(ops, L, b["u_last"], u_law) if CL.limits_rate else u_law
    parts = []
    if L.nz:
        zdot = law.state_derivative(m_used, b["z"], r, out)
        if L.integral and CL.limits_rate:
            zdot = rate_windup(ops, L, zdot, u_law, u, m_used[:n] - r[:n])
        parts.append(b["z"] + L.T * zdot)
    if L.delay:
        ub = b["u_buf"]
        parts += [m_buf_next, ops.cat([ub[n:], u]) if L.delay > 1 else u]
    if L.filtered:
        parts.append(filt_next)
    if L.differentiated:
        parts.append(venc_next)
    if CL.limits_rate:
        parts.append(u)
    c_next = ca.vertcat(*parts) if parts else ca.MX(0, 1)
    held = ((out["u_cmd"] > u_law) + (out["u_cmd"] < u_law)) + 2 * ((u_law > u) + (u_law < u))
    step = ca.Function(f"{name}_ctrl_step", [c, m_raw, r, p, gains], [u, c_next, out["s"], out["y_hat"], held],
                       ["c", "m", "r", "p", "gains"], ["u", "c_next", "s", "y_hat", "held"])
    return _sx(step), _sx(_reset_function(model, L, CL, name, ops))


def _reset_function(model, L: StepLayout, CL: ControllerLayout, name: str, ops):
    """``<name>_ctrl_reset(m0, p) -> (c0, u0)`` (the conventions of ``initial_step_state``)."""
    n = L.n
    m0, p = ca.MX.sym("m0", L.nm), ca.MX.sym("p", len(model.param_names))
    parts = _blocks(m0, L)
    zero = ca.MX.zeros(n, 1)
    qm = None
    i_dqm = ss._slot(L, "dq_m")
    if L.differentiated:                      # computed velocities of an arm at rest: zero
        qm = parts[4] if L.sensing == "torque" else parts[2]
        parts[1] = zero
        parts[i_dqm] = zero
    if L.filtered:
        parts[ss._slot(L, "dtau_J")] = zero
    m_rest = ca.vertcat(*parts)
    # the measured tau_J holds the arm; state sensing: the spring law at the read deflection
    spring = parts[ss._slot(L, "tau_J")] if L.sensing != "state" else ops.spring(parts[2] - parts[0], p)[0]
    if L.interface == "joint_torque":          # the command holding the rest excludes the robot's gravity
        spring = spring - gravity_function(model)(parts[0], p)
    out = [ca.MX.zeros(L.nz, 1)] if L.nz else []
    if L.delay:
        out += [ca.repmat(m_rest, L.delay, 1), ca.repmat(spring, L.delay, 1)]
    if L.filtered:
        out.append(m_rest[ss._slot(L, "tau_J") * n:(ss._slot(L, "dtau_J") + 1) * n])
    if L.differentiated:
        out.append(ca.vertcat(parts[0], parts[1], qm, parts[i_dqm]))
    if CL.limits_rate:
        out.append(spring)
    c0 = ca.vertcat(*out) if out else ca.MX(0, 1)
    return ca.Function(f"{name}_ctrl_reset", [m0, p], [c0, spring], ["m0", "p"], ["c0", "u0"])


def _sx(fn):
    """``fn`` expanded to SX (straight-line C; outlined substeps stay calls)."""
    try:
        return fn.expand()
    except Exception:  # noqa: BLE001 - a graph that cannot be expanded stays MX (still code-generatable)
        return fn
