"""Joint stiffness, rotor inertia, damping and friction from a log, by least squares (docs/identification.md).

Per joint ``i`` (the motor equations are decoupled; a complete model's rotor coupling is not
modelled here), with ``phi = q_m - q`` and the logged (or estimated) joint torque ``tau_J``:

* spring: ``tau_J = K phi + o`` (linear) or ``k1 phi + k3 phi^3 + o`` (cubic), with ``o`` the
  torque sensor's constant offset (identified and reported, not a model parameter);
* motor: ``u - (tau_J - o) = J_m ddq_m + B_m dq_m + F_c c(dq_m) [+ F_s s(dq_m)]`` with the
  regularized Coulomb term ``c = tanh(dq_m / v_c)`` and, for Stribeck, ``s = exp(-(dq_m / v_s)^2) c``
  (then the Coulomb column is ``c - s``: ``F(v) = F_c c + (F_s - F_c) s``). That is the friction law
  of the models that carry one (``link1_hd``: ``F_c, F_s, v_s, v_c``): their names are used, their
  ``v_c, v_s`` are the default velocities, and a Coulomb-only fit sets ``F_s = F_c`` (no hump).

Every model gets the Coulomb column (``--friction coulomb``, the default): drives have dry friction
whether or not the model carries it, and leaving it out biases ``J_m`` and ``B_m``. Windows around a
velocity reversal (stiction, :func:`~fjm_runtime.ident.signals.moving_rows`) are left out of the motor
equation, except for a Stribeck fit, which needs them.

Both are linear in the unknowns: least squares on column-scaled regressors, errors in the
regressors' columns (encoder noise through the filter) removed from the normal equations, standard
errors by a Newey-West sandwich for the coloured residuals, plus a systematic term
(:mod:`fjm_runtime.ident.uncertainty`). Signals are smoothed and differentiated offline by one
zero-phase filter whose derivative kernels are its value kernel applied to differences, the held
torque is averaged over each sample, and the friction columns are evaluated on a per-sample velocity
and then filtered like the rest (:mod:`fjm_runtime.ident.signals`).

Without ``tau_J`` in the log, it is the link equation's: ``tau_J = D(q) ddq + h(q, dq)`` from the
model's generated ``f`` and ``inertia`` at its NOMINAL link parameters (``f``'s link rows at
``q_m = q`` are ``-D^-1 h``), so the link model's error goes into the identified spring.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np

from ..drives import role_names, spring_laws
from ..validation import FjmValueError
from .checks import gear_ratio_warnings, nominal_warnings
from .linkeq import link_torque
from .log import Log
from .signals import (consistent_kernels, held_torque, moving_rows, sample_velocity, smooth_derivatives, white_noise,
                      window_half)
from .uncertainty import INTERVAL_SIGMAS, combined, hac_covariance, systematic

__all__ = ["Identification", "identify", "parameter_names", "friction_names", "SPRINGS", "FRICTIONS"]

SPRINGS = ("linear", "cubic")
FRICTIONS = ("viscous", "coulomb", "stribeck")
#: Friction velocities (rad/s) for a model without its own ``v_c``, ``v_s``.
DEFAULT_V_C, DEFAULT_V_S = 0.01, 0.1
#: A parameter whose standard error exceeds this fraction of its value is reported as not excited.
NOT_EXCITED = 0.1
#: A stiffness whose deflection signal is more than this share noise (variance) is reported as not excited.
MAX_NOISE_SHARE = 0.25
#: Motor-equation rows whose window sees ``|dq_m|`` below this share of its RMS are left out (stiction).
REVERSAL_SHARE = 0.1
#: Extra samples around each left-out stretch (a drive's friction settles within a few milliseconds).
REVERSAL_MARGIN = 5
#: Below this share of rows left, a joint barely moves: all rows are kept, and a warning says so.
MIN_MOVING = 0.3
#: Newey-West bandwidth, filter windows.
HAC_WINDOWS = 4


@dataclass
class JointFit:
    """One least-squares fit: names, values, standard errors, condition number, RMS residual."""

    names: List[str]
    values: np.ndarray
    stderr: np.ndarray
    condition: float
    residual: float


@dataclass
class Identification:
    """What :func:`identify` found.

    Attributes
    ----------
    values, stderr : dict
        Parameter name -> value, standard error (model names: ``K``/``K<i>``, ``J_m``/``Jm<i>``,
        ``B_m``/``Bm<i>``, ``k1``, ``k3``, and ``F_c``, ``F_s`` where the model has motor friction; else
        ``F_c<i>``, ``F_s<i>``, not parameters of the model; ``tau_J_offset<i>``, never one).
    condition : dict
        ``"spring <i>"``, ``"motor <i>"`` -> condition number of the scaled regressor.
    residual : dict
        Same keys -> RMS residual, N m.
    warnings : list of str
    settings : dict
        Method, filter, friction and spring choices, the log's source and duration.
    fixed : dict
        Parameters of the model the fit held at a value instead of identifying (the friction's
        ``v_c``, ``v_s``; ``F_s = F_c`` of a Coulomb-only fit): written to the parameter file with them.
    systematic : dict
        Parameter name -> systematic standard uncertainty (:mod:`fjm_runtime.ident.uncertainty`);
        :meth:`interval` combines it with ``stderr``.
    """

    values: Dict[str, float] = field(default_factory=dict)
    stderr: Dict[str, float] = field(default_factory=dict)
    condition: Dict[str, float] = field(default_factory=dict)
    residual: Dict[str, float] = field(default_factory=dict)
    warnings: List[str] = field(default_factory=list)
    not_excited: List[str] = field(default_factory=list)
    settings: dict = field(default_factory=dict)
    fixed: Dict[str, float] = field(default_factory=dict)
    systematic: Dict[str, float] = field(default_factory=dict)

    def uncertainty(self, name: str) -> float:
        """Standard uncertainty of ``name``: ``sqrt(stderr^2 + systematic^2)``, the parameter's unit."""
        return combined(self.stderr[name], self.systematic.get(name, 0.0))

    def interval(self, name: str, sigmas: float = INTERVAL_SIGMAS) -> Tuple[float, float]:
        """The stated interval of ``name``: value -+ ``sigmas`` standard uncertainties."""
        v, w = self.values[name], sigmas * self.uncertainty(name)
        return v - w, v + w

    def model_values(self, model) -> Dict[str, float]:
        """The identified values that are parameters of ``model`` and that the log determines (excited)."""
        names = set(model.param_names)
        return {k: v for k, v in self.values.items() if k in names and k not in self.not_excited}

    def to_toml(self, path, model) -> Path:
        """Write a parameter file ``fjm design --params`` / ``fjm simulate --params`` read (see module doc)."""
        from .report import params_toml
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        tmp = p.with_name(p.name + ".tmp")
        tmp.write_text(params_toml(self, model))
        tmp.replace(p)
        return p


def parameter_names(model, spring: str) -> Tuple[List[List[str]], List[str], List[str]]:
    """``(spring names per joint, J_m names, B_m names)`` of ``model`` (``model.drives``)."""
    laws = spring_laws(model)
    if spring == "cubic" and laws != ("cubic",):
        raise FjmValueError(f"--spring cubic: {model.name} has no cubic spring parameters k1, k3; expected a "
                            "model with a cubic spring (e.g. link1_hd) or --spring linear")
    if spring != "cubic" and set(laws) != {"linear"}:
        raise FjmValueError(f"{model.name}: no linear stiffness parameters (spring laws {sorted(set(laws))}); "
                            "expected --spring cubic for a nonlinear spring")
    springs = [[model.param_names[i] for i in d.spring] for d in model.drives]
    return springs, role_names(model, "rotor_inertia"), role_names(model, "damping")


def _fit(A: np.ndarray, b: np.ndarray, names: List[str], max_lag: int, noise_var=None) -> JointFit:
    """Least squares ``A theta = b`` on scaled columns. ``noise_var`` (per column, or None): the variance
    of the noise IN the regressor's columns, removed from ``A^T A`` (the bias-corrected, errors-in-variables
    estimate: noisy regressors otherwise shrink their coefficients). Standard errors: Newey-West over
    ``HAC_WINDOWS`` windows of ``max_lag`` samples."""
    scale = np.linalg.norm(A, axis=0)
    if np.any(scale == 0):
        col = names[int(np.argmin(scale))]
        raise FjmValueError(f"identify: the regressor column of {col} is zero (nothing in the log moves it); "
                            "expected an exciting trajectory (fjm excite)")
    As = A / scale
    G = As.T @ As
    if noise_var is not None:
        G = G - np.diag(A.shape[0] * np.asarray(noise_var, dtype=float) / scale ** 2)
    sol = np.linalg.solve(G, As.T @ b)
    r = b - As @ sol
    cov = hac_covariance(As, r, np.linalg.inv(G), int(HAC_WINDOWS * max_lag)) * r.size / max(r.size - A.shape[1], 1)
    svals = np.linalg.svd(As, compute_uv=False)
    return JointFit(names, sol / scale, np.sqrt(np.diag(cov)) / scale, float(svals[0] / svals[-1]),
                    float(np.sqrt(np.mean(r ** 2))))


def _friction_columns(dqm: np.ndarray, friction: str, v_c: float, v_s: float):
    c = np.tanh(dqm / v_c)
    if friction == "viscous":
        return [], []
    if friction == "coulomb":
        return [c], ["F_c"]
    s = np.exp(-(dqm / v_s) ** 2) * c
    return [c - s, s], ["F_c", "F_s"]


def identify(model, log: Log, *, spring: Optional[str] = None, friction: str = "coulomb",
             v_c: Optional[float] = None, v_s: Optional[float] = None, window: float = 0.04,
             nominal=None, reversal_share: Optional[float] = None) -> Identification:
    """Identify the joints' spring, rotor inertia, damping and friction from ``log``.

    Parameters
    ----------
    model : Model
        ``fjm_runtime.load(name)``: its parameter names, and its link model when ``tau_J`` is not logged.
    log : Log
        :func:`~fjm_runtime.ident.log.read_log`.
    spring : {'linear', 'cubic'}, optional
        Default: cubic for a model with ``k1, k3``, else linear.
    friction : {'viscous', 'coulomb', 'stribeck'}
    v_c, v_s : float, optional
        Coulomb regularization and Stribeck velocities, rad/s (link side), > 0. Default: the model's
        ``v_c``, ``v_s`` where it has motor friction, else 0.01 and 0.1.
    window : float
        Filter window, s (the filter's cut-off is about ``1 / window`` Hz).
    nominal : dict, optional
        Link parameters for the link equation (default: the model's defaults).
    reversal_share : float, optional
        Motor-equation windows where ``|dq_m|`` drops below this share of its RMS are left out (dry
        friction's stiction); 0 keeps every row. Default :data:`REVERSAL_SHARE`, 0 for ``stribeck``.

    Returns
    -------
    Identification
    """
    names = list(model.param_names)
    if "coupling" in getattr(model, "functions", {}):
        raise FjmValueError(f"identify: {model.name} is a complete model (rotor coupling); expected its reduced "
                            "model (e.g. panda for panda_complete): the motor equations are identified per joint")
    if spring is None:
        spring = "cubic" if spring_laws(model) == ("cubic",) else "linear"
    if spring not in SPRINGS or friction not in FRICTIONS:
        raise FjmValueError(f"identify: spring {spring!r}, friction {friction!r}; expected spring in {SPRINGS} and "
                            f"friction in {FRICTIONS}")
    v_c = float(model.default_params.get("v_c", DEFAULT_V_C)) if v_c is None else v_c
    v_s = float(model.default_params.get("v_s", DEFAULT_V_S)) if v_s is None else v_s
    for nm, v in (("v_c", v_c), ("v_s", v_s), ("window", window)):
        if not (np.isfinite(v) and v > 0):
            raise FjmValueError(f"identify: {nm} = {v!r}; expected a finite value > 0")
    reversal_share = _reversal_share(reversal_share, friction)
    spring_names, jm, bm = parameter_names(model, spring)
    dt, h = log.dt, window_half(log.dt, window)
    if log.t.size < 10 * (2 * h + 1):
        raise FjmValueError(f"{log.source}: {log.t.size} samples for a {2 * h + 1}-sample filter window; expected "
                            "a log at least 10 windows long (a shorter --window, or a longer log)")
    kernels = consistent_kernels(h, dt)
    S, dS, ddS = smooth_derivatives(np.concatenate([log.q, log.q_m, held_torque(log.u)] + (
        [log.tau_J] if log.tau_J is not None else []), axis=1), dt, h, kernels=kernels)
    n = log.n
    raw_phi, raw_qm = (log.q_m - log.q)[h:log.t.size - h], log.q_m[h:log.t.size - h]
    q, qm, u = S[:, :n], S[:, n:2 * n], S[:, 2 * n:3 * n]
    dqm, ddqm = dS[:, n:2 * n], ddS[:, n:2 * n]
    if log.tau_J is not None:
        tau, source = S[:, 3 * n:], "logged tau_J"
    else:
        p = model.params_array({**model.default_params, **(nominal or {})})
        tau, source = link_torque(model, q, dS[:, :n], ddS[:, :n], p), "link equation at the nominal link parameters"
    out = Identification(settings={
        "model": model.name, "log": log.source, "duration_s": float(log.t[-1] - log.t[0]), "samples": int(log.t.size),
        "rate_hz": 1.0 / dt, "spring": spring, "friction": friction, "v_c": v_c, "v_s": v_s, "tau_J": source,
        "filter": f"zero-phase Blackman window on values and differences, {2 * h + 1} samples "
                  f"({(2 * h + 1) * dt:.3g} s), {h} samples dropped at each end", "reversal_share": reversal_share})
    out.warnings += gear_ratio_warnings(log.q, log.q_m)
    gain = np.sum(kernels ** 2, axis=1)             # white noise's variance through value, rate, acceleration
    v_sample = sample_velocity(log.q_m, dt)             # friction per sample, then filtered like the rest
    for i in range(n):
        fnames = friction_names(model, i)
        fcols = [smooth_derivatives(c[:, None], dt, h, kernels=kernels)[0][:, 0]
                 for c in _friction_columns(v_sample[:, i], friction, v_c, v_s)[0]]
        _identify_joint(out, i, q[:, i], qm[:, i], dqm[:, i], ddqm[:, i], u[:, i], tau[:, i], spring_names[i],
                        jm[i], bm[i], fcols, max_lag=2 * h + 1, offset=log.tau_J is not None,
                        phi_noise=white_noise(raw_phi[:, i]) * gain[0], friction_names=fnames,
                        reversal_share=reversal_share, motor_noise=white_noise(raw_qm[:, i]) * gain[[2, 1]])
        _hold_friction(out, model, friction, fnames, v_c, v_s)
    out.warnings += nominal_warnings({k: v for k, v in out.values.items() if k in model.parameter_info}, model)
    return out


def _reversal_share(share: Optional[float], friction: str) -> float:
    """``share``, checked (0 <= share < 1); None: :data:`REVERSAL_SHARE`, 0 for a Stribeck fit."""
    share = (0.0 if friction == "stribeck" else REVERSAL_SHARE) if share is None else share
    if not (np.isfinite(share) and 0.0 <= share < 1.0):
        raise FjmValueError(f"identify: reversal_share = {share!r}; expected 0 <= value < 1")
    return float(share)


def friction_names(model, i: int) -> Tuple[str, str]:
    """The Coulomb and static friction names of joint ``i`` (0-based): the model's (``model.drives``) where
    its drive has motor friction, else ``F_c<i>``, ``F_s<i>`` (names of the identified values only)."""
    friction = model.drives[i].friction
    if friction is not None:
        return model.param_names[friction[0]], model.param_names[friction[1]]
    return f"F_c{i + 1}", f"F_s{i + 1}"


def _identify_joint(out: Identification, i: int, q, qm, dqm, ddqm, u, tau, spring_names, jm, bm, fcols,
                    max_lag: int, offset: bool, phi_noise: float = 0.0,
                    friction_names: Tuple[str, str] = ("F_c", "F_s"), reversal_share: float = 0.0,
                    motor_noise=(0.0, 0.0)) -> None:
    """Joint ``i``'s spring and motor fits into ``out``. ``fcols``: the filtered friction columns (0, 1 or 2,
    named by ``friction_names``); ``phi_noise``: the noise variance in the filtered deflection;
    ``motor_noise``: in the filtered ``ddq_m`` and ``dq_m`` columns."""
    phi = qm - q
    cols = [phi] + ([phi ** 3] if len(spring_names) == 2 else [])
    noise_var = [phi_noise] + [0.0] * (len(cols) - 1) + ([0.0] if offset else [])
    snames, kinds = list(spring_names), ["spring"] * len(cols)
    if offset:
        cols.append(np.ones_like(phi))
        snames.append(f"tau_J_offset{i + 1}")
        kinds.append("offset")
    fit_s = _fit(np.column_stack(cols), tau, snames, max_lag, noise_var)
    o = fit_s.values[-1] if offset else 0.0
    fnames = list(friction_names[:len(fcols)])
    rows = _motor_rows(out, i, dqm, max_lag // 2 + REVERSAL_MARGIN, reversal_share)
    fit_m = _fit(np.column_stack([ddqm, dqm] + fcols)[rows], (u - (tau - o))[rows], [jm, bm] + fnames, max_lag,
                 list(motor_noise) + [0.0] * len(fcols))
    noise_share = phi_noise / max(float(np.var(phi)), 1e-300)
    if noise_share > MAX_NOISE_SHARE:        # the correction itself is then the estimate: do not trust it
        out.not_excited.append(spring_names[0])
        out.warnings.append(f"{spring_names[0]}: encoder noise is {noise_share:.0%} of the deflection's variance "
                            f"(over {MAX_NOISE_SHARE:.0%}): the joint hardly deflects in this log; the parameter file "
                            "keeps the model's value")
    kinds += ["rotor_inertia", "damping"] + ["friction"] * len(fcols)
    for tag, fit in ((f"spring {i + 1}", fit_s), (f"motor {i + 1}", fit_m)):
        out.condition[tag], out.residual[tag] = fit.condition, fit.residual
        for nm, v, se in zip(fit.names, fit.values, fit.stderr):
            out.values[nm], out.stderr[nm] = float(v), float(se)
            kind = kinds.pop(0)
            out.systematic[nm] = systematic(kind, v)
            if kind != "offset" and nm not in out.not_excited and not se <= NOT_EXCITED * abs(v):
                out.not_excited.append(nm)
                out.warnings.append(_not_excited(nm, kind, v, se, float(np.sqrt(np.mean(dqm ** 2)))))


def _hold_friction(out: Identification, model, friction: str, fnames, v_c: float, v_s: float) -> None:
    """Where the model has the friction law: the velocities the fit held (and ``F_s = F_c`` of a Coulomb-only
    fit) go to ``out.fixed``."""
    if friction != "viscous" and fnames[0] in model.param_names:
        out.fixed.update({nm: v for nm, v in (("v_c", v_c), ("v_s", v_s)) if nm in model.param_names})
        if friction == "coulomb" and fnames[1] in model.param_names and fnames[0] in out.values:
            out.fixed[fnames[1]] = out.values[fnames[0]]  # Coulomb only: the static level is the same


def _motor_rows(out: Identification, i: int, dqm, half: int, reversal_share: float) -> np.ndarray:
    """The motor equation's rows of joint ``i`` (:func:`~fjm_runtime.ident.signals.moving_rows`), bool (N,)."""
    if reversal_share <= 0:
        return np.ones(dqm.size, dtype=bool)
    rows = moving_rows(dqm, half, reversal_share * float(np.sqrt(np.mean(dqm ** 2))))
    if rows.sum() < MIN_MOVING * rows.size:
        out.warnings.append(f"joint {i + 1}: the motor turns slowly or reverses often ({rows.mean():.0%} of the log "
                            f"away from its reversals, under {MIN_MOVING:.0%}): the motor equation keeps every "
                            "sample, and dry friction near the reversals may bias J_m and B_m")
        return np.ones(dqm.size, dtype=bool)
    return rows


def _not_excited(name: str, kind: str, value: float, se: float, rms_speed: float) -> str:
    """The warning of a parameter the log does not determine (standard error over NOT_EXCITED of it)."""
    keep = "the parameter file keeps the model's value"
    if kind == "friction" and abs(value) <= INTERVAL_SIGMAS * se:
        return (f"{name} = {value:.3g} +- {se:.2g}: no dry friction seen (within {INTERVAL_SIGMAS:g} standard "
                "errors of 0)")
    if kind in ("damping", "friction"):
        return (f"{name} = {value:.4g} +- {se:.2g}: not excited (standard error over {NOT_EXCITED:.0%} of the "
                f"value; the motor moves at {rms_speed:.3g} rad/s RMS, too slowly or too little to tell "
                f"damping from friction); {keep}")
    return (f"{name} = {value:.4g} +- {se:.2g}: not excited (standard error over {NOT_EXCITED:.0%} of the value); "
            f"the log does not determine it, {keep}")
