"""The domain of every runtime parameter, written into each manifest entry as ``domain``.

Grammar (one string, the same kinds :func:`derive.model_file.schema.number` checks in model files):

- ``">0"``: a finite real strictly above zero (masses, lengths, inertias, stiffnesses, rotor inertias,
  gear ratios, the friction's velocities, the spring coefficients that are stiffnesses or torques);
- ``">=0"``: a finite real at or above zero (gravity, damping, friction levels, the payload mass);
- ``"any"``: any finite real (payload and centre-of-mass positions, off-diagonal inertia entries, a cubic
  coefficient).

Relations between parameters (a centre of mass on its link, a positive definite inertia tensor, the
three-segment spring's ordered breakpoints) are checked by the runtime on top of these.
"""

from __future__ import annotations

import re
from typing import Dict, Optional

__all__ = ["DOMAINS", "SPRING_DOMAINS", "FRICTION_DOMAINS", "ROLE_DOMAINS", "parameter_domain"]

#: Every domain string the manifests use.
DOMAINS = (">0", ">=0", "any")

#: A spring law's coefficients (``K``: the linear law's stiffness).
SPRING_DOMAINS: Dict[str, str] = {"K": ">0", "k1": ">0", "k3": "any", "K_1": ">0", "K_2": ">0", "K_3": ">0",
                                  "T_1": ">0", "T_2": ">0", "w_blend": ">0"}

#: The motor friction's coefficients (derive.core.friction).
FRICTION_DOMAINS: Dict[str, str] = {"F_c": ">=0", "F_s": ">=0", "v_s": ">0", "v_c": ">0"}

#: The other drive roles.
ROLE_DOMAINS: Dict[str, str] = {"rotor_inertia": ">0", "damping": ">=0", "gear_ratio": ">0"}

# Link and gravity parameters of the model families (link1, planar<n>, URDF arms with a payload and
# symbolic inertials ``m_<link>``, ``cx_<link>``, ``ixx_<link>``).
_POSITIVE = re.compile(r"^(J_l|M|L|m\d+|l\d+|r\d+|I\d+|m_(?!load$).+)$")
_NON_NEGATIVE = re.compile(r"^(g0|m_load)$")


def parameter_domain(name: str, role: Optional[str] = None, coefficient: Optional[str] = None) -> str:
    """The domain string of parameter ``name``.

    Parameters
    ----------
    name : str
        Runtime parameter name.
    role : str, optional
        Its drive role (``"spring"``, ``"rotor_inertia"``, ``"damping"``, ``"friction"``,
        ``"gear_ratio"``), None for a link or gravity parameter.
    coefficient : str, optional
        The law's coefficient name for a spring or friction parameter (``"K_1"``, ``"F_c"``).
    """
    if role == "spring":
        return SPRING_DOMAINS[coefficient]
    if role == "friction":
        return FRICTION_DOMAINS[coefficient]
    if role is not None:
        return ROLE_DOMAINS[role]
    if _POSITIVE.match(name):
        return ">0"
    return ">=0" if _NON_NEGATIVE.match(name) else "any"
