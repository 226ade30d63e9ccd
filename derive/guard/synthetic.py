"""Synthetic spatial serial chains (URDF + model file) for calibrating and testing the cost guard.

A chain of ``n`` revolute joints whose axes cycle z, y, x, with small joint
offsets, centres of mass off the link axes and non-zero products of inertia
(so that no term of the dynamics vanishes by symmetry), every joint elastic
with ``K = 1000 N m/rad`` and ``J_m = 0.1 kg m^2``. The numbers are made up
(plausible for a light arm); only the *size* of the derivation matters here.

Used by :mod:`derive.guard.cost` (calibration), the tests and the bench. No I/O
except :func:`write_synthetic_chain`, which writes the two files.
"""

from __future__ import annotations

from pathlib import Path
from typing import Tuple

__all__ = ["synthetic_urdf", "synthetic_model_file", "write_synthetic_chain", "SYNTHETIC_K", "SYNTHETIC_JM"]

#: Joint stiffness (N m/rad) and reflected motor inertia (kg m^2) of every synthetic joint.
SYNTHETIC_K = 1000.0
SYNTHETIC_JM = 0.1

_AXES = ("0 0 1", "0 1 0", "1 0 0")


def synthetic_urdf(n: int, robot: str = "synthetic") -> str:
    """URDF text of an ``n``-joint revolute chain ``base_link -> link1 -> ... -> link<n>``.

    Parameters
    ----------
    n : int
        Number of revolute joints (>= 1).
    robot : str
        The ``<robot name>``.

    Returns
    -------
    str
        The URDF document; joint ``j<i>`` turns about z, y, x, z, ... for i = 1, 2, 3, 4, ...
    """
    if int(n) != n or n < 1:
        raise ValueError(f"n = {n!r}; expected an integer number of joints >= 1")
    parts = ['<?xml version="1.0"?>', f'<robot name="{robot}">', '  <link name="base_link"/>']
    for i in range(1, int(n) + 1):
        k = i % 3
        mass = 1.0 + 0.1 * k
        parts += [
            f'  <joint name="j{i}" type="revolute">',
            f'    <origin xyz="{0.01 * (k + 1):.3f} {0.005 * (2 - k):.3f} 0.12" rpy="0 0 0"/>',
            f'    <parent link="{"base_link" if i == 1 else f"link{i - 1}"}"/>',
            f'    <child link="link{i}"/>',
            f'    <axis xyz="{_AXES[(i - 1) % 3]}"/>',
            '  </joint>',
            f'  <link name="link{i}">',
            '    <inertial>',
            f'      <origin xyz="0.01 {0.004 * (k + 1):.3f} 0.06" rpy="0 0 0"/>',
            f'      <mass value="{mass:.1f}"/>',
            f'      <inertia ixx="0.010" ixy="0.0005" ixz="0.0003" iyy="{0.012 + 0.001 * k:.3f}" '
            'iyz="0.0004" izz="0.008"/>',
            '    </inertial>',
            '  </link>',
        ]
    parts.append('</robot>')
    return "\n".join(parts) + "\n"


def synthetic_model_file(n: int, name: str, urdf_file: str) -> str:
    """TOML model file (URDF form) for :func:`synthetic_urdf` ``(n)`` stored at ``urdf_file``.

    Parameters
    ----------
    n : int
    name : str
        Model name (a C identifier).
    urdf_file : str
        Path of the URDF relative to the model file.
    """
    return (f'[model]\nname = "{name}"\nurdf = "{urdf_file}"\nbase = "base_link"\ntip = "link{int(n)}"\n'
            f'description = "Synthetic {int(n)}-joint spatial chain (axes z, y, x, ...) for the cost guard."\n\n'
            f'[joints.default]\nK = {SYNTHETIC_K!r}\nJm = {SYNTHETIC_JM!r}\n')


def write_synthetic_chain(n: int, directory: Path, name: str = None) -> Tuple[Path, Path]:
    """Write ``chain<n>.urdf`` and ``chain<n>.toml`` into ``directory`` (created).

    Returns
    -------
    (Path, Path)
        The model file and the URDF file.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    name = name or f"chain{int(n)}"
    urdf = directory / f"{name}.urdf"
    urdf.write_text(synthetic_urdf(n))
    toml = directory / f"{name}.toml"
    toml.write_text(synthetic_model_file(n, name, urdf.name))
    return toml, urdf
