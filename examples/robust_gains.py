"""Synthesized switching gains (fjm_runtime.analysis.certificates.certify) for the generated models, as a Markdown table.

Controller on NOMINAL parameters, certificate over the TRUE parameter box. Run:
``python examples/robust_gains.py [--models link1,planar2,planar3] [--u-max 100]``.
Each row: the box, the per-joint gain, the certificate (worst sgn(s) s' bound
found, must be <= -eta), the largest torque the law may command on the box and
whether a gain exists within the actuator limit.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import fjm_runtime as fjm
from fjm_runtime.control.defaults import DEFAULT_LAM, PAPER_K_RANGE
from fjm_runtime.control.references import Sinusoid, SmoothStep
from fjm_runtime.analysis.certificates.lemma1 import beta_hat_link1
from fjm_runtime.analysis.certificates.certify import synthesize_gains


def _fmt(a):
    return "(" + ", ".join(f"{v:.4g}" for v in np.atleast_1d(a)) + ")"


def cases(models, u_max):
    for name in models:
        m = fjm.load(name)
        n = m.n
        if name == "link1":
            for task, ref, E in (("regulation", SmoothStep(1.0, rise_time=2.0), (0.05, 0.1, 0.5, 1.0)),
                                 ("tracking", Sinusoid(0.5, 1.0), (0.05, 0.5, 0.5, 0.5))):
                for lam in (DEFAULT_LAM, 20.0, 30.0):
                    yield (m, f"{task}, K in [100, 200], K_nom = 150, beta_hat paper", lam,
                           dict(nominal_params={"K": 150.0}, param_box={"K": PAPER_K_RANGE},
                                reference_bounds=ref.derivative_bounds()[:, 0], error_bounds=E,
                                beta_hat=beta_hat_link1({"K": 150.0}, {"K": PAPER_K_RANGE})))
            continue
        ref = Sinusoid([0.5, 0.3, 0.2][:n], [1.0, 1.5, 2.0][:n], n=n, phase=[0.0, 0.5, 0.0][:n])
        for k_nom, (lo, hi) in ((150.0, PAPER_K_RANGE), (100.0, PAPER_K_RANGE), (150.0, (140.0, 160.0))):
            yield (m, f"tracking, K_i in [{lo:g}, {hi:g}], K_nom = {k_nom:g}", DEFAULT_LAM,
                   dict(nominal_params={f"K{i + 1}": k_nom for i in range(n)},
                        param_box={f"K{i + 1}": (lo, hi) for i in range(n)},
                        reference_bounds=ref.derivative_bounds(), error_bounds=(0.05, 0.5, 0.5, 0.5)))


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--models", default="link1,planar2,planar3")
    ap.add_argument("--u-max", type=float, default=100.0, help="actuator limit, N m (default 100)")
    args = ap.parse_args()
    print(f"| model | box | lambda | k_s | certificate | max abs(u) on box (N m) | within u_max = {args.u_max:g} | s |")
    print("|---|---|---|---|---|---|---|---|")
    for m, box, lam, kw in cases(args.models.split(","), args.u_max):
        t0 = time.perf_counter()
        r = synthesize_gains(m, lam=lam, u_max=args.u_max, **kw)
        ok = "yes" if r.feasible else "**no**"
        print(f"| {m.name} | {box} | {lam:g} | {_fmt(r.k_s)} | {_fmt(r.certificate)} | {_fmt(r.u_bound)} | {ok} | "
              f"{time.perf_counter() - t0:.0f} |", flush=True)


if __name__ == "__main__":
    main()
