"""fjm runtime: load generated flexible-joint models and simulate their controllers.

>>> import numpy as np, fjm_runtime
>>> m = fjm_runtime.load("link1")
>>> m.alpha(np.zeros(4), m.default_params).shape
(1,)

The runtime needs only casadi and numpy; it never imports SymPy.
"""

from .model import Model, available_models, load
from .validation import FjmValueError

__all__ = ["Model", "load", "available_models", "FjmValueError"]
__version__ = "0.1.0"
