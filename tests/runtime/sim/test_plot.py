"""SimulationResult.plot: the figure draws the run's own numbers (angles, reference, error, torque,
sliding variable) against its time axis, writes the file it is given, and a missing matplotlib is a
one-line error."""
import sys

import numpy as np
import pytest

from fjm_runtime.control.factory import make_controller
from fjm_runtime.control.references import Sinusoid
from fjm_runtime.sim.simulate import simulate
from fjm_runtime.validation import FjmValueError

import matplotlib  # noqa: F401  (the dev extra: a missing install fails here instead of skipping)


def _run(model, duration=0.2):
    ctrl = make_controller("ismc", model, {}, lam=8.0, k_s=100.0, delta=0.5)
    return simulate(model, ctrl, Sinusoid(0.5, 1.0, n=model.n), duration=duration, dt=1e-3)


def _curves(ax):
    """The (x, y) data of every line of ``ax``, in drawing order."""
    return [(np.asarray(ln.get_xdata(), float), np.asarray(ln.get_ydata(), float)) for ln in ax.get_lines()]


@pytest.mark.parametrize("name", ["link1", "planar2"])
def test_plot_draws_the_runs_numbers(name, tmp_path):
    import fjm_runtime
    import matplotlib.pyplot as plt
    m = fjm_runtime.load(name)
    res = _run(m)
    n = m.n
    path = tmp_path / "run.png"
    fig = res.plot(path, title="run")
    try:
        ax = fig.axes
        angles = _curves(ax[0])
        assert len(angles) == 3 * n
        for i in range(n):  # per joint: link angle, motor angle, reference
            for (x, y), want in zip(angles[3 * i:3 * i + 3], (res.x[:, i], res.x[:, 2 * n + i], res.ref[:, 0, i])):
                np.testing.assert_array_equal(x, res.t)
                np.testing.assert_array_equal(y, want)
        for a, want in ((ax[1], res.e1), (ax[2], res.u), (ax[3], res.s)):
            lines = _curves(a)
            assert len(lines) == n
            for i, (x, y) in enumerate(lines):
                np.testing.assert_array_equal(x, res.t)
                np.testing.assert_array_equal(y, want[:, i])
        # the sliding-variable panel shows the boundary layer: its limit is at least 5 delta
        assert ax[3].get_ylim()[1] >= 5 * float(np.max(res.delta)) - 1e-12
        assert path.stat().st_size > 1000 and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    finally:
        plt.close(fig)


def test_plot_without_a_path_writes_nothing(tmp_path, monkeypatch, link1):
    import matplotlib.pyplot as plt
    monkeypatch.chdir(tmp_path)
    fig = _run(link1, 0.05).plot()
    plt.close(fig)
    assert list(tmp_path.iterdir()) == []


def test_plot_without_matplotlib_is_a_one_line_error(monkeypatch, link1):
    res = _run(link1, 0.05)
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib now raises ImportError
    with pytest.raises(FjmValueError) as err:
        res.plot()
    msg = str(err.value)
    assert "\n" not in msg and "matplotlib" in msg and "pip install" in msg
