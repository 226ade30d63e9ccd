"""A control law for the complete elastic model: the reduced law with the rotor coupling compensated.

The complete model (docs/complete-model.md) has no static feedback linearization, so no law is
emitted for it; its reduced model's laws can drive it (same state layout), but they ignore the
rotor spin coupling. This module adds the coupling back around an emitted reduced law, at the
NOMINAL parameters of both models:

Complete link and motor equations, written against the reduced ones::

    D ddq + h(q, dq)            + K (q - q_m) = -d_l,   d_l = (D' - D) ddq + S ddq_m + (h' + c_l - h)
    J_m ddq_m + B_m dq_m        - K (q - q_m) = u - d_m, d_m = S^T ddq + c_m

``d_l`` and ``d_m`` are computed from the complete model's emitted ``f``, ``inertia`` (``M``) and
``coupling`` (``S``) and the reduced model's ``f`` and ``inertia`` (``D``): with ``a' = M^-1 rhs'``
the complete accelerations at ``u = 0`` and ``a_r`` the reduced ones, ``h' + c_l - h =
D a_r,q - (M a')_q`` and ``c_m = J_m a_r,m - (M a')_m`` (the spring and damping terms cancel).

The law (:class:`CouplingCompensatedController`) shifts the motor state the reduced law sees by the
link-side term, ``q~_m = q_m - K^-1 d_l``, ``dq~_m = dq_m - K^-1 d_l'`` (then ``K (q~_m - q)`` is the
spring torque the links actually feel, and the reduced law's ``y3, y4`` are the true link
acceleration and jerk), and adds to the reduced law's torque ``u_r(x~)`` what the motor side needs::

    u = u_r(x~) + d_l + d_m + K^-1 (B_m d_l' + J_m d_l'')

``d_l``, ``d_m`` depend on the accelerations (the input reaches them directly through ``S``: that
is why no static law exists), so they are estimated, in one of two ways (``source``):

- ``'measured'`` (default): the nominal complete model's accelerations at the measured state under
  the torque held over the previous sample (kept in the controller state); ``d_l'``, ``d_l''``
  (``order`` 1, 2; default 0: not used) are derivatives along ``f + g u_prev``.
- ``'reference'``: a feedforward along the reference: ``q, dq, ddq`` of the reference,
  ``dq_m = dq_d``, ``ddq_m = ddq_d`` (the spring deflection's derivatives are ``O(K^-1)``), and
  ``d_l'``, ``d_l''`` their time derivatives along it (CasADi forward AD with the reference's jerk
  and snap). Exact on the reference, first order off it.

:func:`complete_plant` wraps a complete model as a plant for
:func:`fjm_runtime.sim.simulate.simulate` (which also evaluates the reduced model's ``T`` of the
plant state for its ``y`` output).
"""
from __future__ import annotations

from typing import Dict

import numpy as np

from ..drives import drive_indices
from ..validation import FjmValueError

__all__ = ["CompletePlant", "CouplingCompensatedController", "complete_plant", "coupling_function", "coupling_terms"]


def _check_pair(complete, reduced) -> None:
    """One-line error unless ``complete`` is a complete model whose reduced model is ``reduced``."""
    if getattr(complete, "form", "reduced") != "complete":
        raise FjmValueError(f"model {getattr(complete, 'name', complete)!r}: expected a complete model "
                            "(manifest form 'complete', e.g. panda_complete)")
    if complete.reduced_model != reduced.name:
        raise FjmValueError(f"reduced model {reduced.name!r}: expected {complete.reduced_model!r}, the reduced "
                            f"model of {complete.name!r}")
    n_red = len(reduced.param_names)
    if tuple(complete.param_names[:n_red]) != tuple(reduced.param_names):
        raise FjmValueError(f"model {complete.name!r}: its first parameters are not {reduced.name!r}'s "
                            "(expected the reduced model's param_names, then N1..Nn)")


def _reduced_view(fn, n_par: int, n_red: int, name: str):
    """``fn(x, p_red)`` as a Function of ``(x, p)`` that reads the first ``n_red`` entries of ``p``."""
    import casadi as ca
    x = ca.SX.sym("x", fn.size1_in(0))
    p = ca.SX.sym("p", n_par)
    return ca.Function(name, [x, p], [fn(x, p[:n_red])], ["x", "p"], [fn.name_out(0)])


class CompletePlant:
    """A complete model as a simulation plant: its ``f``, ``g``; ``T``, ``alpha``, ``beta`` of the reduced model.

    :func:`fjm_runtime.sim.simulate.simulate` needs ``T`` (for the result's true ``y``) and looks
    for ``alpha`` and ``beta`` among the plant's Functions; a complete model has none of them
    (no static feedback linearization). Here they are the reduced model's, evaluated on the
    reduced model's parameters (the first entries of the complete parameter vector): ``y`` of the
    result is then the reduced model's linearizing coordinates of the complete plant's state.
    The dynamics (``f``, ``g``) are the complete model's.

    Attributes
    ----------
    name, n, nx, param_names, default_params, form, reduced_model, drives, parameter_info
        As the complete model's (``form`` is ``'complete'``).
    functions : dict str -> casadi.Function
        ``f``, ``g``, ``inertia``, ``coupling``, ``energy`` of the complete model; ``T``, ``alpha``,
        ``beta`` of the reduced one, of ``(x (4n,), p (n_params,))``.
    """

    def __init__(self, complete, reduced):
        _check_pair(complete, reduced)
        self.complete, self.reduced = complete, reduced
        self.name, self.n, self.nx = complete.name, int(complete.n), int(complete.nx)
        self.param_names, self.default_params = complete.param_names, complete.default_params
        self.form, self.reduced_model = complete.form, complete.reduced_model
        self.manifest = complete.manifest
        self.drives, self.parameter_info = complete.drives, complete.parameter_info
        self.spring_functions = complete.spring_functions
        n_par, n_red = len(complete.param_names), len(reduced.param_names)
        self.functions: Dict[str, object] = dict(complete.functions)
        for q in ("T", "alpha", "beta"):
            self.functions[q] = _reduced_view(reduced.functions[q], n_par, n_red, q)

    def __repr__(self) -> str:
        return f"<CompletePlant {self.name} (T, alpha, beta of {self.reduced.name})>"

    def params_array(self, p=None, arg: str = "p") -> np.ndarray:
        """The complete model's parameter vector, shape (n_params,)."""
        return self.complete.params_array(p, arg)

    def state_array(self, x, arg: str = "x") -> np.ndarray:
        """``x`` as a validated vector of shape ``(nx,)``."""
        return self.complete.state_array(x, arg)

    def _call(self, q: str, x, p) -> np.ndarray:
        return self.functions[q](self.state_array(x), self.params_array(p)).full()

    def f(self, x, p=None) -> np.ndarray:
        """Complete drift ``f(x)``, shape (4n,)."""
        return self._call("f", x, p).ravel()

    def g(self, x, p=None) -> np.ndarray:
        """Complete input matrix ``g(x)``, shape (4n, n)."""
        return self._call("g", x, p)

    def T(self, x, p=None) -> np.ndarray:
        """The REDUCED model's ``T(x)``, shape (4n,)."""
        return self._call("T", x, p).ravel()

    def inertia(self, x, p=None) -> np.ndarray:
        """Complete ``M(q)``, shape (2n, 2n)."""
        return self._call("inertia", x, p)

    def coupling(self, x, p=None) -> np.ndarray:
        """``S(q)``, shape (n, n)."""
        return self._call("coupling", x, p)

    def xdot(self, x, u, p=None) -> np.ndarray:
        """``f(x) + g(x) u``, shape (4n,)."""
        return self.f(x, p) + self.g(x, p) @ np.asarray(u, dtype=float).ravel()


def complete_plant(complete, reduced=None) -> CompletePlant:
    """``complete`` (a Model or a name) as a plant for ``simulate``; ``reduced`` default: its reduced model."""
    from ..model import load
    c = load(complete) if isinstance(complete, str) else complete
    if reduced is None:
        if getattr(c, "reduced_model", None) is None:
            raise FjmValueError(f"model {getattr(c, 'name', c)!r}: expected a complete model (it names no "
                                "reduced model)")
        reduced = c.reduced_model
    r = load(reduced) if isinstance(reduced, str) else reduced
    return CompletePlant(c, r)


def _param(model, p, role: str) -> np.ndarray:
    """One drive ``role`` per joint (``model.drives``) of parameter vector ``p`` of ``model``, shape (n,)."""
    return np.asarray(p, dtype=float)[drive_indices(model, role)]


def coupling_terms(complete, reduced, x, ddq, ddq_m, p):
    """``(d_l, d_m)``: what the complete equations add to the reduced ones at ``x`` and the accelerations.

    Parameters
    ----------
    complete, reduced : Model
        The complete model and its reduced model.
    x : array_like or casadi SX, shape (4n,)
    ddq, ddq_m : array_like or casadi SX, shape (n,)
        Link and motor accelerations.
    p : array_like, shape (n_params,)
        The complete model's parameters (the reduced model reads the first entries).

    Returns
    -------
    d_l, d_m : shape (n,) (numpy) or (n, 1) (SX)
        ``d_l = (D' - D) ddq + S ddq_m + h' + c_l - h`` and ``d_m = S^T ddq + c_m`` (module docstring).
    """
    import casadi as ca
    n = int(complete.n)
    symbolic = any(isinstance(v, (ca.SX, ca.MX)) for v in (x, ddq, ddq_m))
    if not symbolic:
        x, ddq, ddq_m = (ca.DM(np.asarray(v, dtype=float).ravel()) for v in (x, ddq, ddq_m))
        p = ca.DM(np.asarray(p, dtype=float).ravel())
    pr = p[:len(reduced.param_names)]
    fc, Mc, Sc = complete.functions["f"], complete.functions["inertia"], complete.functions["coupling"]
    fr, Dr = reduced.functions["f"], reduced.functions["inertia"]
    M, S, D = Mc(x, p), Sc(x, p), Dr(x, pr)
    ac, ar = fc(x, p), fr(x, pr)
    Ma = ca.mtimes(M, ca.vertcat(ac[n:2 * n], ac[3 * n:4 * n]))
    Jm = ca.diag(ca.diag(M[n:, n:]))
    bias_l = ca.mtimes(D, ar[n:2 * n]) - Ma[:n]
    c_m = ca.mtimes(Jm, ar[3 * n:4 * n]) - Ma[n:]
    d_l = ca.mtimes(M[:n, :n] - D, ddq) + ca.mtimes(S, ddq_m) + bias_l
    d_m = ca.mtimes(S.T, ddq) + c_m
    if symbolic:
        return d_l, d_m
    return np.asarray(d_l).ravel(), np.asarray(d_m).ravel()


def _compensation(complete, pv, x, d_l, d_l1, d_l2, d_m, motor: bool):
    """``(x_tilde, u_add)`` of the module docstring from ``d_l`` and its first two derivatives, at the
    NOMINAL stiffness, motor damping and rotor inertia of ``pv`` (CasADi)."""
    import casadi as ca
    n = int(complete.n)
    K, B, Jm = (ca.DM(_param(complete, pv, k)) for k in ("stiffness", "damping", "rotor_inertia"))
    x_t = ca.vertcat(x[:2 * n], x[2 * n:3 * n] - d_l / K, x[3 * n:] - d_l1 / K)
    return x_t, d_l + (d_m if motor else 0) + (B * d_l1 + Jm * d_l2) / K


def coupling_function(complete, reduced, p_nom, motor: bool = True):
    """``comp(x, r) -> (x_tilde, u_add, d_l, d_m)``: the compensation of the module docstring, in CasADi.

    Parameters
    ----------
    complete, reduced : Model
    p_nom : ndarray, shape (n_params,)
        NOMINAL parameters of the complete model (baked in).
    motor : bool
        Include the motor-side term ``d_m`` in ``u_add`` (False: the link side only).

    Returns
    -------
    casadi.Function
        Inputs ``x`` (4n,) and ``r`` (5n,: the reference rows, position to 4th derivative);
        outputs ``x_tilde`` (4n,), ``u_add`` (n,), ``d_l`` (n,), ``d_m`` (n,) on the reference.
    """
    import casadi as ca
    n = int(complete.n)
    pv = np.asarray(p_nom, dtype=float)
    x, r = ca.SX.sym("x", 4 * n), ca.SX.sym("r", 5 * n)
    q, dq, ddq, d3, d4 = (ca.SX.sym(k, n) for k in ("q", "dq", "ddq", "d3", "d4"))
    Z, Zdot = ca.vertcat(q, dq, ddq, d3), ca.vertcat(dq, ddq, d3, d4)
    d_l, d_m = coupling_terms(complete, reduced, ca.vertcat(q, dq, q, dq), ddq, ddq, ca.DM(pv))
    d_l1 = ca.jtimes(d_l, Z, Zdot)
    d_l2 = ca.jtimes(d_l1, Z, Zdot)
    x_t, u_add = _compensation(complete, pv, x, d_l, d_l1, d_l2, d_m, motor)
    inner = ca.Function("inner", [q, dq, ddq, d3, d4, x], [x_t, u_add, d_l, d_m])
    out = inner(*[r[k * n:(k + 1) * n] for k in range(5)], x)
    return ca.Function("coupling_compensation", [x, r], list(out), ["x", "r"],
                       ["x_tilde", "u_add", "d_l", "d_m"])


def _derivatives(d_l, arg, rate, order: int):
    """``[d_l, d_l', ...]`` up to ``order`` along ``arg' = rate`` (CasADi forward AD)."""
    import casadi as ca
    out = [d_l]
    for _ in range(order):
        out.append(ca.jtimes(out[-1], arg, rate))
    return out + [ca.SX.zeros(d_l.shape)] * (2 - order)


def measured_coupling_function(complete, reduced, p_nom, motor: bool = True, order: int = 0):
    """``comp(x, u_prev) -> (x_tilde, u_add, d_l, d_m)``: the compensation from the measured state.

    The accelerations in ``d_l``, ``d_m`` are the complete NOMINAL model's at ``x`` under the torque
    held over the previous sample, ``u_prev``; ``d_l'`` and ``d_l''`` are derivatives along
    ``x' = f(x) + g(x) u_prev`` with the torque held (``order`` of them: 0, 1 or 2).

    Parameters
    ----------
    complete, reduced, p_nom, motor
        As :func:`coupling_function` (``p_nom`` baked in; ``motor``: ``d_m`` in ``u_add``).
    order : {0, 1, 2}
        Derivatives of ``d_l`` used (0: none, the motor shift and torque take ``d_l`` only).

    Returns
    -------
    casadi.Function
        Inputs ``x`` (4n,), ``u_prev`` (n,); outputs ``x_tilde`` (4n,), ``u_add``, ``d_l``, ``d_m`` (n,).
    """
    import casadi as ca
    if order not in (0, 1, 2):
        raise FjmValueError(f"order = {order!r}: expected 0, 1 or 2 (derivatives of the link-side term)")
    n = int(complete.n)
    pv = np.asarray(p_nom, dtype=float)
    p = ca.DM(pv)
    x, u = ca.SX.sym("x", 4 * n), ca.SX.sym("u_prev", n)
    xd = complete.functions["f"](x, p) + ca.mtimes(complete.functions["g"](x, p), u)
    d_l, d_m = coupling_terms(complete, reduced, x, xd[n:2 * n], xd[3 * n:], p)
    d_l, d_l1, d_l2 = _derivatives(d_l, x, xd, order)
    x_t, u_add = _compensation(complete, pv, x, d_l, d_l1, d_l2, d_m, motor)
    return ca.Function("measured_coupling_compensation", [x, u], [x_t, u_add, d_l, d_m], ["x", "u_prev"],
                       ["x_tilde", "u_add", "d_l", "d_m"])


class CouplingCompensatedController:
    """A reduced-model law driving a complete plant with the rotor coupling compensated (module docstring).

    Parameters
    ----------
    inner : SlidingModeController
        A state-feedback law of the REDUCED model (``make_controller(kind, reduced, nominal, ...)``,
        ``sensing='state'``); its torque limit ``u_max`` and anti-windup apply to the total torque.
    complete : Model
        The complete model whose coupling is compensated (``inner.model`` is its reduced model).
    nominal_params : dict or array_like, optional
        NOMINAL parameters of the complete model (default: ``inner``'s nominal parameters and the
        complete model's default gear ratios).
    dt : float
        The control sample time (s): the previous sample's torque is held in the controller state.
    source : {'measured', 'reference'}
        Accelerations in the coupling terms: the nominal complete model's at the measured state under
        the previous torque (``'measured'``), or the reference's (``'reference'``, a feedforward).
    motor : bool
        Include the motor-side term ``d_m``.
    order : {0, 1, 2}
        ``'measured'`` only: derivatives of ``d_l`` used (``'reference'`` always uses 2). Default 0:
        on the Panda at N = 100 the derivatives change the tracking by under 5 % and multiply the
        compiled loop's build time (docs/complete-model.md, "Control").

    newton : int
        ``'measured'`` only: Newton steps solving the implicit law ``u = u_r(x~(u)) + u_add(u)`` for the
        current sample's torque (from the previous one); 0: the previous torque is used as it is.

    Attributes
    ----------
    n_states : int
        ``inner.n_states + n``: the inner law's state, then the previous torque (``'measured'``; else
        ``inner.n_states``).
    p_nom : ndarray, shape (n_params,)
        The complete model's nominal parameter vector.
    """

    sensing = "state"

    def __init__(self, inner, complete, nominal_params=None, *, dt: float, source: str = "measured",
                 motor: bool = True, order: int = 0, newton: int = 0):
        if getattr(inner, "sensing", "state") != "state" or not hasattr(inner, "law_functions"):
            raise FjmValueError("inner: expected a state-feedback law of the reduced model "
                                "(make_controller(kind, reduced, nominal), sensing = 'state')")
        _check_pair(complete, inner.model)
        if source not in ("measured", "reference"):
            raise FjmValueError(f"source = {source!r}: expected 'measured' or 'reference'")
        if not (np.isfinite(dt) and dt > 0):
            raise FjmValueError(f"dt = {dt!r}: expected the control sample time in s, > 0")
        self.inner, self.complete, self.model = inner, complete, complete
        self.n, self.dt, self.source = int(complete.n), float(dt), source
        n_red = len(inner.model.param_names)
        if nominal_params is None:
            nominal_params = dict(zip(inner.model.param_names, inner.p_nom))
        self.p_nom = complete.params_array(nominal_params, "nominal_params")
        if not np.allclose(self.p_nom[:n_red], inner.p_nom, rtol=0, atol=0):
            raise FjmValueError("nominal_params: the reduced model's entries differ from the inner law's "
                                "nominal parameters (expected one nominal model)")
        self.delta, self.u_max = inner.delta, inner.u_max
        self.n_inner = int(inner.n_states)
        if source != "measured" and newton:
            raise FjmValueError("newton: Newton steps solve for the current torque; expected source = 'measured'")
        self.newton = int(newton)
        self.n_states = self.n_inner + (self.n if source == "measured" else 0)
        self.compensation = (measured_coupling_function(complete, inner.model, self.p_nom, motor, order)
                             if source == "measured" else coupling_function(complete, inner.model, self.p_nom, motor))
        self._K = _param(complete, self.p_nom, "stiffness")

    # -- the law, composed in CasADi (numeric calls go through the same graph) --
    def _split(self, x, z, r):
        """``(x_tilde, u_add, z_inner)`` of a sample (CasADi)."""
        src = z[self.n_inner:] if self.source == "measured" else r
        x_t, u_add = self.compensation(x, src)[:2]
        return x_t, u_add, z[:self.n_inner]

    def symbolic_evaluate(self, x, z, r, fns=None):
        """The compensated law in a CasADi graph: dict ``u``, ``u_cmd``, ``s`` (n, 1), ``y_hat`` (4n, 1).

        ``x`` (4n, 1) the plant state, ``z`` (n_states, 1), ``r`` (5n, 1) the reference rows.
        """
        import casadi as ca
        if self.newton:
            z = ca.vertcat(z[:self.n_inner], self._newton(x, z, r))
        x_t, u_add, z_in = self._split(x, z, r)
        out = self.inner.symbolic_evaluate(x_t, z_in, r)
        u_cmd = out["u_cmd"] + u_add
        u = u_cmd if self.u_max is None else ca.fmin(ca.fmax(u_cmd, -ca.DM(self.u_max)), ca.DM(self.u_max))
        return {"u": u, "u_cmd": u_cmd, "s": out["s"], "y_hat": out["y_hat"]}

    def _newton(self, x, z, r):
        """The torque solving ``u = u_r(x~(u)) + u_add(u)`` for this sample: :attr:`newton` Newton steps from ``u_prev``."""
        import casadi as ca
        if getattr(self, "_phi", None) is None:
            xs, zs, rs = ca.MX.sym("x", 4 * self.n), ca.MX.sym("z", self.n_states), ca.MX.sym("r", 5 * self.n)
            x_t, u_add, z_in = self._split(xs, zs, rs)
            res = zs[self.n_inner:] - (self.inner.symbolic_evaluate(x_t, z_in, rs)["u_cmd"] + u_add)
            self._phi = ca.Function("phi", [xs, zs, rs], [res, ca.jacobian(res, zs)[:, self.n_inner:]])
        u = z[self.n_inner:]
        for _ in range(self.newton):
            res, jac = self._phi(x, ca.vertcat(z[:self.n_inner], u), r)
            u = u - ca.solve(jac, res)
        return u

    def symbolic_state_derivative(self, x, z, r, sample):
        """``z'``: the inner law's (on ``x_tilde``, total torques) and ``(u - u_prev) / dt``."""
        import casadi as ca
        x_t, _, z_in = self._split(x, z, r)
        parts = []
        if self.n_inner:
            parts.append(self.inner.symbolic_state_derivative(x_t, z_in, r, sample))
        if self.source == "measured":
            parts.append((sample["u"] - z[self.n_inner:]) / self.dt)
        return ca.vertcat(*parts) if parts else ca.DM(0, 1)

    def _functions(self):
        """``(sample(x, z, r) -> (u, u_cmd, s, y_hat), zdot(x, z, r, u_cmd, u))``, built once."""
        import casadi as ca
        if getattr(self, "_fns", None) is None:
            x, z, r = ca.MX.sym("x", 4 * self.n), ca.MX.sym("z", self.n_states), ca.MX.sym("r", 5 * self.n)
            out = self.symbolic_evaluate(x, z, r)
            sample = ca.Function("sample", [x, z, r], [out["u"], out["u_cmd"], out["s"], out["y_hat"]])
            uc, u = ca.MX.sym("u_cmd", self.n), ca.MX.sym("u", self.n)
            zdot = ca.Function("zdot", [x, z, r, uc, u],
                               [self.symbolic_state_derivative(x, z, r, {"u": u, "u_cmd": uc})])
            self._fns = (sample, zdot)
        return self._fns

    def initial_state(self, t0: float, x0, r0) -> np.ndarray:
        """The inner law's initial state, then (``'measured'``) the torque holding ``x0``: ``K (q_m - q)``."""
        z = [np.asarray(self.inner.initial_state(t0, x0, r0), dtype=float)]
        if self.source == "measured":
            x0 = np.asarray(x0, dtype=float).ravel()
            z.append(self._K * (x0[2 * self.n:3 * self.n] - x0[:self.n]))
        return np.concatenate(z)

    def evaluate(self, t: float, x, z, r):
        """The law at one sample (:class:`~fjm_runtime.control.laws.ControlSample`); ``x`` (4n,), ``r`` (5, n)."""
        from .laws import ControlSample
        sample, _ = self._functions()
        r = np.asarray(r, dtype=float).reshape(5, self.n)
        u, u_cmd, s, y_hat = (np.asarray(v).ravel() for v in sample(np.asarray(x, dtype=float),
                                                                     np.asarray(z, dtype=float), r.reshape(-1)))
        y_hat = y_hat.reshape(4, self.n)
        sat = np.zeros(self.n, dtype=bool) if self.u_max is None else np.abs(u_cmd) > self.u_max
        return ControlSample(u, u_cmd, s, y_hat, y_hat - r[:4], sat)

    def state_derivative(self, t: float, x, z, r, sample) -> np.ndarray:
        """``z'`` of :meth:`symbolic_state_derivative`, shape (n_states,)."""
        _, zdot = self._functions()
        return np.asarray(zdot(np.asarray(x, dtype=float), np.asarray(z, dtype=float),
                               np.asarray(r, dtype=float).reshape(-1), sample.u_cmd, sample.u)).ravel()
