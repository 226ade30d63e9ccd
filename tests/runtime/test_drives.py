"""Model.drives and Model.parameter_info, read from the manifest: checked against the model's own
equations (the motor row of f and g), the spring function, and the domain checks of params_array."""

import json
import shutil

import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.drives import drive_indices, joint_coefficients, role_names
from fjm_runtime.model import Model
from fjm_runtime.validation import FjmValueError

LINEAR = ("link1", "planar3", "panda", "baxter", "elbow3")


@pytest.mark.parametrize("name", LINEAR)
def test_motor_row_of_the_equations_uses_the_drive_indices(name):
    """J_m ddq_m = u - K (q_m - q) - B_m dq_m and g's motor block diag(1/J_m), with K, J_m, B_m at the
    indices Model.drives gives (parameters perturbed so that a wrong index shows)."""
    m = fjm_runtime.load(name)
    n = m.n
    rng = np.random.default_rng(3)
    p = m.params_array() * rng.uniform(0.8, 1.2, len(m.param_names))
    iB = drive_indices(m, "damping")
    p[iB] = rng.uniform(0.1, 0.5, n)
    x = rng.uniform(-0.3, 0.3, 4 * n)
    K, Jm, B = (p[drive_indices(m, r)] for r in ("stiffness", "rotor_inertia", "damping"))
    ddqm = m.f(x, p)[3 * n:]
    np.testing.assert_allclose(Jm * ddqm, -K * (x[2 * n:3 * n] - x[:n]) - B * x[3 * n:], rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(m.g(x, p)[3 * n:], np.diag(1.0 / Jm), rtol=1e-12)
    assert [d.joint for d in m.drives] == list(range(n))
    assert all(d.spring_law == "linear" and len(d.spring) == 1 and d.friction is None for d in m.drives)


def test_nonlinear_drive_coefficients_are_the_spring_functions_inputs():
    """panda_hd: doubling joint 4's K_1, K_2, K_3, T_1, T_2 (Drive.spring_scale) doubles its psi, leaves the others."""
    m = fjm_runtime.load("panda_hd")
    p = m.params_array()
    phi = np.full(m.n, 2e-3)
    psi0 = np.asarray(m.spring_functions["spring"](phi, p)[0]).ravel()
    d = m.drives[3]
    q = p.copy()
    assert d.spring_scale == d.spring[:5]
    q[list(d.spring_scale)] *= 2.0
    psi1 = np.asarray(m.spring_functions["spring"](phi, q)[0]).ravel()
    np.testing.assert_allclose(psi1[3], 2.0 * psi0[3], rtol=1e-9)
    np.testing.assert_allclose(np.delete(psi1, 3), np.delete(psi0, 3), rtol=0, atol=0)
    assert d.spring_law == "three_segment" and d.friction_law == "coulomb_stribeck_tanh"
    assert joint_coefficients(m, 3)["K_1"] == m.param_names[d.stiffness]
    assert [m.param_names[i] for i in d.friction] == [joint_coefficients(m, 3)[c] for c in ("F_c", "F_s", "v_s", "v_c")]


def test_gear_ratio_of_a_complete_model():
    m = fjm_runtime.load("panda_complete")
    assert len(role_names(m, "gear_ratio")) == m.n
    assert all(m.parameter_info[k].role == "gear_ratio" and m.parameter_info[k].joint == i
               for i, k in enumerate(role_names(m, "gear_ratio")))
    with pytest.raises(FjmValueError, match="gear ratio"):
        drive_indices(fjm_runtime.load("panda"), "gear_ratio")


@pytest.mark.parametrize("name", ("link1", "planar2", "panda_hd", "link1_hd", "panda_complete"))
def test_params_array_checks_each_domain(name):
    """Every '>0' parameter refuses 0, every '>=0' one accepts 0 and refuses -1, 'any' takes -1; one line."""
    m = fjm_runtime.load(name)
    for k, info in m.parameter_info.items():
        if info.domain == ">0":
            with pytest.raises(FjmValueError, match=rf"p\['{k}'\] = 0.0: expected > 0") as e:
                m.params_array({k: 0.0})
            assert "\n" not in str(e.value)
        elif info.domain == ">=0":
            with pytest.raises(FjmValueError, match=rf"p\['{k}'\] = -1.0: expected >= 0"):
                m.params_array({k: -1.0})
            assert m.params_array({k: 0.0})[m.param_names.index(k)] == 0.0
        else:
            assert info.domain == "any"
            assert m.params_array({k: -1.0})[m.param_names.index(k)] == -1.0


def test_a_manifest_without_drives_loads_and_says_what_to_do(tmp_path):
    src = fjm_runtime.load("link1").directory
    dst = tmp_path / "link1"
    shutil.copytree(src, dst)
    doc = json.loads((dst / "manifest.json").read_text())
    del doc["drives"]
    (dst / "manifest.json").write_text(json.dumps(doc))
    m = Model(dst)
    assert m.params_array()[m.param_names.index("K")] == 150.0
    with pytest.raises(FjmValueError, match="re-run make derive"):
        m.drives


@pytest.mark.parametrize("name", ("link1", "panda", "panda_complete", "link1_hd", "arm1_hd", "panda_hd"))
def test_every_model_emits_its_spring_law(name):
    """spring(phi, p) -> (psi, psi', psi''): psi' and psi'' are psi's central differences, spring_inverse
    undoes psi, and a linear spring is psi = K phi with K at the drive table's index."""
    from fjm_runtime.drives import model_springs
    m = fjm_runtime.load(name)
    fns = model_springs(m)
    p = m.params_array()
    phi = np.linspace(-4e-3, 5e-3, m.n) if m.n > 1 else np.array([2e-3])
    psi, d1, d2 = (np.asarray(v, dtype=float).ravel() for v in fns["spring"](phi, p))
    h = 1e-7
    up, dn = (np.asarray(fns["spring"](phi + s * h, p)[0], dtype=float).ravel() for s in (1, -1))
    np.testing.assert_allclose(d1, (up - dn) / (2 * h), rtol=1e-6)
    h2 = 1e-9  # the three-segment blends are narrow: psi'' changes over micro-radians
    d1_up, d1_dn = (np.asarray(fns["spring"](phi + s * h2, p)[1], dtype=float).ravel() for s in (1, -1))
    np.testing.assert_allclose(d2, (d1_up - d1_dn) / (2 * h2), rtol=1e-3, atol=1e-3 * np.max(np.abs(d1)))
    np.testing.assert_allclose(np.asarray(fns["spring_inverse"](psi, p), dtype=float).ravel(), phi, rtol=1e-12,
                               atol=1e-15)
    if all(d.spring_law == "linear" for d in m.drives):
        K = p[drive_indices(m, "stiffness")]
        assert np.array_equal(psi, K * phi) and np.array_equal(d1, K) and not d2.any()
