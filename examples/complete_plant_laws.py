"""Which law to ship for the complete Panda: the torque-sensed reduced law or the state-sensed compensated law.

    .venv/bin/python examples/complete_plant_laws.py [--duration 4] [--noise panda_white]

The complete elastic model (rotor i on link i-1, gear ratio 100: docs/complete-model.md) has no
static feedback linearization. Two laws drive it, both as a real loop runs (1 kHz, zero-order hold,
the plant on finer RK4 substeps, one sample of delay with prediction over the NOMINAL reduced
model, the sensor noise of ``--noise``), the plant at the complete model's defaults:

* ``torque-sensed reduced``: the Panda's shipped design (torque-sensed integral SMC, its gains,
  its task): the law reads ``tau_J`` and never needs the spring model, so the spin coupling that
  the reduced model lacks only enters as a disturbance on the link side.
* ``state-sensed compensated``: the reduced integral SMC of the complete-model section (lambda 10,
  k_s 200, delta 1, URDF torque limits) wrapped by :class:`CouplingCompensatedController`, which
  adds the coupling back from the nominal complete model; it reads ``q_m`` and builds the joint
  torque as ``K (q_m - q)``, so encoder noise reaches the law multiplied by the stiffness.
  The same law without noise, without delay, and at 5 kHz (the rate of the complete-model section)
  are the next rows: what the compensation does when nothing but the sample period is in its way
  (it estimates the accelerations under the torque held over the PREVIOUS sample: an error that
  grows with the period).

It prints, per law, the worst joint's RMS of ``e1`` over the second half, the time at a torque
limit and the torque jitter of joints 1-4 (the metrics and thresholds of ``fjm design``).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import fjm_runtime
from fjm_runtime.control.design import Design
from fjm_runtime.control.coupling import CouplingCompensatedController, complete_plant
from fjm_runtime.sim.step import SimulationDivergedError
from fjm_runtime.experiments import panda as P
from fjm_runtime.export.controller import design_controller
from fjm_runtime.sim.metrics import rms_second_half, time_at_limit, torque_jitter
from fjm_runtime.sim.sensor import sensor_from_spec
from fjm_runtime.sim.simulate import simulate

DESIGN = Path(fjm_runtime.__file__).parent / "control" / "designed" / "panda_ismc_tau_1000hz_d1.json"


def _metrics(res) -> str:
    if isinstance(res, Exception):
        return f"diverged ({str(res).splitlines()[0][:60]})"
    rms = rms_second_half(res)
    return (f"worst RMS {np.max(rms):.2e} rad (joint {int(np.argmax(rms)) + 1}), "
            f"{100 * np.max(time_at_limit(res)):.1f} % at a limit, "
            f"jitter j1-4 {np.max(torque_jitter(res)[:4]):.2f} N m")


def _run(plant, ctrl, ref, x0, duration, sensor, dt, delay=1):
    try:
        return simulate(plant, ctrl, ref, duration=duration, dt=dt, x0=x0, sensor=sensor, delay_samples=delay,
                        predict=delay > 0)
    except SimulationDivergedError as exc:
        return exc


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=4.0, help="simulated time, s (default 4)")
    ap.add_argument("--noise", default=None, help="sensor preset or file (default: the design's, panda_white)")
    args = ap.parse_args(argv)
    reduced, complete = fjm_runtime.load("panda"), fjm_runtime.load("panda_complete")
    plant = complete_plant(complete, reduced)
    gains = Design.load(DESIGN, where=str(DESIGN))
    design = design_controller(reduced, gains)
    sensor = design.sensor if args.noise is None else sensor_from_spec(args.noise)
    ref, x0 = gains.reference(reduced), gains.start_state(reduced)
    comp = CouplingCompensatedController(P.controller("ismc", reduced), complete, None, dt=design.layout.T)
    comp5k = CouplingCompensatedController(P.controller("ismc", reduced), complete, None, dt=2e-4)
    rows = {
        "torque-sensed reduced (shipped design)": _run(plant, design.controller, ref, x0, args.duration, sensor,
                                                       design.layout.T),
        f"state-sensed compensated ({gains.noise or sensor.name if args.noise is None else args.noise})": _run(plant, comp, ref, x0, args.duration, sensor,
                                                         design.layout.T),
        "state-sensed compensated (no noise)": _run(plant, comp, ref, x0, args.duration, None, design.layout.T),
        "state-sensed compensated (no noise, no delay)": _run(plant, comp, ref, x0, args.duration, None,
                                                              design.layout.T, delay=0),
        "state-sensed compensated (no noise, no delay, 5 kHz)": _run(plant, comp5k, ref, x0, args.duration, None,
                                                                     2e-4, delay=0),
        "torque-sensed reduced (no noise, no delay)": _run(plant, design.controller, ref, x0, args.duration, None,
                                                           design.layout.T, delay=0),
    }
    print(f"panda_complete (N = 100), 1 kHz, delay 1 with prediction, {args.duration:g} s of the design's task:")
    for label, res in rows.items():
        print(f"  {label:52s} {_metrics(res)}")
    return rows


if __name__ == "__main__":
    main()
