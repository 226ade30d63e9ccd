"""A linear spring's ``spring`` and ``spring_inverse`` Functions and its manifest ``springs`` entry.

Every model emits the same two spring Functions, so the runtime calls the model's law whatever it is:
a nonlinear law's come from :mod:`derive.emit.spring`; a linear spring ``psi = K phi`` is the degenerate
law, emitted here from the drive table (:func:`derive.emit.parameters.drive_table`)::

    spring(phi, p)          -> (K phi, K, 0)     each (n,)
    spring_inverse(tau_J, p) -> tau_J / K         (n,), exact

They are ``.casadi`` files only (the model's C file keeps its functions).
"""

from __future__ import annotations

from typing import Dict, List

import casadi as ca

from ..core.model_base import FlexibleJointModel
from .functions import operation_count

__all__ = ["linear_spring_functions", "linear_springs_entry", "SPRING_MEANINGS"]

#: Manifest meanings of the two Functions (shared with the nonlinear emitter's wording).
SPRING_MEANINGS = {
    "spring": "the spring law: psi(phi), psi'(phi), psi''(phi) per joint (N m, N m/rad, N m/rad^2)",
    "spring_inverse": "the implied deflection phi_J = psi^-1(tau_J) per joint (exact for a linear spring: "
                      "tau_J / K)",
}


def linear_spring_functions(m: FlexibleJointModel, drives: List[dict]) -> Dict[str, ca.Function]:
    """``{"spring", "spring_inverse"}`` SX Functions of a model whose drives all have linear springs."""
    n = m.n
    names = list(m.param_names)
    p, phi, tau = ca.SX.sym("p", len(names)), ca.SX.sym("phi", n), ca.SX.sym("tau_J", n)
    K = ca.vertcat(*[p[names.index(d["spring"]["parameters"][0])] for d in drives])
    return {"spring": ca.Function(f"{m.name}_spring", [phi, p], [K * phi, K, ca.SX.zeros(n)], ["phi", "p"],
                                  ["psi", "dpsi", "ddpsi"]),
            "spring_inverse": ca.Function(f"{m.name}_spring_inverse", [tau, p], [tau / K], ["tau_J", "p"],
                                          ["phi_J"])}


def linear_springs_entry(drives: List[dict], springs: Dict[str, ca.Function], sizes: Dict[str, int]) -> dict:
    """The manifest's ``springs`` of a linear model: per joint its law and parameter, the inverse's
    method, and per Function of ``springs`` its ``casadi_file``, ``meaning``, ``inputs``, ``operations`` and
    ``casadi_bytes`` (``sizes``: the written files' byte sizes by name)."""
    files = {name: {"casadi_file": f"{name}.casadi", "meaning": SPRING_MEANINGS[name], "inputs": [arg, "p"],
                    "operations": operation_count(springs[name]), "casadi_bytes": sizes[name]}
             for name, arg in (("spring", "phi"), ("spring_inverse", "tau_J"))}
    return {"joints": [{"joint": d["joint"], "law": "linear", "psi": f"{d['spring']['parameters'][0]} phi",
                        "phi": "q_m - q", "parameters": list(d["spring"]["parameters"])} for d in drives],
            "inverse": {"method": "exact"},
            "functions": files}
