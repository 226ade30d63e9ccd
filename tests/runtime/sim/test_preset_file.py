"""fjm_runtime.sim.preset_file: a loop model's TOML file read over its preset."""
import pytest

from fjm_runtime.sim.preset_file import read_preset_file
from fjm_runtime.sim.sensor import PRESETS, SensorModel
from fjm_runtime.validation import FjmValueError


def test_the_base_is_the_named_preset_with_the_files_stem_as_name(tmp_path):
    f = tmp_path / "my_arm.toml"
    f.write_text('preset = "franka_like"\ntau_J = 0.1\n')
    p, base, data = read_preset_file(f, "sensor file", PRESETS, "ideal", make=lambda build: build(seed=7))
    want = SensorModel.franka_like(seed=7).as_dict()
    assert p == f and data == {"tau_J": 0.1}
    assert base == {**want, "name": "my_arm"}


def test_a_file_without_preset_starts_from_the_default(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text("q = 1e-4\n")
    _, base, _ = read_preset_file(f, "sensor file", PRESETS, "ideal")
    assert base == {**SensorModel.ideal().as_dict(), "name": "s"}


@pytest.mark.parametrize("text, words", [('preset = "nope"\n', "preset = 'nope'"), ("q = [\n", "not valid TOML"),
                                         ("preset = 3\n", "preset = 3")])
def test_bad_files_are_one_line_errors_naming_the_file(tmp_path, text, words):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(FjmValueError) as e:
        read_preset_file(f, "sensor file", PRESETS, "ideal")
    msg = str(e.value)
    assert "\n" not in msg and str(f) in msg and words in msg


def test_a_missing_file_names_the_presets(tmp_path):
    with pytest.raises(FjmValueError, match="not found .*'franka_like'"):
        read_preset_file(tmp_path / "none.toml", "sensor file", PRESETS, "ideal")
