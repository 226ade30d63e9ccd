"""The bad-input catalogue of model files: every numeric value has a physical range.

Each case is a model file with one value no arm has (``F_c = 1e300`` and ``K_3 = 1e300`` ended in
"LinAlgError: SVD did not converge"; ``K = 1e300``, ``range = 1e6`` rad and ``F_s < F_c`` were accepted).
``fjm derive --model-file FILE --out DIR`` must refuse it before deriving: exit status 2, one line on
stderr ``FILE:LINE: key: value ... expected RANGE``, no traceback, nothing written. The command-line
cases are in tests/runtime/cli/test_bad_input_catalogue.py.
"""
import math
from pathlib import Path

import pytest

from derive.__main__ import main as derive_main
from derive.model_file.drive_tables import MAX_DEFLECTION
from derive.model_file.schema import PHYSICAL_MAX, SMALLEST

ROOT = Path(__file__).resolve().parents[2]
ONE = '[model]\nname = "arm"\nlinks = 1\n'                       # lines 1-3
THREE = '[model]\nname = "arm"\nlinks = 3\n'
URDF = (f'[model]\nname = "uarm"\nurdf = "{ROOT / "derive/robots/elbow3/elbow3.urdf"}"\nbase = "base_link"\n'
        'tip = "tool0"\n')                                       # lines 1-5
SEGMENTS = 'law = "three_segment"\nrange = 0.01\nK_1 = 1.3e4\nK_2 = 1.7e4\nK_3 = 2.0e4\nT_1 = 14.0\nT_2 = 48.0\n'

#: (id, file text, key, line, value as the message shows it, text of the expected range)
CASES = [
    ("K-1e300", THREE + "[parameters]\nK1 = 1e300\n", "parameters.K1", 5, "1e+300", "1e+09 N m/rad"),
    ("K-1e10", THREE + "[parameters]\nK2 = 1e10\n", "parameters.K2", 5, "10000000000.0", "1e+09 N m/rad"),
    ("mass", THREE + "[parameters]\nm1 = 1e6\n", "parameters.m1", 5, "1000000.0", "10000 kg"),
    ("length", THREE + "[parameters]\nl2 = 1e4\n", "parameters.l2", 5, "10000.0", "100 m"),
    ("inertia-tiny", THREE + "[parameters]\nI1 = 1e-20\n", "parameters.I1", 5, "1e-20", "1e-12 <="),
    ("motor-inertia", THREE + "[parameters.Jm2]\ndefault = 1e300\n", "parameters.Jm2.default", 5, "1e+300",
     "kg m^2"),
    ("damping", THREE + "[parameters]\nBm1 = 1e9\n", "parameters.Bm1", 5, "1000000000.0", "1e+06 N m s/rad"),
    ("gravity", THREE + "[parameters]\ng0 = 1e3\n", "parameters.g0", 5, "1000.0", "100 m/s^2"),
    ("com-tiny", THREE + "[parameters]\nr1 = 1e-15\n", "parameters.r1", 5, "1e-15", "1e-12 <="),
    ("F_c-1e300", ONE + "[friction]\nF_c = 1e300\n", "friction.F_c", 5, "1e+300", "1e+06 N m"),
    ("F_s-below-F_c", ONE + "[friction]\nF_c = 1.0\nF_s = 0.5\n", "friction.F_s", 6, "0.5", "F_s >= F_c"),
    ("v_c-tiny", ONE + "[friction]\nF_c = 1.0\nv_c = 1e-300\n", "friction.v_c", 6, "1e-300", "1e-12 <="),
    ("v_s-huge", ONE + "[friction]\nF_c = 1.0\nv_s = 1e9\n", "friction.v_s", 6, "1000000000.0", "rad/s"),
    ("K_3-1e300", ONE + "[spring]\n" + SEGMENTS.replace("K_3 = 2.0e4", "K_3 = 1e300"), "spring.K_3", 9,
     "1e+300", "1e+09 N m/rad"),
    ("range-1e6", ONE + "[spring]\n" + SEGMENTS.replace("range = 0.01", "range = 1e6"), "spring.range", 6,
     "1000000.0", "deflection range <= 3.14159 rad"),
    ("range-one-turn", ONE + "[spring]\n" + SEGMENTS.replace("range = 0.01", "range = 6.3"), "spring.range", 6,
     "6.3", "3.14159 rad (pi"),
    ("k3-cubic", ONE + '[spring]\nlaw = "cubic"\nrange = 0.1\nk1 = 100.0\nk3 = 1e300\n', "spring.k3", 8, "1e+300",
     "1e+12 N m/rad^3"),
    ("T_2-huge", ONE + "[spring]\n" + SEGMENTS.replace("T_2 = 48.0", "T_2 = 1e9"), "spring.T_2", 11,
     "1000000000.0", "1e+06 N m"),
    ("w_blend-huge", ONE + "[spring]\n" + SEGMENTS + "w_blend = 1e300\n", "spring.w_blend", 12, "1e+300", "rad"),
    ("urdf-K", URDF + "[joints.default]\nK = 1e300\nJm = 0.04\n", "joints.default.K", 7, "1e+300",
     "1e+09 N m/rad"),
    ("urdf-Jm", URDF + "[joints.default]\nK = 300.0\nJm = 1e-30\n", "joints.default.Jm", 8, "1e-30", "1e-12 <="),
    ("urdf-Bm", URDF + "[joints.default]\nK = 300.0\nJm = 0.04\nBm = 1e300\n", "joints.default.Bm", 9, "1e+300",
     "N m s/rad"),
    ("urdf-g0", URDF + "[joints.default]\nK = 300.0\nJm = 0.04\n[parameters]\ng0 = 1e300\n", "parameters.g0", 10,
     "1e+300", "m/s^2"),
    ("urdf-F_c", URDF + "[joints.default]\nJm = 0.04\nK = 300.0\n[friction.default]\nF_c = 1e300\n",
     "friction.default.F_c", 10, "1e+300", "N m"),
    ("urdf-F_s", URDF + "[joints.default]\nJm = 0.04\nK = 300.0\n[friction.default]\nF_c = 2.0\nF_s = 1.0\n",
     "friction.default.F_s", 11, "1.0", "F_s >= F_c"),
    ("urdf-K_3", URDF + "[joints.default]\nJm = 0.04\n[spring.default]\n" + SEGMENTS.replace("K_3 = 2.0e4",
                                                                                              "K_3 = 1e300"),
     "spring.default.K_3", 13, "1e+300", "N m/rad"),
    ("payload-mass", URDF + "[joints.default]\nK = 300.0\nJm = 0.04\n[payload]\nmass = 1e6\ncom = [0, 0, 0]\n",
     "payload.mass", 10, "1000000.0", "10000 kg"),
    ("payload-com", URDF + "[joints.default]\nK = 300.0\nJm = 0.04\n[payload]\nmass = 1.0\ncom = [0, 0, 1e9]\n",
     "payload.com", 11, "1000000000.0", "100 m"),
    ("effort", URDF + "[joints.default]\nK = 300.0\nJm = 0.04\n[limits]\neffort = 1e300\n", "limits.effort", 10,
     "1e+300", "N m"),
    ("velocity", URDF + "[joints.default]\nK = 300.0\nJm = 0.04\n[limits]\nvelocity = 1e9\n", "limits.velocity",
     10, "1000000000.0", "rad/s"),
    ("torque-rate", URDF + "[joints.default]\nK = 300.0\nJm = 0.04\n[limits]\ntorque_rate = 1e300\n",
     "limits.torque_rate", 10, "1e+300", "N m/s"),
    ("task-amplitude", URDF + '[joints.default]\nK = 300.0\nJm = 0.04\n[task]\nkind = "sines"\namplitude = 1e3\n'
     "omega = 1.0\n", "task.amplitude", 11, "1000.0", "rad"),
    ("task-omega", URDF + '[joints.default]\nK = 300.0\nJm = 0.04\n[task]\nkind = "sines"\namplitude = 0.1\n'
     "omega = 1e9\n", "task.omega", 12, "1000000000.0", "rad/s"),
]


@pytest.mark.parametrize("text, key, line, value, expected", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_an_unphysical_value_is_one_line_at_its_key(text, key, line, value, expected, tmp_path, capsys):
    path = tmp_path / "arm.toml"
    path.write_text(text)
    out = tmp_path / "out"
    assert derive_main(["--model-file", str(path), "--out", str(out)]) == 2
    got = capsys.readouterr()
    lines = [ln for ln in got.err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in got.err, got.err
    msg = lines[0]
    assert f"{path}:{line}: {key}: " in msg, msg
    assert value in msg and expected in msg and "expected" in msg, (value, expected, msg)
    assert not out.exists() or not any(out.iterdir())


def test_the_catalogue_with_the_command_line_holds_at_least_sixty_cases():
    from tests.runtime.cli.test_bad_input_catalogue import CASES as CLI_CASES
    assert len(CASES) + len(CLI_CASES) >= 60 and len({c[0] for c in CASES}) == len(CASES)


def test_every_unit_of_a_model_file_has_a_range_that_holds_its_builtins():
    """Each unit's bound is beyond every built-in model's value in it (the built-ins derive unchanged: derive
    --check) and within double precision's room for the derivation's products."""
    from derive.model_file.chain_form import SI_UNITS
    from derive.model_file.robot_facts import LIMIT_KEYS, TASK_KINDS
    from derive.core.spring_laws import SPRING_PARAMETERS
    units = set(SI_UNITS.values()) | {u for u, _, _ in LIMIT_KEYS.values()} | {u for _, u in SPRING_PARAMETERS.values()}
    units |= {k[0] for kind in TASK_KINDS.values() for k in kind.values()}
    assert units <= set(PHYSICAL_MAX), units - set(PHYSICAL_MAX)
    for unit, (top, _) in PHYSICAL_MAX.items():
        assert SMALLEST < top <= 1e12 and math.isfinite(top * top * top), unit
    assert MAX_DEFLECTION == pytest.approx(math.pi)
