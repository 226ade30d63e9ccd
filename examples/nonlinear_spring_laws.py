"""What deriving the law for the real spring buys: link1_hd's cubic-spring law against linear-spring laws.

    .venv/bin/python examples/nonlinear_spring_laws.py [--duration 6] [--draws 8]

The plant is ``link1_hd`` (the paper's link on a cubic harmonic-drive spring, ``psi = k1 phi +
k3 phi^3``: 75 N m/rad at rest, 150 at 0.1 rad). Three integral sliding-mode laws with the same gains
track a 1 rad, 2 rad/s sine in the sampled loop as a robot runs it (1 kHz, zero-order hold, plant on
substeps, ``panda_white`` noise, one sample of delay with prediction over each law's own nominal
model), all STATE-sensed:

* the law derived for the cubic spring (``link1_hd``: ``beta = J_l J_m / psi'(phi)``, ``y3``, ``y4`` with
  ``psi``, ``psi'``), at the true coefficients;
* link1's law (linear spring) with ``K = k1``, the small-deflection stiffness (a datasheet's K1);
* link1's law with ``K = 150``, the stiffness at 0.1 rad (a linear fit over the working range).

It prints the worst second-half RMS, the time at the torque limit and the largest deflection.

Then motor friction: the TRUE plant gets Coulomb + Stribeck friction on the motor (``F_c = 1``,
``F_s = 1.5 N m``, derive/core/friction.py), and the law derived for the cubic spring runs with the
NOMINAL friction fed forward (``F_c = 0.7``, ``F_s = 1.05``: 30 % low, as an identification might
miss it) against the same law without it (nominal ``F_c = F_s = 0``).

Last the datasheet curve (``arm1_hd``: a one-link arm on a harmonic drive, stiffness 1.3e4 to 2.0e4
N m/rad over three segments, motor friction) in a Franka-like loop, TORQUE- and state-sensed (the
simulated sensor measures the true curve ``psi(q_m - q)``): the law derived for the curve against the
same law told a linear spring ``K_1``, and without the friction feedforward.
"""
from __future__ import annotations

import argparse

import numpy as np

import fjm_runtime
from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import make_reference
from fjm_runtime.sim.metrics import rms_second_half, time_at_limit
from fjm_runtime.sim.sensor import SensorModel
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.sim.step import SimulationDivergedError

GAINS = {"lam": 10.0, "k_s": 50.0, "delta": 2.0, "u_max": 60.0}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=6.0, help="simulated seconds (default 6)")
    ap.add_argument("--draws", type=int, default=8, help="true drives of the arm1_hd section (default 8)")
    args = ap.parse_args(argv)
    hd, l1 = fjm_runtime.load("link1_hd"), fjm_runtime.load("link1")
    d = hd.default_params
    ref = make_reference("sine", 1, amplitude=1.0, omega=2.0)
    laws = {"derived for the cubic spring": make_controller("ismc", hd, d, **GAINS),
            f"linear spring, K = k1 = {d['k1']:g}": make_controller("ismc", l1, {**l1.default_params, "K": d["k1"]},
                                                                   **GAINS),
            "linear spring, K = 150 (psi' at 0.1 rad)": make_controller("ismc", l1, {**l1.default_params, "K": 150.0},
                                                                       **GAINS)}
    out = {}
    print(f"link1_hd, 1 kHz, panda_white noise, delay 1 with prediction, {args.duration:g} s of a 1 rad sine:")
    for label, ctrl in laws.items():
        try:
            r = simulate(hd, ctrl, ref, duration=args.duration, dt=1e-3, sensor=SensorModel.panda_white(),
                         delay_samples=1, predict=True)
        except SimulationDivergedError as exc:
            print(f"  {label:42s} diverged ({str(exc)[:60]})")
            continue
        phi = r.x[:, 2] - r.x[:, 0]
        out[label] = float(np.max(rms_second_half(r)))
        print(f"  {label:42s} worst RMS {out[label]:.3g} rad, {100 * np.max(time_at_limit(r)):.1f} % at the limit, "
              f"max deflection {np.max(np.abs(phi)):.3f} rad")
    out.update(friction_section(hd, ref, args.duration))
    out.update(datasheet_section(min(args.duration, 4.0), args.draws))
    return out


def _run(model, ctrl, ref, duration, true=None):
    r = simulate(model, ctrl, ref, duration=duration, dt=1e-3, sensor=SensorModel.panda_white(), delay_samples=1,
                 predict=True, true_params=true)
    return float(np.max(rms_second_half(r))), float(np.max(time_at_limit(r)))


def friction_section(hd, ref, duration) -> dict:
    """The cubic-spring law with and without the nominal friction feedforward, on a plant with friction."""
    d = hd.default_params
    true = {**d, "F_c": 1.0, "F_s": 1.5}
    laws = {"friction fed forward (nominal 30 % low)": {**d, "F_c": 0.7, "F_s": 1.05},
            "no friction compensation": dict(d)}
    print(f"link1_hd with motor friction (true F_c = {true['F_c']:g}, F_s = {true['F_s']:g} N m), same loop:")
    out = {}
    for label, nominal in laws.items():
        rms, lim = _run(hd, make_controller("ismc", hd, nominal, **GAINS), ref, duration, true)
        out[label] = rms
        print(f"  {label:42s} worst RMS {rms:.3g} rad, {100 * lim:.1f} % at the limit")
    return out



def datasheet_section(duration: float, draws: int) -> dict:
    """arm1_hd (three-segment datasheet curve, motor friction): the laws of
    :data:`fjm_runtime.experiments.real_drives.LAWS` over ``draws`` true drives (the demo's section)."""
    from fjm_runtime.experiments.real_drives import compare_datasheet_laws
    print(f"arm1_hd (datasheet curve, motor friction), 1 kHz, franka_like sensor and torque-rate limit, delay 1 "
          f"with prediction, {duration:g} s of a 0.5 rad sine about horizontal, {draws} true drives:")
    out = {}
    for key, row in compare_datasheet_laws(duration, draws).items():
        out[key] = max(row["rms"])
        print(f"  {key:42s} worst RMS {out[key]:.3g} rad (median {np.median(row['rms']):.3g}), "
              f"{100 * max(row['at_limit']):.1f} % at the limit, deflection up to {1e3 * row['phi'][1]:.2f} mrad")
    return out

if __name__ == "__main__":
    main()
