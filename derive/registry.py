"""Model registry: the built-in models by name (:data:`MODEL_NAMES`, :func:`build`).

``link1`` and ``planar1..7`` are closed forms (:mod:`derive.planar.planar`), ``link1_hd`` its cubic-spring
variant (:mod:`derive.core.spring`), ``arm1_hd`` a one-link drive model file with the three-segment
datasheet spring (``derive/robots/arm1_hd``); the
spatial arms ``elbow3`` and ``panda`` are URDF model files shipped in
``derive/robots/<name>/<name>.toml`` (read by :mod:`derive.model_file`, built
by :mod:`derive.spatial.spatial`). This module sits on top of both: nothing in
``derive`` below it imports it.
"""

from __future__ import annotations

import re
from pathlib import Path

from .core.model_base import MODEL_NAMES, SPATIAL_NAMES, FlexibleJointModel
from .planar.planar import make_link1, make_link1_complete, make_planar
from .core.rotors import Rotors

__all__ = ["ROBOTS", "build", "PLANAR2_COMPLETE_ROTORS"]

#: Rotors of ``planar2_complete``: gear ratio 10 (with planar2's J_m = 2 kg m^2: I_a = 0.02 kg m^2,
#: S_12 = 0.2 kg m^2, next to link inertias ~1 kg m^2), massless, no transverse inertia (planar motion).
PLANAR2_COMPLETE_ROTORS = Rotors(gear_ratio=(10.0, 10.0), mass=(0.0, 0.0), transverse_inertia=(0.0, 0.0))

#: Built-in drive models whose model files (``[spring]``, ``[friction]``) ship in ``derive/robots``.
FILE_SPRING_NAMES = ("arm1_hd", "panda_hd")

#: Where the built-in spatial arms' model files and URDFs are.
ROBOTS = Path(__file__).resolve().parent / "robots"


def build(name: str) -> FlexibleJointModel:
    """Build a registered model by name.

    Raises
    ------
    ValueError
        If ``name`` is not registered; the message lists the available models.
    """
    if name == "link1":
        return make_link1()
    match = re.fullmatch(r"planar([1-7])", name or "")
    if match:
        return make_planar(int(match.group(1)))
    if name == "link1_hd":
        from .core.spring import make_link1_hd
        return make_link1_hd()
    if name == "link1_complete":
        return make_link1_complete()
    if name == "planar2_complete":
        return make_planar(2, name="planar2_complete", rotors=PLANAR2_COMPLETE_ROTORS, reduced_model="planar2",
                           description="planar2 with its rotors (complete elastic model): rotor 2 rides on link 1, "
                                       "axes parallel, constant coupling S_12 = Jm2 / N2.")
    if name in SPATIAL_NAMES or name in FILE_SPRING_NAMES or name == "panda_complete":
        # Imported here: model files need a TOML parser (tomli before Python 3.11), the formula models do not.
        from .model_file import load_model_file
        return load_model_file(ROBOTS / name / f"{name}.toml", builtin=True).build()
    raise ValueError(f"unknown model {name!r}; available models: {', '.join(MODEL_NAMES)}")
