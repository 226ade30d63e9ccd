"""Run an fjm controller against the Panda exported to MuJoCo.

    .venv/bin/python examples/mujoco_closed_loop.py [--duration 2] [--out panda.xml]

1. ``write_mjcf`` writes the elastic Panda (links from the URDF, rotor hinges,
   spring tendons, motors ``<joint>_motor``, sensors) as an MJCF file, with the
   MuJoCo step = the control period / SUBSTEPS and the RK4 integrator.
2. MuJoCo loads the file as it is (``mujoco.MjModel.from_xml_path``).
3. An integral sliding-mode law of the REDUCED model on its NOMINAL parameters
   (``make_controller``) runs at 1 kHz: each millisecond it reads the state from
   MuJoCo's ``qpos``/``qvel`` (the rotor joint angle is ``N q_m``; N = 1 here),
   computes ``u`` and holds it in ``ctrl`` over SUBSTEPS MuJoCo steps. The plant
   has the nominal parameters: at 1 kHz the zero-order hold against the wrist's
   ~700 rad/s mode alone costs joint 7 about 0.1 rad (fjm's Panda demo runs at
   5 kHz; a stiffness error on this arm needs more than this law, see docs/spatial.md).
4. It prints the tracking error per joint and how far MuJoCo's trajectory is
   from fjm's own plant (``fjm_runtime.simulate`` on the same substeps).

The same loop works with any MuJoCo model that follows the export's names.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import mujoco
import numpy as np

import fjm_runtime
from fjm_runtime.export.mjcf import write_mjcf

DT = 1e-3          # s: the control period (1 kHz, the Panda's real loop rate)
SUBSTEPS = 20      # MuJoCo steps per control period (5e-5 s: the wrist mode is ~700 rad/s)


def rest_state(model, q, p):
    """At rest at link angles q holding gravity: q_m = q + K^-1 G(q)."""
    n = model.n
    x = np.concatenate([q, np.zeros(n), q, np.zeros(n)])
    G = -model.inertia(x, p) @ model.f(x, p)[n:2 * n]
    x[2 * n:3 * n] = q + G / np.array([p[f"K{i + 1}"] for i in range(n)])
    return x


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=2.0, help="simulated seconds (default 2)")
    ap.add_argument("--out", type=Path, default=None, help="where to write the MJCF (default: a temp file)")
    args = ap.parse_args(argv)

    m = fjm_runtime.load("panda")
    n = m.n
    true = dict(m.default_params, m_load=0.0)
    path = args.out or Path(tempfile.mkdtemp()) / "panda.xml"
    write_mjcf(m, path, true, timestep=DT / SUBSTEPS)

    mj = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(mj)
    joints = m.manifest["source"]["joints"]
    qpos = [mj.joint(j).qposadr[0] for j in joints] + [mj.joint(f"{j}_rotor").qposadr[0] for j in joints]
    qvel = [mj.joint(j).dofadr[0] for j in joints] + [mj.joint(f"{j}_rotor").dofadr[0] for j in joints]
    ctrl = [mj.actuator(f"{j}_motor").id for j in joints]

    def read_state():  # fjm's x = [q; dq; q_m; dq_m] (gear ratio 1: rotor angle = q_m)
        pos, vel = data.qpos[qpos], data.qvel[qvel]
        return np.concatenate([pos[:n], vel[:n], pos[n:], vel[n:]])

    ref = m.task.reference()   # the Panda's own task (panda.toml [task]): sines about Franka's ready pose
    x0 = rest_state(m, np.asarray(ref(0.0))[0], true)

    def law():  # the nominal model (the defaults), integral sliding surface, torque-limited
        return fjm_runtime.make_controller("ismc", m, m.default_params, lam=10.0, k_s=200.0, delta=1.0,
                                           u_max=np.array(m.limits.effort))  # N m, the URDF's
    controller = law()
    data.qpos[qpos] = np.concatenate([x0[:n], x0[2 * n:3 * n]])
    data.qvel[qvel] = 0.0
    z = controller.initial_state(0.0, x0, np.asarray(ref(0.0)))
    steps = int(round(args.duration / DT))
    err = np.zeros((steps + 1, n))
    X = np.zeros((steps + 1, 4 * n))
    for k in range(steps + 1):
        t, x, r = k * DT, read_state(), np.asarray(ref(k * DT))
        sample = controller.evaluate(t, x, z, r)
        err[k], X[k] = x[:n] - r[0], x
        if k == steps:
            break
        z = z + DT * controller.state_derivative(t, x, z, r, sample)   # the law's state, once per sample
        data.ctrl[ctrl] = sample.u                                     # held over the sample
        for _ in range(SUBSTEPS):
            mujoco.mj_step(mj, data)

    # ctrl = u held over the sample above: the ideal actuator (no current loop) on fjm's side too
    fjm = fjm_runtime.simulate(m, law(), ref, duration=steps * DT, dt=DT, substeps=SUBSTEPS, true_params=true,
                               x0=x0, interface="ideal")
    rms = np.sqrt(np.mean(err[steps // 2:] ** 2, axis=0))
    gap = float(np.max(np.abs(X - fjm.x)))
    print(f"MuJoCo {mujoco.__version__}, {path}: Panda, ismc at {1 / DT:g} Hz, {SUBSTEPS} MuJoCo steps per sample, "
          f"{steps * DT:g} s, plant = nominal model")
    print("RMS tracking error, second half (rad): " + " ".join(f"{v:.2e}" for v in rms))
    print(f"max |error| (rad): {np.max(np.abs(err)):.3e}; MuJoCo vs fjm's own plant, max |x difference|: {gap:.2e}")
    return {"rms": rms, "max_error": float(np.max(np.abs(err))), "gap": gap}


if __name__ == "__main__":
    main()
