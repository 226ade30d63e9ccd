"""The spring laws (derive/core/spring_laws.py) and the drive tables of a model file.

The three-segment datasheet curve: equal to the piecewise-linear datasheet curve outside the blend
windows (written out here), C2 across every window edge (psi'' continuous, psi''' jumps only at
the edges), odd, stiffness between K_1 and K_3, potential whose derivative is psi. Every law's check:
one line naming model, joint, value and unit (and the deflection where psi' fails). The ``[spring]``
and ``[friction]`` tables of a one-link model file: parsed into a model with the law, errors on the
offending key's line (a negative friction, psi' <= 0 on the range, a second link, K1 beside a law).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from derive.core.spring_laws import CubicSpring, LinearSpring, SpringError, ThreeSegmentSpring
from derive.model_file import parse_model_text
from derive.model_file.schema import ModelFileError
from support.model_files import THREE_SEGMENT_SPRING

NAMES = ("K_1", "K_2", "K_3", "T_1", "T_2", "w_blend")
VALUES = dict(zip(NAMES, (1.3e4, 1.7e4, 2.0e4, 14.0, 48.0, 2e-4)))
SYMS = [sp.Symbol(n, real=True) for n in NAMES]


def _three(rng=0.01):
    return ThreeSegmentSpring(1, *SYMS, rng)


def _numeric(law, k):
    a = sp.Symbol("a", real=True)
    e = law.derivative(k, a).subs({s: VALUES[str(s)] for s in SYMS})
    return sp.lambdify(a, e, "math")


def _datasheet(phi):
    K1, K2, K3, T1, T2, _ = (VALUES[n] for n in NAMES)
    b1, a = T1 / K1, abs(phi)
    b2 = b1 + (T2 - T1) / K2
    g = K1 * a if a <= b1 else T1 + K2 * (a - b1) if a <= b2 else T2 + K3 * (a - b2)
    return np.sign(phi) * g


def test_three_segment_is_the_datasheet_curve_outside_the_blends():
    psi, w = _numeric(_three(), 0), VALUES["w_blend"]
    b1 = VALUES["T_1"] / VALUES["K_1"]
    b2 = b1 + (VALUES["T_2"] - VALUES["T_1"]) / VALUES["K_2"]
    for phi in np.linspace(-0.01, 0.01, 2001):
        if min(abs(abs(phi) - b1), abs(abs(phi) - b2)) >= w / 2:
            assert psi(phi) == pytest.approx(_datasheet(phi), rel=1e-13, abs=1e-12), phi
        assert psi(-phi) == pytest.approx(-psi(phi), rel=1e-14, abs=1e-300)
    # inside a window the blend rounds the corner off
    assert abs(psi(b1) - _datasheet(b1)) > 1e-3


def test_three_segment_is_c2_with_stiffness_between_the_segments():
    """psi and its first three derivatives continuous across every window edge; psi' monotone, K_1 to K_3."""
    w = VALUES["w_blend"]
    b1 = VALUES["T_1"] / VALUES["K_1"]
    b2 = b1 + (VALUES["T_2"] - VALUES["T_1"]) / VALUES["K_2"]
    fns = [_numeric(_three(), k) for k in range(4)]
    eps = 1e-12
    for centre in (b1, b2):
        for k, fn in enumerate(fns):
            scale = max(abs(fn(v)) for v in np.linspace(centre - w, centre + w, 401))
            for edge in (centre - w / 2, centre + w / 2):
                left, right = fn(edge - eps), fn(edge + eps)
                assert abs(left - right) <= 1e-6 * scale, (k, edge, left, right)
    ks = [fns[1](phi) for phi in np.linspace(0, 0.01, 1001)]
    assert np.all(np.diff(ks) >= -1e-9) and min(ks) == VALUES["K_1"] and max(ks) == pytest.approx(VALUES["K_3"])


def test_potential_is_the_integral_of_the_law():
    a = sp.Symbol("a", real=True)
    law = _three()
    V = sp.lambdify(a, law.potential(a).subs({s: VALUES[str(s)] for s in SYMS}), "math")
    psi = _numeric(law, 0)
    assert V(0.0) == 0.0
    h = 1e-8
    for phi in (3e-4, 1.0e-3, 1.1e-3, 3.0e-3, 7e-3, -2e-3):
        assert (V(phi + h) - V(phi - h)) / (2 * h) == pytest.approx(psi(phi), rel=1e-6)


@pytest.mark.parametrize("change, message", [
    ({"K_1": -5.0}, "spring stiffness psi'(phi) = -5 N m/rad <= 0 at deflection phi = 0 rad"),
    ({"K_2": 0.0}, "psi'(phi) = K_2 = 0 N m/rad <= 0 beyond deflection phi = 0.00107692 rad"),
    ({"K_2": 1.0e4}, "expected K_1 <= K_2 <= K_3"),
    ({"T_2": 14.0}, "expected 0 < T_1 < T_2"),
    ({"w_blend": 3e-3}, "blend width w_blend = 0.003 rad; expected 0 < w <= 0.002 rad"),
    ({"K_3": float("inf")}, "spring coefficient K_3 = inf N m/rad; expected a finite number"),
])
def test_three_segment_checks_are_one_line(change, message):
    with pytest.raises(SpringError) as info:
        _three().check("drive", {**VALUES, **change})
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith("drive joint 1: ") and message in msg, msg


def test_linear_and_cubic_checks_and_bounds():
    K, k1, k3 = sp.symbols("K k1 k3", real=True)
    LinearSpring(1, K, 1.0).check("m", {"K": 100.0})
    with pytest.raises(SpringError, match="psi'\\(phi\\) = -1 N m/rad <= 0 at deflection phi = 0 rad"):
        LinearSpring(1, K, 1.0).check("m", {"K": -1.0})
    cubic = CubicSpring(1, k1, k3, 0.25)
    assert cubic.stiffness_bounds({"k1": 75.0, "k3": 2500.0}) == (75.0, 75.0 + 3 * 2500.0 * 0.0625)
    with pytest.raises(SpringError, match="at deflection phi = 0.25 rad"):
        cubic.check("m", {"k1": 75.0, "k3": -500.0})
    lo, hi = _three().stiffness_bounds(VALUES)
    assert lo == VALUES["K_1"] and hi == pytest.approx(VALUES["K_3"])


# -- model files -------------------------------------------------------------------------------------------

DRIVE = f"""\
[model]
name = "drive"
links = 1

[spring]
{THREE_SEGMENT_SPRING}
[friction]
F_c = 0.5
"""


def test_a_drive_model_file_builds_the_law_and_friction():
    model = parse_model_text(DRIVE, "drive.toml").build()
    assert [p.name for p in model.params] == ["m1", "l1", "r1", "I1", *NAMES, "Jm1", "Bm1", "g0",
                                              "F_c", "F_s", "v_s", "v_c"]
    d = {p.name: p.default for p in model.params}
    assert (d["F_c"], d["F_s"], d["v_s"], d["v_c"]) == (0.5, 0.5, 0.1, 0.01)  # F_s defaults to F_c
    assert model.springs[0].kind == "three_segment" and model.frictions is not None
    assert str(model.K[0]) == "K_1"
    cubic = DRIVE.replace('law = "three_segment"', 'law = "cubic"').split("K_1")[0] + "k1 = 100.0\nk3 = 1e4\n"
    m2 = parse_model_text(cubic, "cubic.toml").build()
    assert m2.springs[0].kind == "cubic" and m2.frictions is None
    linear = "[model]\nname = \"lin\"\nlinks = 1\n[friction]\nF_c = 0.2\nF_s = 0.3\n"
    m3 = parse_model_text(linear, "lin.toml").build()  # friction on today's linear spring K1
    assert m3.springs[0].kind == "linear" and str(m3.K[0]) == "K1" and "K1" in [p.name for p in m3.params]


@pytest.mark.parametrize("edit, line, message", [
    (("F_c = 0.5", "F_c = -0.5"), 16, "friction.F_c: -0.5 N m is not physical: motor Coulomb friction (link side) "
                                      "must be >= 0"),
    (("law = \"three_segment\"", "law = \"cubic\"\nk1 = 100.0\nk3 = -1e6"), 10,
     "spring.K_1: unknown key for law = \"cubic\""),
    (("links = 1", "links = 2"), 5, "a flat [spring] table is for one link; this file has links = 2"),
    (("K_2 = 1.7e4", "K_2 = 1.0e4"), 6, "expected K_1 <= K_2 <= K_3"),
    (("range = 0.01\n", ""), 5, "spring.range: missing required key"),
    (("law = \"three_segment\"", "law = \"quintic\""), 6, "expected one of 'linear', 'cubic', 'three_segment'"),
])
def test_drive_table_errors_name_file_line_and_key(edit, line, message):
    with pytest.raises(ModelFileError) as info:
        parse_model_text(DRIVE.replace(*edit), "drive.toml")
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(f"drive.toml:{line}: ") and message in msg, msg


def test_cubic_with_negative_stiffness_in_range_is_refused_at_the_law_line():
    text = ("[model]\nname = \"c\"\nlinks = 1\n[spring]\nlaw = \"cubic\"\nrange = 0.25\nk1 = 75.0\n"
            "k3 = -500.0\n")
    with pytest.raises(ModelFileError) as info:
        parse_model_text(text, "c.toml")
    msg = str(info.value)
    assert msg.startswith("c.toml:5: spring.law: ") and "psi'(phi) = -18.75 N m/rad <= 0 at deflection " \
        "phi = 0.25 rad" in msg, msg


def test_k1_beside_a_nonlinear_law_is_refused():
    text = DRIVE.replace("[spring]", "[parameters]\nK1 = 100.0\n\n[spring]")
    with pytest.raises(ModelFileError, match=r"drive.toml:6: parameters.K1: the \[spring\] law 'three_segment' "
                                             r"replaces the linear stiffness K1"):
        parse_model_text(text, "drive.toml")


# --- the URDF form: drive tables per joint (panda_hd's file) ---------------------------------------------

PANDA_HD = Path(__file__).resolve().parents[2] / "derive" / "robots" / "panda_hd"


def _panda_hd_text() -> str:
    return (PANDA_HD / "panda_hd.toml").read_text()


def _line(text: str, needle: str) -> int:
    """1-based number of the first line that starts with ``needle``."""
    return next(i for i, line in enumerate(text.splitlines(), 1) if line.startswith(needle))


def test_urdf_drive_tables_give_every_joint_its_law_and_friction():
    spec = parse_model_text(_panda_hd_text(), "panda_hd.toml", base_dir=PANDA_HD, builtin=True)
    assert [s.kind for s in spec.springs] == ["three_segment"] * 7
    assert [s.coefficients["K_1"] for s in spec.springs] == [1.3e4] * 4 + [2.9e3] * 3  # joint table over default
    assert [s.coefficients["w_blend"] for s in spec.springs] == [2e-4] * 7  # the default's key, kept
    assert [f["F_c"] for f in spec.frictions] == [0.8] * 4 + [0.4] * 3 and spec.frictions[0]["v_c"] == 0.01
    assert spec.K == (None,) * 7  # no linear stiffness where a law stands
    names = [p.name for p in spec.build().params]
    assert names[:6] == ["K_1_1", "K_2_1", "K_3_1", "T_1_1", "T_2_1", "w_blend_1"] and "F_c_7" in names
    assert not any(n in names for n in ("K1", "K7"))


def test_urdf_joint_law_replaces_the_default_table():
    text = _panda_hd_text().replace("[spring.panda_joint2]\nK_1 = 1.3e4\nK_2 = 1.7e4\nK_3 = 2.0e4\nT_1 = 14.0\n"
                                    "T_2 = 48.0\n", "[spring.panda_joint2]\nlaw = \"cubic\"\nrange = 0.02\n"
                                                    "k1 = 1.2e4\nk3 = 1e8\n")
    spec = parse_model_text(text, "arm.toml", base_dir=PANDA_HD, builtin=True)
    assert spec.springs[1].kind == "cubic" and spec.springs[1].coefficients == {"k1": 1.2e4, "k3": 1e8}
    assert [p.name for p in spec.build().params][6:8] == ["k1_2", "k3_2"]


@pytest.mark.parametrize("edit, anchor, message", [
    (("[spring.panda_joint3]\nK_1 = 1.3e4\nK_2 = 1.7e4", "[spring.panda_joint3]\nK_1 = 1.3e4\nK_2 = 1.0e4"),
     "[spring.panda_joint3]", "spring.panda_joint3.law: joint panda_joint3: "),
    (("[friction.panda_joint2]\nF_c = 0.8", "[friction.panda_joint2]\nF_c = -0.8"), "F_c = -0.8",
     "friction.panda_joint2.F_c: -0.8 N m is not physical"),
    (("[spring.panda_joint4]", "[spring.panda_joint9]"), "[spring.panda_joint9]",
     "no revolute joint 'panda_joint9' on the chain"),
    (("[joints.panda_joint1]\nJm = 0.3", "[joints.panda_joint1]\nJm = 0.3\nK = 1e4"), "K = 1e4",
     "has a nonlinear spring law ([spring.*]), which replaces its stiffness K"),
    (("[friction.default]      # wrist motors, link side\nF_c = 0.4", "[friction.default]\nF_c = 0.4\nmu = 0.1"),
     "mu = 0.1", "friction.default.mu: unknown key"),
])
def test_urdf_drive_table_errors_are_one_line_at_the_key(edit, anchor, message):
    text = _panda_hd_text()
    assert edit[0] in text
    bad = text.replace(*edit)
    with pytest.raises(ModelFileError) as info:
        parse_model_text(bad, "arm.toml", base_dir=PANDA_HD, builtin=True)
    msg = str(info.value)
    assert "\n" not in msg and message in msg, msg
    assert msg.startswith(f"arm.toml:{_line(bad, anchor)}: "), msg
    if "K_1 <= K_2" in message or "joint panda_joint3" in message:
        assert "expected K_1 <= K_2 <= K_3" in msg
