"""The linear sampled-data analysis of a law with given gains (``fjm analyze``; the screen of ``fjm design``).

The whole sampled loop of :mod:`fjm_runtime.sim.sample_step` (plant over one period with the torque
held on the same RK4 substeps, the delay buffer, the predictor, the sensor filters, the rate limit,
the law inside its boundary layer) is linearized about an operating point by CasADi jacobians of
``fjm_sample_step`` with respect to the step state ``w`` and the noise row::

    w_{k+1} = A w_k + B n_k,        u_k = C w_k + D n_k

The step is treated generically: nothing here knows the layout of ``w`` beyond its blocks
``x`` (the plant state, first) and ``z`` (the controller state, where the gains ride as constants,
:class:`~fjm_runtime.batch.sampled.GainInput`, so one jacobian Function serves every candidate).
States the step holds constant (``A`` row = unit row, ``B`` row = 0: a per-run sensor offset, for
instance) are inputs, not dynamics, and are dropped. Encoder quantization (``floor``, derivative 0)
is switched off in the linearized step and enters as uniform noise ``step^2 / 12``
(:func:`fjm_runtime.sim.sensor.linear_noise_levels`).

Operating points (:class:`LinearAnalyzer`): ``rest`` (the equilibrium holding gravity at the task's
start with a constant set point, solved by a chord-Newton iteration on ``w = F(w)`` for each plant
and layout) and task points ``t_j`` (frozen time: ``w_k`` and ``r_k`` of a noise-free run of the
loop on the nominal plant; for another plant or delay, the run's plant state at ``t_j - catch_up``
(the spring deflection rescaled to keep the spring torque) seeds a short noise-free run to ``t_j``).
Figures (:mod:`fjm_runtime.analysis.sampled.sampled_noise` for the noise ones): the spectral radius of ``A``
and the joint its eigenvector lives on; the first delay ``d' > d`` (up to ``d + 4``) at which the
spectral radius reaches 1; the range ``[g_lo, g_hi]`` of one factor on every TRUE stiffness that
keeps it below 1 (bisection); the stationary torque jitter (the metric of
:func:`fjm_runtime.sim.metrics.torque_jitter`) and link-angle error std per joint, and which noise
channel dominates each joint's jitter.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Optional, Sequence

import numpy as np

from ...drives import model_springs, spring_scale_groups
from ...sim.sample_step import initial_step_state, sample_step_function
from ...sim.step_layout import make_layout
from ...sim.sensor import SIGNALS, noise_slots
from ...validation import FjmValueError

__all__ = ["LinearStep", "Linearization", "linear_step", "noise_levels", "assess", "spectral"]


def noise_levels(sensor, sensing: str, n: int) -> np.ndarray:
    """Std per noise slot with quantization folded in (``linear_noise_levels``, else ``levels``), shape (nm,)."""
    from ...sim import sensor as sensor_mod
    fn = getattr(sensor_mod, "linear_noise_levels", None)
    return np.asarray(fn(sensor, sensing, n) if fn is not None else sensor.levels(sensing, n), dtype=float)


def channel_names(sensor, sensing: str, n: int):
    """A label per noise slot: the signal whose noise it carries and the joint (``'q_m3'``)."""
    chans = noise_slots(sensor, sensing, n)[0]
    return [f"{SIGNALS[int(c) // n]}{int(c) % n + 1}" for c in chans]


@dataclass
class Linearization:
    """One linearization: ``A`` (nd, nd) on the dynamic states, ``B`` (nd, nm), ``C`` (n, nd), ``D`` (n, nm).

    ``w`` is the operating point (core state, gains excluded), ``dyn`` the core indices kept. The law's
    sliding variable ``s_k = Cs w_k + Ds n_k`` (``Cs`` (n, nd), ``Ds`` (n, nm); ``s`` (n,) its value at
    the point) and an additive input ``v`` on the law's ``nu`` (entering as the reference's fourth
    derivative does): ``w_{k+1} += Bv v_k``, ``u_k += Dv v_k`` (``Bv`` (nd, n), ``Dv`` (n, n)); with them
    :mod:`~fjm_runtime.analysis.sampled.sampled_equivalent` changes the boundary layer's slope.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    w: np.ndarray
    dyn: np.ndarray
    nx: int
    Cs: Optional[np.ndarray] = None
    Ds: Optional[np.ndarray] = None
    Bv: Optional[np.ndarray] = None
    Dv: Optional[np.ndarray] = None
    s: Optional[np.ndarray] = None


class LinearStep:
    """The sample step of one (model, law structure, layout) and its jacobians, gains as an input.

    ``step(wc, r, noise, p, g) -> (wc_next, aux)`` and ``jac(v, r_low, p, g) -> (out, J)`` (CasADi
    Functions) on the CORE state ``wc`` (``w`` without the riding gains): ``v = [wc; noise; nu input]``,
    ``out = [wc_next; u; s]``, ``J = d out / d v`` (:meth:`linearize` slices it).
    """

    def __init__(self, model, controller, L):
        import casadi as ca
        from ...batch.sampled import GainInput
        gi = GainInput(controller)
        self.model, self.L, self.n, self.n_law, self.n_gains = model, L, L.n, gi.n_law, gi.n_gains
        self.controller = gi
        F = sample_step_function(model, gi, L, outline=True)
        a = L.slices()[1].start + gi.n_law
        self._a = a
        nc = L.nw - gi.n_gains
        wc, g = ca.MX.sym("w", nc), ca.MX.sym("g", gi.n_gains)
        r, noise, p = ca.MX.sym("r", 5 * L.n), ca.MX.sym("noise", L.nm), ca.MX.sym("p", len(model.param_names))
        w_next, aux = F(ca.vertcat(wc[:a], g, wc[a:]), r, noise, p)
        wcn = ca.vertcat(w_next[:a], w_next[a + gi.n_gains:])
        args = [wc, r, noise, p, g]
        self.step = ca.Function("fjm_lin_step", args, [wcn, aux])
        # one jacobian of (w_next, u, s) with respect to one symbol v = [w; noise; nu input] (the reference's
        # fourth derivative, the only place it enters the law, is nu's additive input)
        n, nm = L.n, L.nm
        v, r_low = ca.MX.sym("v", nc + nm + n), ca.MX.sym("r_low", 4 * n)
        w_next, aux = F(ca.vertcat(v[:a], g, v[a:nc]), ca.vertcat(r_low, v[nc + nm:]), v[nc:nc + nm], p)
        out = ca.vertcat(w_next[:a], w_next[a + gi.n_gains:], aux[:2 * n])
        self.jac = ca.Function("fjm_lin_jac", [v, r_low, p, g], [out, ca.jacobian(out, v)])
        self._nc = nc
        self._runs: dict = {}

    def core_state(self, x0, z_law, p, sensor) -> np.ndarray:
        """The core ``w`` of a loop starting at ``x0`` with law state ``z_law``: the loop's memory at rest
        (:func:`~fjm_runtime.sim.sample_step.initial_step_state`: the delay buffer holds the spring
        torques that held ``x0``), the per-run sensor offset 0 (an input, not a state of the analysis)."""
        z = np.concatenate([np.asarray(z_law, dtype=float), np.zeros(self.n_gains)])
        w = initial_step_state(self.model, self.L, x0, z, p, seed=0, sensor=sensor, controller=self.controller)
        if getattr(self.L, "offset", False):
            w[self.L.extra_slices()[1]] = 0.0
        return np.r_[w[:self._a], w[self._a + self.n_gains:]]

    def z_law(self, wc) -> np.ndarray:
        """The law's state in a core ``w``."""
        s = self.L.slices()[1]
        return np.asarray(wc[s.start:s.start + self.n_law], dtype=float)

    def run(self, wc, R, p, g) -> np.ndarray:
        """Noise-free run from ``wc`` over the reference rows ``R`` (N, 5n): the states ``w_1..w_N`` (N, nc)."""
        N = R.shape[0]
        if N == 0:
            return np.zeros((0, wc.size))
        fn = self._runs.get(N)
        if fn is None:
            fn = self._runs[N] = self.step.mapaccum("fjm_lin_run", N)
        W, _ = fn(wc, R.T, np.zeros((self.L.nm, N)), p, g)
        return np.asarray(W).T

    def linearize(self, wc, r, p, g) -> Linearization:
        """``A, B, C, D`` (and ``Cs, Ds, Bv, Dv``) at ``(wc, r)`` with the constant states dropped."""
        n, nm, nc = self.n, self.L.nm, self._nc
        r = np.asarray(r, dtype=float).ravel()
        val, J = self.jac(np.r_[np.asarray(wc, dtype=float).ravel(), np.zeros(nm), r[4 * n:]], r[:4 * n], p, g)
        val, J = np.asarray(val, dtype=float).ravel(), np.asarray(J, dtype=float)
        A, B, Bv = J[:nc, :nc], J[:nc, nc:nc + nm], J[:nc, nc + nm:]
        eye = np.eye(nc)
        const = np.all(A == eye, axis=1) & ~np.any(B, axis=1)
        dyn = np.flatnonzero(~const)
        u_rows, s_rows = slice(nc, nc + n), slice(nc + n, nc + 2 * n)
        return Linearization(A[np.ix_(dyn, dyn)], B[dyn], J[u_rows, dyn], J[u_rows, nc:nc + nm],
                             np.asarray(wc, dtype=float), dyn, int(self.model.nx), Cs=J[s_rows, dyn],
                             Ds=J[s_rows, nc:nc + nm], Bv=Bv[dyn], Dv=J[u_rows, nc + nm:], s=val[s_rows])

    def equilibrium(self, wc, r, p, g, chord: Optional[Linearization] = None, iterations: int = 40,
                    tol: float = 1e-11, _own: bool = True):
        """``(w*, converged)``: ``w* = F(w*)`` by chord-Newton from ``wc``.

        The chord matrix is ``chord.A`` when given (e.g. the nominal plant's linearization, for a
        corner plant), else the jacobian at ``wc``; refreshed at ``w`` every 5 iterations without
        convergence; a chord that does not converge is dropped for the jacobian at ``wc``.
        """
        if chord is not None and _own:
            w, ok = self.equilibrium(wc, r, p, g, chord, 12, tol, _own=False)
            if ok:
                return w, ok
        w = np.asarray(wc, dtype=float).copy()
        lin = chord if chord is not None and not _own and chord.dyn.size == chord.A.shape[0] and \
            chord.w.size == w.size else self.linearize(w, r, p, g)
        for it in range(iterations):
            res = np.asarray(self.step(w, r, np.zeros(self.L.nm), p, g)[0]).ravel() - w
            if not np.all(np.isfinite(res)):
                return np.asarray(wc, dtype=float), False
            if np.max(np.abs(res)) <= tol * (1.0 + np.max(np.abs(w))):
                return w, True
            try:
                w[lin.dyn] += np.linalg.solve(np.eye(lin.dyn.size) - lin.A, res[lin.dyn])
            except np.linalg.LinAlgError:
                return np.asarray(wc, dtype=float), False
            if it % 5 == 4:                   # slow contraction: refresh the chord
                lin = self.linearize(w, r, p, g)
        return w, False


_STEPS: dict = {}


def linear_step(model, controller, T, substeps, sensor, delay, predict, interface=None) -> LinearStep:
    """The :class:`LinearStep` of these settings, built once per (model, law structure, nominal, layout).

    ``sensor`` is the linearized one (quantization off); ``interface`` default motor. The gains are NOT
    part of the key.
    """
    from ...batch.sampled import GainInput
    L = make_layout(model, GainInput(controller), float(T), int(substeps), sensor, int(delay), bool(predict),
                    interface=interface)
    key = (id(model), controller.law_kind, tuple(np.asarray(controller.p_nom, dtype=float).tolist()), L)
    hit = _STEPS.get(key)
    if hit is None or hit.model is not model:
        if len(_STEPS) > 64:
            _STEPS.clear()
        hit = _STEPS[key] = LinearStep(model, controller, L)
    return hit


def spectral(lin: Linearization, n: int):
    """``(rho, joint)``: the spectral radius of ``A`` and the joint (0-based) its eigenvector lives on.

    The joint: the largest share of the eigenvector's plant-state entries (``x = [q; dq; q_m; dq_m]``),
    each of the four blocks normalised by its own norm first; ``None`` when the mode has no plant part.
    """
    vals, vecs = np.linalg.eig(lin.A)
    k = int(np.argmax(np.abs(vals)))
    v = np.abs(vecs[:, k])
    xrows = lin.dyn < lin.nx
    vx = np.zeros(lin.nx)
    vx[lin.dyn[xrows]] = v[xrows]
    blocks = vx.reshape(-1, n)
    norms = np.linalg.norm(blocks, axis=1, keepdims=True)
    share = np.sum(np.divide(blocks, norms, out=np.zeros_like(blocks), where=norms > 0), axis=0)
    joint = int(np.argmax(share)) if np.any(share > 0) else None
    return float(np.abs(vals[k])), joint


def assess(lin: Linearization, levels, h: int, names: Sequence[str], attribution: bool = False,
           layer: Optional[tuple] = None, sigma0=None) -> dict:
    """The verdict at one point, and when stable the predicted jitter and link-angle error std per joint.

    ``layer = (k_s, delta, slope)`` (each (n,)): the law's switching gain, its boundary layer and the slope
    ``lin`` carries. With it and sensor noise, the layer enters by its equivalent gain under that noise
    (:mod:`~fjm_runtime.analysis.sampled.sampled_equivalent`) unless the noise keeps ``s`` inside it; without
    noise, an equilibrium unstable inside the layer but stable outside it gets no verdict (the loop settles
    in an oscillation of the layer's width). ``sigma0`` (n,): a start for the std of ``s`` (another point's).

    Returns
    -------
    dict
        ``rho`` (of the loop judged), ``rho_small_signal``, ``stable`` (True, False, or None: no verdict,
        with ``reason``), ``method`` ('small-signal' or 'equivalent gain'), ``dominant_joint`` (1-based);
        when stable ``torque_jitter`` (n,) N m, ``q_error_std`` (n,) rad, with a layer ``layer_fraction``
        (n,) (the time inside it) and ``s_std_over_delta`` (n,); with ``attribution``: ``noise_share``
        {joint: {channel: share of the jitter variance}} (top 3) and ``dominant_noise`` (n,) labels.
    """
    from .sampled_equivalent import equivalent_loop, loop_figures, noise_columns, with_slope
    n = lin.C.shape[0]
    levels = np.asarray(levels, dtype=float)
    rho0, joint = spectral(lin, n)
    out = {"rho": rho0, "rho_small_signal": rho0, "stable": bool(rho0 < 1.0), "method": "small-signal",
           "dominant_joint": None if joint is None else joint + 1}
    qrows = [int(np.flatnonzero(lin.dyn == i)[0]) for i in range(n)]
    loop = (lin.A, lin.B, lin.C, lin.D)
    zero = np.zeros(n)
    if layer is not None:
        k_s, delta, slope = (np.asarray(v, dtype=float) for v in layer)
        quiet = not np.any(levels > 0)
        small_ok = rho0 < 1.0 and (quiet or _inside(lin, loop, levels, qrows, h, delta))
        if quiet and not small_ok:
            rho_sat = spectral(replace(lin, A=with_slope(lin, -slope)[0]), n)[0]
            if rho_sat < 1.0:
                out.update(stable=None, rho_saturated=rho_sat, reason=(
                    f"noise-free, the equilibrium is unstable inside the boundary layer (rho {rho0:.4g}) and stable "
                    f"outside it (rho {rho_sat:.4g}): the loop settles in an oscillation of the layer's width, "
                    "which no linearization judges"))
            return out
        if not small_ok:
            eq = equivalent_loop(lin, levels, k_s, delta, slope, h, qrows, sigma0)
            out.update(rho=eq.rho, method="equivalent gain", layer_fraction=eq.p_in.tolist(),
                       equivalent_gain=eq.gain.tolist(), iterations=eq.iterations)
            if not eq.converged:
                out.update(stable=False if eq.rho >= 1.0 else None, reason=eq.reason)
                return out
            out["stable"], loop, zero = True, (eq.A, eq.B, eq.C, eq.D), eq.residual
    if not out["stable"]:
        return out
    BS, DS, DsS = noise_columns(lin, loop, levels, zero)
    jit_c, q_c, s_c = loop_figures(loop[0], BS, loop[2], DS, lin.Cs, DsS, qrows, h, channels=True)
    jit, qv = jit_c.sum(axis=0), q_c.sum(axis=0)
    if layer is not None:
        from .sampled_equivalent import sat_moments
        s_std = np.sqrt(s_c.sum(axis=0))
        out.setdefault("layer_fraction", sat_moments(lin.s, s_std, delta)[0].tolist())
        out["s_std_over_delta"] = (s_std / delta).tolist()
    if attribution and jit_c.shape[0] >= len(names):
        share = jit_c[:len(names)] / np.maximum(jit[None, :], 1e-300)
        out["dominant_noise"] = [names[int(np.argmax(share[:, i]))] for i in range(n)]
        out["noise_share"] = {str(i + 1): {names[c]: float(share[c, i]) for c in np.argsort(-share[:, i])[:3]}
                              for i in range(n)}
    out["torque_jitter"] = np.sqrt(jit).tolist()
    out["q_error_std"] = np.sqrt(np.maximum(qv, 0.0)).tolist()
    return out


#: The small-signal linearization stands when ``s`` stays inside the layer this fraction of the time.
INSIDE_FRACTION = 0.999


def _inside(lin, loop, levels, qrows, h, delta) -> bool:
    """Does the small-signal loop's own noise keep every ``s`` inside its layer (``INSIDE_FRACTION``)?"""
    from .sampled_equivalent import loop_figures, noise_columns, sat_moments
    BS, DS, DsS = noise_columns(lin, loop, levels, np.zeros(len(qrows)))
    s_var = loop_figures(loop[0], BS, loop[2], DS, lin.Cs, DsS, qrows, h)[2]
    return bool(np.all(sat_moments(lin.s, np.sqrt(s_var), delta)[0] >= INSIDE_FRACTION))


@dataclass(frozen=True)
class Conditions:
    """The loop a law runs in: what :class:`LinearAnalyzer` needs (``DesignLoops`` has the same names).

    Attributes
    ----------
    model : fjm_runtime.Model
    kind, sensing : str
    dt : float
        Control period, s.
    delay : int
    predict : bool
    sensor : SensorModel
        As simulated (quantization included: the analysis switches it off and folds it into the noise).
    reference : object
        ``reference(t) -> (5, n)`` (and ``sample(t)``).
    x0 : ndarray (nx,)
        The task's start (at rest holding gravity, nominal parameters).
    nominal : dict
        The controller's nominal parameters.
    u_max : sequence of float or None
    interface : CommandInterface, optional
        The command interface (default motor).
    """

    model: object
    kind: str
    sensing: str
    dt: float
    delay: int
    predict: bool
    sensor: object
    reference: object
    x0: np.ndarray = field(compare=False)
    nominal: dict = field(compare=False, default_factory=dict)
    u_max: Optional[tuple] = None
    interface: object = None

    @classmethod
    def from_loops(cls, loops) -> "Conditions":
        """From a :class:`~fjm_runtime.analysis.search.runs.DesignLoops`."""
        return cls(loops.model, loops.kind, loops.sensing, float(loops.dt), int(loops.delay), bool(loops.predict),
                   loops.sensor, loops.reference, np.asarray(loops.x0, dtype=float), dict(loops.nominal),
                   None if loops.u_max is None else tuple(loops.u_max), getattr(loops, "interface", None))

    def controller(self, gains: dict):
        """The law with ``gains`` (``lam, k_lin, k_s, delta``; ``u_max`` from the conditions unless given)."""
        from ...control.factory import make_controller
        g = dict(gains)
        u_max = g.pop("u_max", self.u_max)
        try:
            return make_controller(self.kind, self.model, self.nominal, sensing=self.sensing, u_max=u_max, **g)
        except (TypeError, ValueError) as exc:
            raise FjmValueError(f"gains {sorted(gains)}: {exc}") from None

    def linear_sensor(self):
        """The sensor of the linearized step: quantization off (folded into the noise levels)."""
        return replace(self.sensor, q_quant=0.0, q_m_quant=0.0)


def scaled_stiffness(model, p, g: float) -> np.ndarray:
    """``p`` with every spring torque times ``g`` (the TRUE plant): each ``K_i``, or every coefficient of a
    nonlinear law that scales its torque (:func:`~fjm_runtime.drives.spring_scale_groups`)."""
    p = np.asarray(p, dtype=float).copy()
    for grp in spring_scale_groups(model):
        p[grp] *= g
    return p


def respring(model, x, p_from, p_to) -> np.ndarray:
    """``x`` with the motor angles moved so that the spring torques (``K (q_m - q)`` or ``psi(q_m - q)``) are the
    same under ``p_to`` as under ``p_from``."""
    n = int(model.n)
    x = np.asarray(x, dtype=float).copy()
    springs = model_springs(model)
    tau = np.asarray(springs["spring"](x[2 * n:3 * n] - x[0:n], np.asarray(p_from, dtype=float))[0]).ravel()
    x[2 * n:3 * n] = x[0:n] + np.asarray(springs["spring_inverse"](tau, np.asarray(p_to, dtype=float))).ravel()
    return x


def finite(v) -> Optional[float]:
    """``v`` as a float, or None when not finite (JSON)."""
    return float(v) if v is not None and math.isfinite(float(v)) else None
