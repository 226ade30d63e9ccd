"""Matched disturbances on the motor torque: Coulomb friction and user-supplied bounded signals.

The plant becomes ``x' = f(x; p) + g(x; p) (u + d)`` with ``d`` (shape (n,), N m)
acting where the input acts (matched), while the controller keeps its nominal
model (it knows nothing about ``d``):

* :func:`with_motor_disturbance` wraps a model so that its drift ``f`` carries a
  state-dependent ``d(x)``: Coulomb friction on the motor,
  ``-F_c sign(dq_m)`` or smoothed ``-F_c tanh(dq_m / eps)``, plus a constant
  torque ``bias``. The wrapper has the model's interface (``functions``, ``f``,
  ``g``, ``T``, ...), so every simulation backend (python, casadi, compiled)
  runs it; pass it to :func:`fjm_runtime.sim.simulate.simulate` as the PLANT and
  build the controller on the undisturbed model.
* :class:`TorqueDisturbance` wraps a controller so that the plant receives
  ``u + d(t)`` for a user-supplied bounded signal ``d(t)`` (held over each
  sample like ``u``). It has no CasADi mirror: ``simulate`` then uses the plain
  Python loop. ``SimulationResult.u`` records the torque the plant received
  (``u + d``); the wrapped controller's own state (integrator, estimator) sees
  its commanded ``u``.

Both report ``bound`` (N m per joint), the input to
:func:`fjm_runtime.tune.synthesize_gains` (``disturbance_bound``).
"""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np

from ..validation import joint_vector


class DisturbedModel:
    """A model whose drift includes a matched motor torque ``d(x)`` (see :func:`with_motor_disturbance`).

    Attributes
    ----------
    base : Model
        The undisturbed model.
    bound : ndarray, shape (n,)
        ``sup |d_i|`` in N m (``F_c + |bias|``).
    functions : dict
        The base model's CasADi Functions with ``f`` replaced by ``f + g d``.
    """

    def __init__(self, model, coulomb, smoothing: Optional[float], bias):
        import casadi as ca
        self.base = model
        n, nx = int(model.n), int(model.nx)
        self.n, self.nx = n, nx
        self.name = model.name
        self.param_names = model.param_names
        self.default_params = model.default_params
        self.manifest = getattr(model, "manifest", {})
        self.coulomb = joint_vector(coulomb, n, "coulomb", minimum=0.0)
        self.bias = joint_vector(bias, n, "bias")
        if smoothing is not None and not (np.isfinite(smoothing) and smoothing > 0):
            raise ValueError(f"smoothing = {smoothing!r}: expected None (sign) or a velocity scale > 0 (rad/s)")
        self.smoothing = smoothing
        self.bound = self.coulomb + np.abs(self.bias)
        x = ca.SX.sym("x", nx)
        p = ca.SX.sym("p", len(model.param_names))
        dqm = x[3 * n:4 * n]
        shape = ca.sign(dqm) if smoothing is None else ca.tanh(dqm / float(smoothing))
        d = -ca.DM(self.coulomb) * shape + ca.DM(self.bias)
        f = model.functions["f"](x, p) + ca.mtimes(ca.reshape(model.functions["g"](x, p), nx, n), d)
        self.functions = dict(model.functions)
        self.functions["f"] = ca.Function("f", [x, p], [f])
        self._d = ca.Function("d", [x], [d])

    def __repr__(self) -> str:
        return (f"<fjm DisturbedModel {self.name}: Coulomb {self.coulomb.tolist()} N m "
                f"({'sign' if self.smoothing is None else f'tanh(dq_m / {self.smoothing:g})'}), "
                f"bias {self.bias.tolist()} N m>")

    def disturbance(self, x) -> np.ndarray:
        """``d(x)``, shape (n,) (N m)."""
        return np.asarray(self._d(self.state_array(x))).ravel()

    def params_array(self, p=None, arg: str = "p") -> np.ndarray:
        return self.base.params_array(p, arg=arg)

    def state_array(self, x, arg: str = "x") -> np.ndarray:
        return self.base.state_array(x, arg)

    def f(self, x, p=None) -> np.ndarray:
        """Drift including ``g d(x)``, shape (4n,)."""
        xv = self.state_array(x)
        return np.asarray(self.functions["f"](xv, self.params_array(p))).ravel()

    def __getattr__(self, name):          # g, T, alpha, beta, energy, inertia, ad, xdot of the base
        return getattr(self.base, name)


def with_motor_disturbance(model, *, coulomb=0.0, smoothing: Optional[float] = None, bias=0.0) -> DisturbedModel:
    """The plant ``model`` with a matched motor torque ``d = -F_c psi(dq_m) + bias``.

    Parameters
    ----------
    model : Model
    coulomb : float or array_like, shape (n,)
        Coulomb friction level ``F_c >= 0`` per motor (N m).
    smoothing : float, optional
        ``None``: ``psi = sign`` (discontinuous); else ``psi = tanh(dq_m / smoothing)``.
    bias : float or array_like, shape (n,)
        Constant torque (N m).

    Returns
    -------
    DisturbedModel
        Use it as the plant of ``simulate``; ``.bound`` is ``sup |d|``.
    """
    return DisturbedModel(model, coulomb, smoothing, bias)


class TorqueDisturbance:
    """Controller wrapper: the plant receives ``u + d(t)`` (a user-supplied bounded signal).

    Parameters
    ----------
    controller : SlidingModeController
    signal : callable
        ``signal(t) -> (n,)`` torque in N m.
    bound : float or array_like, shape (n,)
        A bound on ``|signal|`` (N m), used by the synthesis; checked at every sample
        (``ValueError`` when exceeded).
    """

    def __init__(self, controller, signal: Callable[[float], np.ndarray], bound):
        self.inner = controller
        self.n = int(controller.n)
        self.signal = signal
        self.bound = joint_vector(bound, self.n, "bound", minimum=0.0)
        self.n_states = controller.n_states
        self.delta = getattr(controller, "delta", np.full(self.n, np.inf))

    def initial_state(self, t0, x0, r0):
        return self.inner.initial_state(t0, x0, r0)

    def evaluate(self, t, x, z, r):
        sample = self.inner.evaluate(t, x, z, r)
        d = np.broadcast_to(np.asarray(self.signal(t), dtype=float), (self.n,))
        if np.any(np.abs(d) > self.bound * (1 + 1e-12)):
            raise ValueError(f"disturbance signal({t:g}) = {d.tolist()}: exceeds the stated bound "
                             f"{self.bound.tolist()} N m")
        self._commanded = sample
        return sample._replace(u=sample.u + d)

    def state_derivative(self, t, x, z, r, sample):
        return self.inner.state_derivative(t, x, z, r, self._commanded)

    def __getattr__(self, name):
        if name == "symbolic_evaluate":      # no CasADi mirror: simulate() uses the Python loop
            raise AttributeError(name)
        return getattr(self.inner, name)
