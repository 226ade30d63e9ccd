"""The batch form of THE sample step: :mod:`fjm_runtime.sim.sample_step` plus running per-run metrics.

:func:`sampled_metric_step` wraps ``fjm_sample_step(w, r, noise, p)`` into one SX Function
``(acc, r, noise, flags) -> acc_next`` whose accumulator carries the step state and the running
sums of every figure of :mod:`fjm_runtime.sim.metrics` (the whole-run :class:`Metrics` and the
per-joint ``rms_second_half``, ``peak_torque``, ``time_at_limit`` and ``torque_jitter`` of the
``fjm simulate --json`` report), so a C driver folds it over samples and runs without storing
trajectories. The sensor noise is NOT an input array: the C drivers generate it per run and
sample with the counter-based generator of :mod:`fjm_runtime.sim.sensor` (``noise.c``, the same
integer arithmetic; log/sqrt/cos from libm), so memory does not grow with ``B * N``.

Gains per run. For a :class:`~fjm_runtime.control.laws.SlidingModeController` the emitted law's
``gains`` vector (its manifest layout) rides in the controller state as constants
(``z = [z_law; gains]``, ``gains' = 0``, so ``gains + T * 0`` is the same number every sample):
one compiled library serves every candidate of a gain search (:mod:`fjm_runtime.analysis.search.search`).
The law then reads ``delta`` (reaching time) and ``u_max``, ``limit`` (time at limit) from there.

Torque jitter over the applied torques ``u_0 .. u_{N-1}`` with ``h = round(window / 2T)``: the
accumulator holds a shift register of the last ``2h + 1`` torques (a ring buffer of the 20 ms
window); once full, the centred deviation ``u_{k-h} - mean(u_{k-2h} .. u_k)`` adds to a sum and a
sum of squares, and ``std = sqrt(E[d^2] - E[d]^2)`` (the population std of
:func:`fjm_runtime.sim.metrics.torque_jitter`, one pass instead of two: equal to rounding).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..control.laws import SlidingModeController
from ..sim.sample_step import sample_step_function
from ..sim.step_layout import StepLayout

__all__ = ["AccLayout", "GainInput", "jitter_half_width", "sampled_metric_step"]

#: Flags per sample: ``[in_second_half, k, is_first, is_last, applied, jitter_full]``.
N_FLAGS = 6


def jitter_half_width(T: float, window: float = 0.02) -> int:
    """``h`` of :func:`fjm_runtime.sim.metrics.torque_jitter`: ``max(1, round(window / (2 T)))``."""
    return max(1, int(round(0.5 * window / T)))


class GainInput:
    """A sliding-mode controller whose ``gains`` vector is read from the controller state.

    ``z = [z_law (n_law); gains (n_g)]`` with ``gains' = 0``; every other attribute the sample
    step reads (``sensing``, ``p_nom``, ``n_states``) is the wrapped controller's or derived.
    """

    def __init__(self, controller: SlidingModeController):
        self.base = controller
        self.sensing = controller.sensing
        self.p_nom = controller.p_nom
        self.n = controller.n
        self.n_law = int(controller.n_states)
        self.n_gains = int(np.asarray(controller.gains).size)
        self.n_states = self.n_law + self.n_gains
        self.model = controller.model
        self.layout = {b["name"]: (int(b["offset"]), int(b["size"]))
                       for b in controller.model.manifest["controls"][controller.law_kind]["gains"]}

    def gain_block(self, z, name: str):
        """Block ``name`` of the gains riding in ``z`` (SX/MX), shape (size, 1)."""
        off, size = self.layout[name]
        return z[self.n_law + off:self.n_law + off + size]

    def symbolic_evaluate(self, m, z, r, fns=None):
        law, _ = self.base.law_functions()
        u, s, _, u_cmd, y_hat = law(m, z[:self.n_law], r, ca.DM(self.p_nom), z[self.n_law:])
        return {"u": u, "u_cmd": u_cmd, "s": s, "y_hat": y_hat}

    def symbolic_state_derivative(self, m, z, r, sample):
        _, zdot = self.base.law_functions()
        zero = ca.DM.zeros(self.n_gains, 1)
        if self.n_law == 0:
            return zero
        out = zdot(m, z[:self.n_law], r, ca.DM(self.p_nom), z[self.n_law:], sample["u_cmd"], sample["u"])
        return ca.vertcat(out, zero)


@dataclass(frozen=True)
class AccLayout:
    """Where things sit in the batch accumulator ``acc = [w | sums | p]``.

    ``sums = [e2_half_j (n); e2_all; e2_half_all; peak_j (n); limit_count_j (n); max_u; last_out;
    tv; u_prev (n); first_bad; ring (width n); jit_sum (n); jit_sq (n); rate_count_j (n)]``.
    """

    nw: int
    n: int
    width: int
    n_par: int

    def offsets(self) -> dict:
        n, o, out = self.n, self.nw, {}
        for name, size in (("e2_half_j", n), ("e2_all", 1), ("e2_half_all", 1), ("peak_j", n),
                           ("limit_j", n), ("max_u", 1), ("last_out", 1), ("tv", 1), ("u_prev", n),
                           ("first_bad", 1), ("ring", self.width * n), ("jit_sum", n), ("jit_sq", n), ("rate_j", n)):
            out[name] = (o, size)
            o += size
        out["p"] = (o, self.n_par)
        return out

    @property
    def nacc(self) -> int:
        return self.offsets()["p"][0] + self.n_par

    def initial(self, w0, p) -> np.ndarray:
        """The accumulator before sample 0 (``last_out = first_bad = -1``, zero sums)."""
        acc = np.zeros(self.nacc)
        acc[:self.nw] = w0
        off = self.offsets()
        for name in ("last_out", "first_bad"):
            acc[off[name][0]] = -1.0
        acc[off["p"][0]:] = p
        return acc

    def get(self, acc, name: str):
        o, size = self.offsets()[name]
        return acc[..., o:o + size]


def _limits(ctrl, z, n):
    """``(u_max, limit)`` as CasADi expressions (from the riding gains or the controller)."""
    if isinstance(ctrl, GainInput):
        return ctrl.gain_block(z, "u_max"), ctrl.gain_block(z, "limit")[0]
    u_max = getattr(ctrl, "u_max", None)
    return (ca.DM.ones(n), 0.0) if u_max is None else (ca.DM(np.asarray(u_max, dtype=float)), 1.0)


def _delta(ctrl, z, n):
    if isinstance(ctrl, GainInput) and "delta" in ctrl.layout:   # a law without a layer (impedance): never outside
        return ctrl.gain_block(z, "delta")
    if isinstance(ctrl, GainInput):
        return ca.DM(np.full(n, np.inf))
    return ca.DM(np.asarray(getattr(ctrl, "delta", np.full(n, np.inf)), dtype=float))


def sampled_metric_step(model, ctrl, L: StepLayout, max_state: float, width: int):
    """``(acc, r, noise, flags) -> acc_next`` (SX, :class:`AccLayout`; ``flags`` of :data:`N_FLAGS`).

    ``ctrl`` is the controller of the step (a :class:`GainInput` or any controller with
    ``symbolic_evaluate``); ``width = 2h + 1`` the jitter window in samples. A run whose state
    became non-finite or beyond ``max_state`` (first row ``k + 1``, as ``simulate`` checks it)
    is frozen at its last good state and ``first_bad = k + 1`` recorded.
    """
    n, n_par = L.n, len(model.param_names)
    A = AccLayout(L.nw, n, int(width), n_par)
    off = A.offsets()
    acc = ca.SX.sym("acc", A.nacc)
    r, noise, fl = ca.SX.sym("r", 5 * n), ca.SX.sym("noise", L.nm), ca.SX.sym("flags", N_FLAGS)
    half, k, first, last, applied, jit_full = (fl[i] for i in range(N_FLAGS))
    g = {name: acc[o:o + size] for name, (o, size) in off.items()}
    w, p = acc[:L.nw], g["p"]
    w_step, aux = sample_step_function(model, ctrl, L, outline=True)(w, r, noise, p)
    u, s = aux[:n], aux[n:2 * n]
    z = w[L.slices()[1]]
    e1 = w[:n] - r[:n]
    e2 = e1 ** 2
    absu = ca.fabs(u)
    u_max, limit = _limits(ctrl, z, n)
    at_limit = limit * (absu >= u_max * (1.0 - 1e-9))
    outside = ca.mmax(ca.fabs(s) - _delta(ctrl, z, n)) > 0
    # at the rate limit: the applied torque moved by the whole allowed step (sample 0 has no u_prev)
    at_rate = (ca.fabs(u - g["u_prev"]) >= ca.DM(list(L.rate_step)) * (1.0 - 1e-9)) * (1 - first) \
        if L.rate_step else ca.DM.zeros(n)
    # the ring shifts at every sample: after the last one (applied = 0) it is never read again (jit_full = 0)
    ring = ca.vertcat(g["ring"][n:], u) if width > 1 else u
    mean = sum(ring[i * n:(i + 1) * n] for i in range(width)) / width
    h = (width - 1) // 2
    dev = ring[h * n:(h + 1) * n] - mean
    # the divergence check skips an entry the step copies from w (a riding gain, a delay-buffer shift): its
    # value was checked when it was computed
    copied = {w[j].name() for j in range(L.nw)}
    keep = [i for i in range(L.nw) if not (w_step[i].is_symbolic() and w_step[i].name() in copied)]
    absw = ca.fabs(w_step[keep])
    ok = (ca.mmax(absw) <= max_state) * (ca.sum1(absw) <= 1e308)  # NaN compares false
    was_bad = g["first_bad"][0] >= 0
    bad_now = (1 - ok) * (1 - was_bad) * (1 - last)
    freeze = last + was_bad + bad_now > 0
    # an entry the step passes through unchanged (the riding gains) stays the input itself, so the SIMD
    # emitter sees it constant along the run and hoists what depends on it
    w_next = ca.vertcat(*[w[i] if ca.is_equal(w_step[i], w[i]) else ca.if_else(freeze, w[i], w_step[i])
                          for i in range(L.nw)])
    acc_next = ca.vertcat(
        w_next,
        g["e2_half_j"] + half * e2, g["e2_all"] + ca.sum1(e2), g["e2_half_all"] + half * ca.sum1(e2),
        ca.fmax(g["peak_j"], applied * absu), g["limit_j"] + applied * at_limit,
        ca.fmax(g["max_u"], ca.mmax(absu)), ca.if_else(outside, k, g["last_out"]),
        g["tv"] + (1 - first) * ca.sum1(ca.fabs(u - g["u_prev"])), u,
        ca.if_else(bad_now, k + 1, g["first_bad"]),
        ring if width > 1 else g["ring"],
        g["jit_sum"] + jit_full * dev, g["jit_sq"] + jit_full * dev ** 2,
        g["rate_j"] + applied * at_rate,
        p)
    return ca.Function("fjm_sampled_step", [acc, r, noise, fl], [ca.cse(acc_next)]), A
