"""The bad-input catalogue of the command line: each case is one nonsense value of one numeric flag.

Every case must be refused before any work: exit status 2, exactly one line on stderr that names the
flag and the value as typed (and the expected range), no traceback, no internal class name, nothing
on stdout and nothing written. The cases that used to allocate terabytes (``excite --duration 1e9``,
``--rate 1e12``) or run for minutes (``excite --harmonics 100000``) are here: they now return at
once, refused from their flags alone. The model-file cases are in tests/derive/test_model_file_ranges.py.
"""
import re

import pytest

from fjm_runtime.cli.main import main
from fjm_runtime.cli.ranges import DURATION, RATE, SEED, Range

#: Internal names a user must never read in an error.
INTERNAL = re.compile(r"Traceback|SensorModel|Namespace|FjmValueError|ArgumentTypeError|Error\b|\bargs\.")

#: (command line, text that must appear besides the flag and the value). The value is the argument
#: after the flag as typed; ``{out}`` is an output path in a fresh folder (it must stay empty).
CASES = [
    # excite: the allocations and the hang of the first user's report
    ("excite link1 --duration 1e9 --out {out}", "3600 s"),
    ("excite link1 --duration 10 --rate 1e12 --out {out}", "100000 Hz"),
    ("excite link1 --duration 10 --harmonics 100000 --out {out}", "1000"),
    ("excite link1 --duration 0 --out {out}", "0 < T"),
    ("excite link1 --duration -5 --out {out}", "0 < T"),
    ("excite link1 --duration nan --out {out}", "0 < T"),
    ("excite link1 --duration inf --out {out}", "3600"),
    ("excite link1 --duration 10 --rate 0 --out {out}", "1 <= rate"),
    ("excite link1 --duration 10 --harmonics 2 --out {out}", "3 <= harmonics"),
    ("excite link1 --duration 10 --harmonics 4.5 --out {out}", "integer"),
    ("excite link1 --duration 10 --base-freq 0 --out {out}", "0 < f0"),
    ("excite link1 --duration 10 --base-freq 1e9 --out {out}", "1000 Hz"),
    ("excite link1 --duration 10 --amplitude 100 --out {out}", "rad"),
    ("excite link1 --duration 10 --candidates 0 --out {out}", "1 <= candidates"),
    ("excite link1 --duration 10 --iterations -1 --out {out}", "0 <= iterations"),
    ("excite link1 --duration 10 --seed -1 --out {out}", "2^64-1"),
    ("excite link1 --duration 10 --seed 1e30 --out {out}", "2^64-1"),
    ("excite link1 --duration 10 --harmonics 500 --rate 100 --out {out}", "Nyquist"),
    ("excite panda --duration 10 --harmonics 1000 --out {out}", "Fourier terms"),
    ("excite link1 --duration 3600 --rate 100000 --out {out}", "GB"),
    # simulate
    ("simulate link1 --seed -1 --plot {out}", "0 <= seed"),
    ("simulate link1 --k-s 1e300 --plot {out}", "1e+20"),
    ("simulate link1 --k-s -1 --plot {out}", "0 <= k_s"),
    ("simulate link1 --delta 0 --plot {out}", "0 < delta"),
    ("simulate link1 --u-max 0 --plot {out}", "0 < u"),
    ("simulate link1 --u-max 1e300 --plot {out}", "N m"),
    ("simulate link1 --k-min -5 --plot {out}", "0 < K"),
    ("simulate link1 --k-max 1e300 --plot {out}", "N m/rad"),
    ("simulate link1 --q-d 1e6 --plot {out}", "rad"),
    ("simulate link1 --rise-time 0 --plot {out}", "0 < T"),
    ("simulate link1 --dt 5 --plot {out}", "0 < dt"),
    ("simulate link1 --payload -1 --plot {out}", "kg"),
    ("simulate link1 --param K=1e300 --plot {out}", "1e+12"),
    ("simulate link1 --nominal K=1e300 --plot {out}", "1e+12"),
    ("simulate link1 --duration 1e9 --plot {out}", "GB"),
    ("simulate link1 --rate 1e12 --plot {out}", "GB"),
    ("simulate link1 --lam 1e300 --plot {out}", "Nyquist"),
    ("simulate link1 --substeps 100000 --plot {out}", "10000"),
    ("simulate link1 --omega 1e9 --plot {out}", "Nyquist"),
    ("simulate link1 --max-memory 0 --plot {out}", "> 0 GB"),
    ("simulate link1 --max-memory 1e9 --plot {out}", "10000 GB"),
    ("simulate link1 --lam 1 --rate 1 --duration 3601 --plot {out}", "3600 s"),
    ("simulate link1 --duration 0.001 --rate 200000 --plot {out}", "100000 Hz"),
    ("simulate link1 --duration 0.0001 --dt 1e-7 --plot {out}", "1e-05 <= dt"),
    ("simulate link1 --delay-samples 101 --plot {out}", "100 samples"),
    ("simulate link1 --K -3 --plot {out}", "0 < K"),
    ("simulate link1 --K nan --plot {out}", "0 < K"),
    ("simulate link1 --param B_m=-1 --plot {out}", ">= 0 N m s/rad"),
    ("simulate link1 --nominal J_m=0 --plot {out}", "> 0 kg m^2"),
    ("tune link1 --nominal K=-5", "> 0 N m/rad"),
    ("simulate link1 --noise {noise} --plot {out}", "seed"),
    ("simulate link1 --noise {noise_level} --plot {out}", "1 rad"),
    ("simulate link1 --gains {gains_k_s} --plot {out}", "1e+20"),
    ("simulate link1 --gains {gains_u_max} --plot {out}", "1e+06"),
    # derive (python -m derive in a subprocess)
    ("derive --models link1 --max-cost -1 --out {out}", "a week"),
    ("derive --models link1 --max-cost 1e300 --out {out}", "604800"),
    # design
    ("design planar2 --draws 0 --out {out}", "1 <= draws"),
    ("design planar2 --draws 1e9 --out {out}", "100000"),
    ("design planar2 --rate 1e12 --out {out}", "100000 Hz"),
    ("design planar2 --delay-samples 1000 --out {out}", "100 samples"),
    ("design planar2 --delay-samples -1 --out {out}", "0 <= delay"),
    ("design planar2 --rounds 1000 --out {out}", "100"),
    ("design planar2 --screen-draws 0 --out {out}", "1 <= draws"),
    ("design planar2 --screen-duration 1e9 --out {out}", "3600 s"),
    ("design planar2 --seed -3 --out {out}", "2^64-1"),
    ("design planar2 --threads 0 --out {out}", "1 <= threads"),
    ("design planar2 --max-rms 50 --out {out}", "rad"),
    ("design planar2 --max-jitter 1e300 --out {out}", "N m"),
    ("design planar2 --duration 5000 --out {out}", "3600 s"),
    ("design planar2 --draws 100000 --duration 3000 --out {out}", "control samples"),
    ("design planar2 --params {spread_K} --out {out}", "1e+12"),
    ("design planar2 --params {spread_Bm} --out {out}", ">= 0 N m s/rad"),
    # sweep
    ("sweep link1 --samples 0 --out {out}", "1 <= samples"),
    ("sweep link1 --samples 1e12 --out {out}", "10000000"),
    ("sweep link1 --chunk 0 --out {out}", "1 <= chunk"),
    ("sweep link1 --workers 100000 --out {out}", "1024"),
    ("sweep link1 --k-rel 0 2 --out {out}", "0 < factor"),
    ("sweep link1 --lam -8 --out {out}", "0 < lam"),
    ("sweep link1 --seed -1 --out {out}", "2^64-1"),
    ("sweep link1 --duration 3000 --rate 20000 --out {out}", "GB"),
    ("sweep link1 --samples 10000000 --duration 60 --out {out}", "control samples"),
    # analyze
    ("analyze link1 --gains fjm_runtime/control/designed/panda_ismc_tau_1000hz_d1.json --rate 1e9 --out {out}",
     "100000 Hz"),
    ("analyze link1 --gains fjm_runtime/control/designed/panda_ismc_tau_1000hz_d1.json --delay-samples 1e6 "
     "--out {out}", "100 samples"),
    # identify
    ("identify link1 log.csv --window 0 --out {out}", "0 < window"),
    ("identify link1 log.csv --window 1e9 --out {out}", "60 s"),
    ("identify link1 log.csv --v-c -1 --out {out}", "0 < v"),
    ("identify link1 log.csv --v-s 1e9 --out {out}", "rad/s"),
    # export
    ("export mjcf link1 --gear-ratio 0 --out {out}", "0 < N"),
    ("export mjcf link1 --gear-ratio 1e300 --out {out}", "10000"),
    ("export mjcf link1 --timestep 1e6 --out {out}", "0.01 s"),
    ("export mjcf link1 --K 1e300 --out {out}", "1e+12"),
    ("export controller panda --gains fjm_runtime/control/designed/panda_ismc_tau_1000hz_d1.json --substeps 1e8 "
     "--out {out}", "1..1000"),
    # figures
    ("figures --samples 0 --out {out}", "1 <= samples"),
    ("figures --samples 5000 --out {out}", "1000"),
    # tune
    ("tune link1 --budget 1e7", "1000000"),
    ("tune link1 --k-range 0 100", "0 < K"),
    ("tune link1 --eta 0", "0 < eta"),
    ("tune link1 --nominal K=1e300", "1e+12"),
    ("tune link1 --sensing torque --payload -1", "kg"),
    ("tune link1 --sensing torque --gamma-range 1.3 0.7", "LO <= HI"),
    ("tune link1 --layer-rate 0", "0 < rate"),
    ("tune link1 --u-max 1e300", "N m"),
    ("tune link1 --error-box 0.05,0.5,nan,0.5", "0 <= bound"),
    ("simulate planar2 --k-scale 1e9 --plot {out}", "0 < factor <= 1000"),
    ("simulate planar2 --jm-scale 0,1 --plot {out}", "0 < factor"),
    ("excite link1 --duration 10 --posture 1e9 --out {out}", "rad"),
]


def _flag_and_value(argv):
    """The last flag given a numeric value and that value as typed (``--param K=1e300``: K and 1e300)."""
    for i in range(len(argv) - 1, 0, -1):
        if argv[i].startswith("--") and argv[i] not in ("--out", "--plot", "--gains", "--models") and i + 1 < len(argv):
            if argv[i] in ("--param", "--nominal"):
                name, _, value = argv[i + 1].partition("=")
                return argv[i], name, value
            return argv[i], argv[i], argv[i + 1]
    raise AssertionError(argv)


def _file_kind(command: str) -> str:
    """Which bad file a case passes (its value is in the file, not on the command line), or ''."""
    return next((k for k in ("spread_K", "spread_Bm", "noise_level", "gains_k_s", "gains_u_max")
                 if "{" + k + "}" in command),
                "--noise" if "{noise}" in command else "")


def _names_value(line: str, value: str) -> bool:
    """The value as typed, or as Python prints it (1e300 -> 1e+300, 4.5 -> 4.5)."""
    shown = {value}
    try:
        v = float(value)
        shown |= {f"{v:g}", repr(v)}
    except ValueError:
        pass
    return any(s in line for s in shown)


@pytest.mark.parametrize("command, must", CASES, ids=[c for c, _ in CASES])
def test_nonsense_is_one_line_naming_flag_value_and_range(command, must, tmp_path, capfd, monkeypatch):
    monkeypatch.chdir(__import__("pathlib").Path(__file__).resolve().parents[3])  # the shipped designs' paths
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    noise = tmp_path / "sensor.toml"         # a sensor file whose seed is out of range
    noise.write_text("seed = -1\n")
    files = {"noise": noise, "noise_level": tmp_path / "loud.toml"}
    files["noise_level"].write_text("q = 1e300\n")       # an angle noise of 1e300 rad
    for name, extra in (("gains_k_s", '"k_s": 1e300, "delta": 1'), ("gains_u_max", '"k_s": 10, "delta": 1, "u_max": 1e300')):
        files[name] = tmp_path / f"{name}.json"           # a gains file with a gain no loop has
        files[name].write_text('{"kind": "smc", "gains": {"lam": 8, ' + extra + "}}")
    for name, text in (("spread_K", "K1 = [1e-300, 1e300]"), ("spread_Bm", "Bm1 = [-1.0, 1.0]")):
        files[name] = tmp_path / f"{name}.toml"        # a parameter file whose [spread] range is not physical
        files[name].write_text(f"[spread]\n{text}\n")
    argv = command.format(out=out_dir / "result", **files).split()
    try:
        status = main(argv)
    except SystemExit as exc:       # fjm tune's parser leaves through sys.exit (its own one-line error)
        status = exc.code
    got = capfd.readouterr()
    lines = [ln for ln in got.err.splitlines() if ln.strip()]
    assert status == 2 and got.out == "", (status, got.out, got.err)
    assert len(lines) == 1 and lines[0].startswith(("fjm: error: ", "fjm tune: error: ", "fjm derive: error: ")), got.err
    flag, name, value = {"--noise": ("--noise", "seed", "-1"), "noise_level": ("--noise", "q", "1e300"),
                         "gains_k_s": ("--gains", "k_s", "1e300"), "gains_u_max": ("--gains", "u_max", "1e300"), "spread_K": ("--params", "K1", "1e-300"),
                         "spread_Bm": ("--params", "Bm1", "-1")}.get(_file_kind(command)) or _flag_and_value(argv)
    line = lines[0]
    assert name in line and _names_value(line, value), (name, value, line)
    assert must in line, (must, line)
    assert not INTERNAL.search(line), line
    assert list(out_dir.iterdir()) == [], list(out_dir.iterdir())


def test_the_catalogue_has_at_least_sixty_cases():
    assert len(CASES) >= 60 and len({c for c, _ in CASES}) == len(CASES)


@pytest.mark.parametrize("rng, inside, outside", [
    (DURATION, [1e-9, 1.0, 3600.0], [0.0, -1.0, 3600.0000001, float("nan"), float("inf")]),
    (RATE, [1.0, 1000.0, 100000.0], [0.999, 100000.5, float("nan")]),
    (SEED, [0, 2 ** 64 - 1], [-1, 2 ** 64, 0.5]),
])
def test_a_range_holds_its_bounds_and_nothing_beyond(rng, inside, outside):
    assert all(rng.contains(v) for v in inside)
    assert not any(rng.contains(v) for v in outside)


def test_a_range_parses_what_it_accepts_exactly():
    seed = Range(0, 2 ** 64 - 1, integer=True)
    assert seed("18446744073709551615") == 2 ** 64 - 1       # exact: not rounded through a float
    assert seed("1e3") == 1000 and isinstance(seed("1e3"), int)
    assert RATE("1e3") == 1000.0


def _error(argv, capfd):
    assert main(argv) == 2
    return capfd.readouterr().err.strip()


def test_excite_states_the_size_it_refuses(tmp_path, capfd):
    """link1, 3600 s at 100 kHz: 3.6e8 + 1 rows x (1 + 7 x 1 CSV + 20 x 1 check) columns x 8 bytes x 2 copies."""
    from fjm_runtime.cli.excite import CHECK_COLUMNS_PER_JOINT
    rows, columns = 3600 * 100_000 + 1, 1 + 7 + CHECK_COLUMNS_PER_JOINT
    err = _error(["excite", "link1", "--duration", "3600", "--rate", "100000", "--out", str(tmp_path / "x.csv")], capfd)
    assert f"{rows:.4g} rows x {columns} columns x 8 bytes x 2 = {rows * columns * 16 / 1e9:.3g} GB" in err, err


def test_excite_states_the_fourier_terms_it_refuses(tmp_path, capfd):
    """The Panda, 10 s at 1 kHz from 0.2 Hz: 2 periods of 5000 samples; (20 + 40) series rated up to 12 times on
    400 samples, the chosen one up to 20 times on 5000, each sample 1000 harmonics x 7 joints."""
    terms = ((20 + 40) * 12 * 400 + 20 * 5000) * 1000 * 7
    err = _error(["excite", "panda", "--duration", "10", "--harmonics", "1000", "--out", str(tmp_path / "x.csv")], capfd)
    assert f"{terms:.3g} Fourier terms" in err and "5000 samples per period" in err, err


def test_design_states_the_control_samples_it_refuses(tmp_path, capfd):
    """(draws + as many re-check draws) x duration x rate."""
    err = _error(["design", "planar2", "--draws", "100000", "--duration", "3000", "--out", str(tmp_path / "g.json")],
                 capfd)
    assert f"{2 * 100000 * 3000 * 1000:.3g} control samples" in err, err
