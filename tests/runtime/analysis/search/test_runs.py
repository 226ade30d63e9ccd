"""The loops of the gain search (fjm_runtime.analysis.search.runs): substeps of a cluster batch and the parameter
file's nominal in the law and the draws."""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.analysis.search.draws import default_spread, draw_params, load_params_file
from fjm_runtime.sim.interface import CommandInterface
from fjm_runtime.sim.sensor import SensorModel


@pytest.mark.slow  # builds the batch step (C) on a cold cache
def test_a_cluster_batch_uses_the_substeps_of_the_whole_batch():
    """Rows sorted soft to stiff: the first chunk alone would need fewer substeps; the cluster's runs must
    still equal the local batch bit for bit (substeps decided once, on the client, for every row)."""
    from dataclasses import replace
    from dask.distributed import Client, LocalCluster
    from fjm_runtime.analysis.search.runs import DesignLoops
    m = fjm_runtime.load("planar2")
    wide = default_spread(m, {"K1": 1500.0, "K2": 1500.0})
    wide = replace(wide, relative={**wide.relative, "K1": 0.6, "K2": 0.6})
    P = draw_params(m, 20, 5, wide)
    P = P[np.argsort(P[:, m.param_names.index("K1")] + P[:, m.param_names.index("K2")])]
    g = {"lam": 20.0, "k_lin": [100.0, 100.0], "k_s": [4e4, 2e4], "delta": [200.0, 100.0]}
    args = ("ismc", "torque", 500.0, 1, SensorModel.panda_white(seed=5), None, None, True, False)
    # an ideal actuator: with the 2 kHz current loop one of these stiff rows diverges under the high gains
    local = DesignLoops(m, *args, nominal=wide.nominal, interface=CommandInterface.ideal())
    assert local.substeps(P[:8]) < local.substeps(P)                   # the first chunk alone would differ
    a = local.run([g], P, 0.3, 5)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        b = DesignLoops(m, *args, nominal=wide.nominal, client=client, interface=local.interface).run([g], P, 0.3, 5)
    assert b.info["chunks"] >= 2 and not a.diverged.any()
    for k, v in a.joint_metrics.items():
        np.testing.assert_array_equal(b.joint_metrics[k], v, err_msg=k)


def test_the_params_file_nominal_reaches_the_law_and_the_draws_centre(tmp_path):
    """The controller runs on the file's nominal values (not the model's defaults); the draws centre on them."""
    from fjm_runtime.analysis.search.runs import DesignLoops
    m = fjm_runtime.load("planar2")
    path = tmp_path / "p.toml"
    path.write_text("[parameters]\nK1 = 1500.0\nJm2 = 0.5\n")
    spread = load_params_file(path, m)
    loops = DesignLoops(m, "ismc", "torque", 1000.0, 1, SensorModel.ideal(), None, None, True, nominal=spread.nominal)
    ctrl = loops.controller({"lam": 20.0})
    assert ctrl.p_nom[m.param_names.index("K1")] == 1500.0 and ctrl.p_nom[m.param_names.index("Jm2")] == 0.5
    assert ctrl.p_nom[m.param_names.index("K2")] == 150.0
    P = draw_params(m, 200, 0, spread)
    k1 = P[9:, m.param_names.index("K1")]
    assert 1050.0 <= k1.min() and k1.max() <= 1950.0 and abs(np.mean(k1) / 1500.0 - 1) < 0.05
