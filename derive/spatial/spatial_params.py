"""Parameter tables of a spatial chain: elastic joints, tip payload, symbolic link inertials.

``param_names`` of a URDF model (docs/design.md, "Spatial arms from URDF"):
``K1..Kn, Jm1..Jmn, Bm1..Bmn, g0`` (:func:`elastic_params`), then optionally
the tip payload ``m_load, x_load, y_load, z_load`` (:func:`payload_params`),
then the inertial parameters of the links kept symbolic
(:func:`inertial_params`). :func:`derive.spatial.spatial.make_spatial` checks this
order. Pure data: no I/O.
"""

from __future__ import annotations

from typing import Dict, Sequence, Tuple

from .chain import ChainDescription, chain_numerics
from ..core.model_base import Param

__all__ = ["PAYLOAD", "payload_params", "INERTIAL_FIELDS", "inertial_params", "elastic_params"]

#: Optional tip payload parameters (a point mass in the tip link frame), after g0.
PAYLOAD: Tuple[str, ...] = ("m_load", "x_load", "y_load", "z_load")


def payload_params(mass: float, com: Sequence[float], tip: str) -> Tuple[Param, ...]:
    """Parameters ``m_load, x_load, y_load, z_load``: a point payload fixed to the tip link.

    Parameters
    ----------
    mass : float
        Default payload mass (kg, >= 0).
    com : sequence of 3 floats
        Default position of the payload in the tip link frame (m).
    tip : str
        Tip link name, quoted in the meanings.
    """
    return (Param("m_load", float(mass), f"payload mass, a point mass fixed to the tip link {tip} (>= 0)", "kg"),
            *(Param(f"{a}_load", float(v), f"payload position along {a} of the tip link {tip} frame", "m")
              for a, v in zip("xyz", com)))


#: Inertial parameters of a link listed in ``symbolic`` (suffix ``_<link>``).
INERTIAL_FIELDS: Tuple[Tuple[str, str, str], ...] = (
    ("m", "mass of link {l}", "kg"),
    ("cx", "centre of mass of link {l}, x in the link frame", "m"),
    ("cy", "centre of mass of link {l}, y in the link frame", "m"),
    ("cz", "centre of mass of link {l}, z in the link frame", "m"),
    ("ixx", "inertia of link {l} about its centre of mass, xx (URDF inertial frame)", "kg m^2"),
    ("ixy", "inertia of link {l} about its centre of mass, xy (URDF inertial frame)", "kg m^2"),
    ("ixz", "inertia of link {l} about its centre of mass, xz (URDF inertial frame)", "kg m^2"),
    ("iyy", "inertia of link {l} about its centre of mass, yy (URDF inertial frame)", "kg m^2"),
    ("iyz", "inertia of link {l} about its centre of mass, yz (URDF inertial frame)", "kg m^2"),
    ("izz", "inertia of link {l} about its centre of mass, zz (URDF inertial frame)", "kg m^2"),
)


def inertial_params(desc: ChainDescription, links: Sequence[str]) -> Tuple[Param, ...]:
    """Parameters ``m_<link>, cx_<link>, ..., izz_<link>`` with the URDF values as defaults.

    The inertial frame's orientation (``rpy``) stays baked; the centre of mass
    is in the link frame, the tensor in the inertial frame (URDF conventions).
    """
    num = chain_numerics(desc, links)
    out = []
    for link, _, _, _, inertial in num.symbolic:
        values = (inertial.mass, *inertial.xyz, *inertial.inertia)
        out += [Param(f"{f}_{link}", float(v), meaning.format(l=link), unit)
                for (f, meaning, unit), v in zip(INERTIAL_FIELDS, values)]
    return tuple(out)


def elastic_params(n: int, K: Sequence[float], Jm: Sequence[float], Bm: Sequence[float],
                   g0: float = 9.81, joint_names: Sequence[str] = None,
                   sources: Dict[str, str] = None) -> Tuple[Param, ...]:
    """Parameter table ``K1..Kn, Jm1..Jmn, Bm1..Bmn, g0`` of a spatial chain.

    Parameters
    ----------
    n : int
    K, Jm, Bm : sequence of float, length n
        Defaults (N m/rad, kg m^2, N m s/rad).
    g0 : float
    joint_names : sequence of str, optional
        URDF joint names, quoted in the meanings.
    sources : dict str -> str, optional
        Extra text appended to the meaning of ``K`` and ``Jm`` (e.g. where the
        illustrative values come from).
    """
    names = list(joint_names) if joint_names is not None else [str(i + 1) for i in range(n)]
    sources = sources or {}
    groups = [("K", K, "stiffness of joint {i} ({j})", "N m/rad"),
              ("Jm", Jm, "reflected inertia of motor {i} ({j})", "kg m^2"),
              ("Bm", Bm, "viscous damping of motor {i} ({j})", "N m s/rad")]
    params = []
    for g, values, meaning, unit in groups:
        for i in range(n):
            text = meaning.format(i=i + 1, j=names[i]) + sources.get(g, "")
            params.append(Param(f"{g}{i + 1}", float(values[i]), text, unit))
    params.append(Param("g0", float(g0), "gravitational acceleration along -z of the base frame", "m/s^2"))
    return tuple(params)

