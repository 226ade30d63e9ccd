"""The controller of the sampled-loop tests (tests/runtime/sim: the loop in simulate, the substeps)."""
from fjm_runtime.control.factory import make_controller


def ismc_controller(m, **kw):
    """The integral SMC on ``m`` at the nominal parameters, lam 8, k_s 100, delta 2 unless given in ``kw``."""
    kw.setdefault("lam", 8.0)
    kw.setdefault("k_s", 100.0)
    kw.setdefault("delta", 2.0)
    return make_controller("ismc", m, {}, **kw)
