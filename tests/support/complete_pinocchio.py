"""An independent Pinocchio build of a complete elastic model (rotor bodies as their own joints).

Shares no code with ``derive/``: the links come from Pinocchio's own URDF parser
(or :func:`support.independent_chain.pinocchio_chain`), and each rotor ``i`` is a
separate revolute joint appended to link ``i-1`` (the universe for ``i = 1``) at
joint ``i``'s placement and about joint ``i``'s axis, with the rotor inertia added
by ``appendBodyToJoint``. Its variable is the rotor angle ``theta_i = N_i q_m,i``,
so ``v_pin = T [dq; dq_m]`` with ``T = P diag(1, N)`` (``P`` the depth-first joint order); in fjm's coordinates
``M = T^T M_pin T``, ``b = T^T b_pin`` and generalized forces ``tau = T^T tau_pin``.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pinocchio as pin

_AXES = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0), "JointModelRZ": (0.0, 0.0, 1.0)}


def joint_axis(joint) -> np.ndarray:
    """The rotation axis of a Pinocchio revolute joint model, in its joint frame."""
    name = joint.shortname()
    if name in _AXES:
        return np.array(_AXES[name])
    if name == "JointModelRevoluteUnaligned":
        return np.array(joint.extract().axis, float)
    raise ValueError(f"unsupported joint {name}")


class CompleteReference:
    """Complete model = Pinocchio link model + one rotor joint per link joint.

    Parameters
    ----------
    links : pinocchio.Model
        ``n`` revolute joints (indices 1..n, joint k's parent is joint k-1), gravity set.
    N, Ia, It, mr : sequences of n floats
        Gear ratios, rotor polar and transverse inertias, rotor masses.
    """

    def __init__(self, links: pin.Model, N: Sequence[float], Ia: Sequence[float], It: Sequence[float],
                 mr: Sequence[float]):
        # Depth-first order (Pinocchio's algorithms need every subtree contiguous in v):
        # rotor 1, link 1, rotor 2 (on link 1), link 2, rotor 3 (on link 2), ...
        model = pin.Model()
        model.gravity = links.gravity
        n = links.njoints - 1
        order = []  # pinocchio v index -> fjm index (links 0..n-1, rotors n..2n-1)
        parent = 0
        for i in range(1, n + 1):
            a = joint_axis(links.joints[i])
            rotor = model.addJoint(parent, pin.JointModelRevoluteUnaligned(a), links.jointPlacements[i],
                                   f"rotor{i}")
            I = float(It[i - 1]) * (np.eye(3) - np.outer(a, a)) + float(Ia[i - 1]) * np.outer(a, a)
            model.appendBodyToJoint(rotor, pin.Inertia(float(mr[i - 1]), np.zeros(3), I), pin.SE3.Identity())
            order.append(n + i - 1)
            parent = model.addJoint(parent, links.joints[i], links.jointPlacements[i], links.names[i])
            model.appendBodyToJoint(parent, links.inertias[i], pin.SE3.Identity())
            order.append(i - 1)
        self.model, self.data, self.n = model, model.createData(), n
        P = np.zeros((2 * n, 2 * n))
        P[np.arange(2 * n), order] = 1.0  # v_pin = P T [dq; dq_m]
        self.T = P @ np.diag(np.concatenate([np.ones(n), np.asarray(N, float)]))

    def inertia(self, q: np.ndarray) -> np.ndarray:
        """``T^T M_pin T`` at link angles ``q`` (rotor angles do not enter), shape (2n, 2n)."""
        M = pin.crba(self.model, self.data, self._config(q))
        M = np.triu(M) + np.triu(M, 1).T
        return self.T.T @ M @ self.T

    def bias(self, q, dq, dqm) -> np.ndarray:
        """``T^T rnea(q, v, 0)`` (Coriolis, gyroscopic, gravity), shape (2n,)."""
        v = self.T @ np.concatenate([dq, dqm])
        return self.T.T @ pin.rnea(self.model, self.data, self._config(q), v, np.zeros(2 * self.n))

    def xdot(self, x: np.ndarray, u: np.ndarray, K, Bm) -> np.ndarray:
        """``[dq; ddq; dq_m; ddq_m]`` by ``aba`` with the spring and damping as joint torques."""
        n = self.n
        q, dq, qm, dqm = (x[k * n:(k + 1) * n] for k in range(4))
        K, Bm = np.asarray(K, float), np.asarray(Bm, float)
        tau = np.concatenate([K * (qm - q), K * (q - qm) - Bm * dqm + u])  # fjm coordinates
        tau_pin = np.linalg.solve(self.T.T, tau)
        v = self.T @ np.concatenate([dq, dqm])
        acc = np.linalg.solve(self.T, pin.aba(self.model, self.data, self._config(q), v, tau_pin))
        return np.concatenate([dq, acc[:n], dqm, acc[n:]])

    def _config(self, q: np.ndarray) -> np.ndarray:
        return self.T @ np.concatenate([np.asarray(q, float), np.zeros(self.n)])
