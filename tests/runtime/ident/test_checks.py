"""The identification's plausibility warnings (fjm_runtime.ident.checks)."""
import numpy as np

import fjm_runtime
from fjm_runtime.ident.checks import gear_ratio_warnings, nominal_warnings


def test_gear_ratio_and_nominal_warnings_name_the_joint_and_the_factor():
    m = fjm_runtime.load("planar2")
    t = np.linspace(0, 10, 5000)
    q = np.column_stack([0.3 * np.sin(t), 0.2 * np.cos(t)])
    q_m = q.copy()
    q_m[:, 1] = 100.0 * q[:, 1]                        # joint 2 logged on the rotor side
    w = gear_ratio_warnings(q, q_m)
    assert len(w) == 1 and w[0].startswith("joint 2:") and "100 times" in w[0]
    assert gear_ratio_warnings(q, q + 1e-3 * q) == []
    nominal = m.default_params["K1"]
    w = nominal_warnings({"K1": nominal / 160.0, "K2": 1.3 * m.default_params["K2"], "Bm1": 0.2}, m)
    assert len(w) == 1 and w[0].startswith("K1 = ") and "1/160 of" in w[0]
