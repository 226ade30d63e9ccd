"""fjm runtime: load generated flexible-joint models and simulate their controllers.

>>> import numpy as np, fjm_runtime
>>> m = fjm_runtime.load("link1")
>>> m.alpha(np.zeros(4), m.default_params).shape
(1,)

The runtime needs only casadi and numpy; it never imports SymPy. ``make_controller``,
``make_reference``, ``simulate`` and ``simulate_batch`` are imported on first use.
"""

from .model import Model, available_models, load
from .validation import FjmValueError

__all__ = ["Model", "load", "available_models", "FjmValueError", "make_controller", "make_reference",
           "simulate", "simulate_batch"]
__version__ = "0.1.0"

#: Top-level names loaded on first access: name -> module that defines it.
_LAZY = {"make_controller": "fjm_runtime.control.factory", "make_reference": "fjm_runtime.control.references",
         "simulate": "fjm_runtime.sim.simulate", "simulate_batch": "fjm_runtime.batch.runner"}


def __getattr__(name):
    if name in _LAZY:
        import importlib
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'fjm_runtime' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
