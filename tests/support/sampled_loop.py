"""Controllers shared by the sampled-loop tests (tests/runtime/sim, tests/runtime/batch)."""
from fjm_runtime.control.factory import make_controller


def ismc_controller(m, **kw):
    """The integral SMC on ``m`` at the nominal parameters, lam 8, k_s 100, delta 2 unless given in ``kw``."""
    kw.setdefault("lam", 8.0)
    kw.setdefault("k_s", 100.0)
    kw.setdefault("delta", 2.0)
    return make_controller("ismc", m, {}, **kw)


def planar2_torque_ismc():
    """``(model, controller)``: planar2 under the integral SMC on torque sensing (lam 20, k_s 200, delta 5), the
    case of the outlined batch step's tests (tests/runtime/batch: the sampled step, the SIMD source)."""
    import fjm_runtime
    m = fjm_runtime.load("planar2")
    return m, make_controller("ismc", m, nominal_params={}, lam=20, k_s=200, delta=5, sensing="torque")
