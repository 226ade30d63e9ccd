"""Load generated models: ``load(name) -> Model`` (the contract of docs/design.md, "Runtime contract").

The runtime only deserializes the CasADi Functions written by ``make derive``;
it never imports SymPy.
"""

from __future__ import annotations

import json
import os
from functools import lru_cache
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import casadi as ca
import numpy as np

from .validation import FjmValueError, as_vector, params_vector

#: Quantities every generated model provides (file ``<name>.casadi``).
QUANTITIES = ("f", "g", "ad", "T", "alpha", "beta", "energy", "inertia")


def generated_root() -> Path:
    """Directory holding ``<model>/manifest.json``.

    Order: ``$FJM_GENERATED``; the copy shipped inside the installed package
    (``fjm_runtime/generated``); the repository's ``generated/``.
    """
    env = os.environ.get("FJM_GENERATED")
    if env:
        return Path(env)
    here = Path(__file__).resolve().parent
    for cand in (here / "generated", here.parent / "generated"):
        if cand.is_dir():
            return cand
    return here.parent / "generated"


def available_models(root: Optional[Path] = None) -> List[str]:
    """Names of the models found under the generated root, sorted."""
    root = root or generated_root()
    if not root.is_dir():
        return []
    return sorted(d.name for d in root.iterdir() if (d / "manifest.json").is_file())


def _read_function(path: Path) -> ca.Function:
    lines = [ln for ln in path.read_text().splitlines() if ln and not ln.startswith("#")]
    if len(lines) != 1:
        raise FjmValueError(f"{path}: corrupt generated file (expected one serialized Function line)")
    return ca.Function.deserialize(lines[0])


class Model:
    """A generated flexible-joint model.

    Attributes
    ----------
    name : str
    n : int
        Number of links.
    nx : int
        State dimension, ``4 n``; ``x = [q; dq; q_m; dq_m]``.
    param_names : tuple of str
    default_params : dict str -> float
    manifest : dict
        The model's ``manifest.json``.

    Every method takes ``x`` (length 4n) and ``p`` (array in ``param_names``
    order, dict with defaults for missing keys, or None for all defaults) and
    returns NumPy arrays.
    """

    def __init__(self, directory: Path):
        self.directory = Path(directory)
        self.manifest = json.loads((self.directory / "manifest.json").read_text())
        self.name: str = self.manifest["model"]
        self.n: int = int(self.manifest["n"])
        self.nx: int = int(self.manifest["nx"])
        self.param_names: Tuple[str, ...] = tuple(p["name"] for p in self.manifest["parameters"])
        self.default_params: Dict[str, float] = {
            p["name"]: float(p["default"]) for p in self.manifest["parameters"]}
        self.functions: Dict[str, ca.Function] = {
            q: _read_function(self.directory / f"{q}.casadi") for q in QUANTITIES}

    def __repr__(self) -> str:
        return f"<fjm Model {self.name}: n={self.n}, nx={self.nx}, params={len(self.param_names)}>"

    # -- argument handling -------------------------------------------------
    def params_array(self, p=None, arg: str = "p") -> np.ndarray:
        """``p`` (array, dict or None) as a validated vector of shape ``(len(param_names),)``."""
        return params_vector(self.param_names, self.default_params, p, arg)

    def state_array(self, x, arg: str = "x") -> np.ndarray:
        """``x`` as a validated vector of shape ``(nx,)``."""
        return as_vector(arg, x, self.nx)

    def _eval(self, quantity: str, x, p) -> np.ndarray:
        xv = self.state_array(x)
        pv = self.params_array(p)
        return self.functions[quantity](xv, pv).full()

    # -- the contract ------------------------------------------------------
    def f(self, x, p=None) -> np.ndarray:
        """Drift ``f(x)``, shape (4n,)."""
        return self._eval("f", x, p).ravel()

    def g(self, x, p=None) -> np.ndarray:
        """Input matrix ``g(x)``, shape (4n, n)."""
        return self._eval("g", x, p)

    def ad(self, x, p=None) -> np.ndarray:
        """``[g, ad_f g, ad_f^2 g, ad_f^3 g]`` with ``ad_f v = (df/dx) v - (dv/dx) f``, shape (4n, 4n)."""
        return self._eval("ad", x, p)

    def T(self, x, p=None) -> np.ndarray:
        """Linearizing coordinates ``[y1; y2; y3; y4]``, shape (4n,)."""
        return self._eval("T", x, p).ravel()

    def alpha(self, x, p=None) -> np.ndarray:
        """``alpha(x)``, shape (n,); ``u = alpha + beta nu`` gives ``y4' = nu``."""
        return self._eval("alpha", x, p).ravel()

    def beta(self, x, p=None) -> np.ndarray:
        """``beta(x) = J_m K^-1 D(q)``, shape (n, n)."""
        return self._eval("beta", x, p)

    def energy(self, x, p=None) -> float:
        """Total mechanical energy (links, motors, springs, gravity), scalar."""
        return float(self._eval("energy", x, p)[0, 0])

    def inertia(self, x, p=None) -> np.ndarray:
        """Link inertia matrix ``D(q)``, shape (n, n)."""
        return self._eval("inertia", x, p)

    def xdot(self, x, u, p=None) -> np.ndarray:
        """Open-loop dynamics ``f(x) + g(x) u``, shape (4n,)."""
        uv = as_vector("u", u, self.n)
        return self.f(x, p) + self.g(x, p) @ uv


@lru_cache(maxsize=None)
def _load_cached(directory: str) -> Model:
    return Model(Path(directory))


def load(name: str) -> Model:
    """Load a generated model by name (``"link1"``, ``"planar1"`` .. ``"planar7"``).

    Raises
    ------
    ValueError
        If no generated model of that name exists; the message lists the
        available ones.
    """
    root = generated_root()
    models = available_models(root)
    if not isinstance(name, str) or name not in models:
        raise FjmValueError(
            f"unknown model {name!r}; available models: {', '.join(models) or '(none: run make derive)'}")
    return _load_cached(str(root / name))
