"""The sensor model: the counter-based generator follows its documented algorithm bit for bit
(checked against splitmix64's published outputs and a pure-Python big-integer version), gives
standard normals, lays noise out by measurement, and refuses bad levels in one line."""
import math

import numpy as np
import pytest

from fjm_runtime.sim.sensor import SensorModel, noise_array, splitmix64, standard_normals
from fjm_runtime.validation import FjmValueError

M64 = (1 << 64) - 1


def _mix(x):                       # the published splitmix64 step, in Python integers
    z = (x + 0x9E3779B97F4A7C15) & M64
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & M64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & M64
    return z ^ (z >> 31)


def test_splitmix64_published_outputs():
    # the first two outputs of the SplitMix64 generator seeded with 0
    assert int(splitmix64(np.array([0], dtype=np.uint64))[0]) == 0xE220A8397B1DCDAF
    assert int(splitmix64(np.array([0x9E3779B97F4A7C15], dtype=np.uint64))[0]) == 0x6E789E6AA1B965F4


@pytest.mark.parametrize("seed, k, c", [(0, 0, 0), (7, 123, 5), (2 ** 63 + 5, 99999, 41)])
def test_normals_follow_the_documented_algorithm(seed, k, c):
    key = _mix(seed)
    h = _mix(key ^ k)
    a, b = _mix(h ^ (2 * c)), _mix(h ^ (2 * c + 1))
    u1, u2 = ((a >> 11) + 0.5) * 2.0 ** -53, ((b >> 11) + 0.5) * 2.0 ** -53
    expected = math.sqrt(-2 * math.log(u1)) * math.cos(2 * math.pi * u2)
    got = standard_normals(seed, k + 1, [c])[k, 0]
    assert got == pytest.approx(expected, rel=1e-15, abs=1e-15)


def test_normals_are_standard_and_independent_across_channels():
    N = standard_normals(3, 40000, [0, 1, 17])
    assert np.all(np.abs(N.mean(axis=0)) < 0.02)
    assert np.all(np.abs(N.std(axis=0) - 1) < 0.02)
    assert abs(np.corrcoef(N[:, 0], N[:, 1])[0, 1]) < 0.02
    assert abs(np.corrcoef(N[1:, 0], N[:-1, 0])[0, 1]) < 0.02


def test_noise_layout_by_sensing():
    s = SensorModel(q=1.0, dq=2.0, q_m=3.0, dq_m=4.0, tau_J=5.0, dtau_J=6.0, seed=9)
    n = 2
    state, torque = noise_array(s, "state", n, 5), noise_array(s, "torque", n, 5)
    unit = standard_normals(9, 5, range(6 * n))
    assert np.allclose(state, unit[:, :4 * n] * np.repeat([1.0, 2.0, 3.0, 4.0], n))
    # torque: q, dq, tau_J, dtau_J, dq_m -> channel blocks 0, 1, 4, 5, 3 (a signal keeps its noise)
    blocks = [0, 1, 4, 5, 3]
    cols = [b * n + i for b in blocks for i in range(n)]
    assert np.allclose(torque, unit[:, cols] * np.repeat([1.0, 2.0, 5.0, 6.0, 4.0], n))
    filt = SensorModel(tau_J=5.0, dtau_J=6.0, dtau_mode="filtered", seed=9)
    assert np.all(noise_array(filt, "torque", n, 5)[:, 3 * n:4 * n] == 0)     # dtau_J is the filter's


def test_presets():
    assert SensorModel.ideal().is_ideal()
    p = SensorModel.panda_white()
    assert (p.tau_J, p.q, p.dq, p.dtau_mode, p.velocity_mode) == (0.05, 1e-4, 1e-3, "filtered", "measured")
    assert SensorModel.panda() == p                       # the former name
    f = SensorModel.franka_like()
    assert (f.velocity_mode, f.dq, f.tau_J_offset) == ("differentiated", 0.0, 0.2)
    assert not hasattr(f, "torque_rate_limit")           # the rate limit is the command interface's


@pytest.mark.parametrize("kw", [{"q": float("nan")}, {"tau_J": -1.0}, {"dq": float("inf")},
                                {"dtau_mode": "guessed"}, {"dtau_cutoff": 0.0}, {"seed": -1}])
def test_bad_levels_are_one_line_errors(kw):
    with pytest.raises(FjmValueError) as exc:
        SensorModel(**kw)
    assert "\n" not in str(exc.value) and "SensorModel." in str(exc.value)


def test_read_noise_of_a_filtered_difference_matches_the_filter_run_on_noise():
    """read_noise_levels' closed form against the filter run on 200k samples of the source's noise
    (white normal plus uniform quantization error, the offset left out: it cancels in the difference)."""
    from fjm_runtime.sim.sensor import read_noise_levels
    sensor, T, n = SensorModel.franka_like(), 1e-3, 1
    rng = np.random.default_rng(3)

    def filtered_difference_std(s_white, step, cutoff):
        x = s_white * rng.standard_normal(200_000) + step * (rng.random(200_000) - 0.5)
        a, v, out = 1.0 - np.exp(-cutoff * T), 0.0, np.empty(x.size - 1)
        d = np.diff(x) / T
        for k in range(d.size):  # the loop's recursion v_k = v_{k-1} + a (d_k - v_{k-1})
            v += a * (d[k] - v)
            out[k] = v
        return out[1000:].std()

    lev = read_noise_levels(sensor, "full", n, T)  # q, dq, q_m, dq_m, tau_J, dtau_J
    assert lev[1] == pytest.approx(filtered_difference_std(sensor.q, sensor.q_quant, sensor.velocity_cutoff), rel=0.03)
    assert lev[3] == pytest.approx(filtered_difference_std(sensor.q_m, sensor.q_m_quant, sensor.velocity_cutoff),
                                   rel=0.03)
    assert lev[5] == pytest.approx(filtered_difference_std(sensor.tau_J, 0.0, sensor.dtau_cutoff), rel=0.03)
    assert lev[4] == sensor.tau_J and lev[0] == pytest.approx(np.hypot(sensor.q, sensor.q_quant / np.sqrt(12)))
