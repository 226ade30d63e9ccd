"""A generated fjm model inside a CasADi ``Opti`` problem: minimum-effort point-to-point motion.

The drift ``f(x, p)`` and input matrix ``g(x, p)`` are the CasADi Functions that
``make derive`` wrote to ``generated/<model>/{f,g}.casadi`` (loaded here through
``fjm_runtime.load(model).functions``), so they can be called on symbolic ``MX``
just like on numbers. The problem, multiple shooting with one RK4 step per
interval of length ``dt``::

    minimise    sum_k dt |u_k|^2
    subject to  x_{k+1} = RK4(x_k, u_k)            (x' = f(x) + g(x) u)
                x_0 = rest at q = q0 (hanging down, spring unloaded)
                q(t_N) = q_target, dq = dq_m = 0 at t_N,
                f(x_N) + g(x_N) u_hold = 0           (x_N is an equilibrium held by u_hold)
                |u_k| <= u_max

Run ``python examples/opti_mpc.py`` (link1, 2 s, to q = pi/2) or
``python examples/opti_mpc.py --model planar2 --target 0.5 -0.3``.
``--json FILE`` writes the solution (t, X, U, u_hold, ...) for further use.
The first control of the solution is what one MPC step would apply.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Dict, Optional, Sequence

import casadi as ca
import numpy as np

import fjm_runtime


def rk4_step(f: ca.Function, g: ca.Function, x, u, p, dt: float):
    """One classical RK4 step of x' = f(x, p) + g(x, p) u with u held constant."""
    def xdot(xx):
        return f(xx, p) + ca.mtimes(g(xx, p), u)
    k1 = xdot(x)
    k2 = xdot(x + dt / 2 * k1)
    k3 = xdot(x + dt / 2 * k2)
    k4 = xdot(x + dt * k3)
    return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def solve(model: str = "link1", q_target: Optional[Sequence[float]] = None, horizon: float = 2.0,
          intervals: int = 40, u_max: float = 60.0, params: Optional[Dict[str, float]] = None,
          verbose: bool = False) -> Dict[str, object]:
    """Solve the point-to-point problem; returns a dict of NumPy arrays and solver statistics."""
    m = fjm_runtime.load(model)
    n, nx = m.n, m.nx
    p = m.params_array(params)                      # validated, in param_names order
    q_target = np.full(n, np.pi / 2) if q_target is None else np.asarray(q_target, dtype=float)
    q_target = m.state_array(np.concatenate([q_target, np.zeros(3 * n)]))[:n]
    f, g = m.functions["f"], m.functions["g"]
    dt = horizon / intervals

    opti = ca.Opti()
    X = opti.variable(nx, intervals + 1)
    U = opti.variable(n, intervals)
    u_hold = opti.variable(n)

    opti.minimize(dt * ca.sumsqr(U))
    opti.subject_to(X[:, 0] == np.zeros(nx))        # at rest, hanging straight down
    for k in range(intervals):
        opti.subject_to(X[:, k + 1] == rk4_step(f, g, X[:, k], U[:, k], p, dt))
    xN = X[:, intervals]
    opti.subject_to(xN[:n] == q_target)
    opti.subject_to(xN[n:2 * n] == 0)
    opti.subject_to(xN[3 * n:] == 0)
    opti.subject_to(f(xN, p) + ca.mtimes(g(xN, p), u_hold) == 0)
    opti.subject_to(opti.bounded(-u_max, ca.vec(U), u_max))

    # initial guess: linear interpolation of the link and motor angles
    s = np.linspace(0, 1, intervals + 1)
    guess = np.zeros((nx, intervals + 1))
    guess[:n] = np.outer(q_target, s)
    guess[2 * n:3 * n] = np.outer(q_target, s)
    opti.set_initial(X, guess)

    opti.solver("ipopt", {"print_time": False},
                {"print_level": 5 if verbose else 0, "sb": "yes", "tol": 1e-10, "max_iter": 200})
    t0 = time.perf_counter()
    sol = opti.solve()
    seconds = time.perf_counter() - t0
    stats = sol.stats()
    return {
        "model": model,
        "param_names": list(m.param_names),
        "p": p.tolist(),
        "q_target": q_target.tolist(),
        "dt": dt,
        "t": np.linspace(0, horizon, intervals + 1).tolist(),
        "X": np.atleast_2d(sol.value(X)).tolist(),
        "U": np.atleast_2d(sol.value(U)).reshape(n, intervals).tolist(),
        "u_hold": np.atleast_1d(sol.value(u_hold)).tolist(),
        "u_max": u_max,
        "cost": float(sol.value(opti.f)),
        "success": bool(stats["success"]),
        "iterations": int(stats["iter_count"]),
        "solve_seconds": seconds,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default="link1")
    ap.add_argument("--target", type=float, nargs="+", help="target link angles (rad); default pi/2 each")
    ap.add_argument("--horizon", type=float, default=2.0)
    ap.add_argument("--intervals", type=int, default=40)
    ap.add_argument("--u-max", type=float, default=60.0)
    ap.add_argument("--json", metavar="FILE", help="write the solution to FILE")
    ap.add_argument("--verbose", action="store_true", help="show Ipopt's iterations")
    args = ap.parse_args(argv)
    res = solve(args.model, args.target, args.horizon, args.intervals, args.u_max, verbose=args.verbose)
    X, U = np.array(res["X"]), np.array(res["U"])
    n = U.shape[0]
    print(f"{res['model']}: {'solved' if res['success'] else 'FAILED'} in {res['iterations']} iterations "
          f"({res['solve_seconds']:.2f} s), cost {res['cost']:.4g}")
    print(f"  q(T) = {np.round(X[:n, -1], 6).tolist()}  target {np.round(res['q_target'], 6).tolist()}")
    print(f"  max |u| = {np.abs(U).max():.4g} (bound {res['u_max']}), holding torque {np.round(res['u_hold'], 4).tolist()}")
    print(f"  first MPC control u_0 = {np.round(U[:, 0], 4).tolist()}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(res, fh, indent=1)
    return 0 if res["success"] else 1


if __name__ == "__main__":
    sys.exit(main())
