"""The demo's complete-model section in quick mode: three fjm runs at N = 100, the same two laws against MuJoCo, a figure."""
import math
import sys

from fjm_runtime.experiments.complete import MUJOCO_FILE, complete_section, mujoco_runs, mujoco_text
from fjm_runtime.experiments.settings import DemoContext

#: Bound on max abs(q_MuJoCo - q_fjm) over the quick run (0.05 s, 250 samples at 5 kHz), rad. The two
#: plants' accelerations agree to ~1e-14 relative (tests/runtime/export/test_mjcf.py) and both integrate
#: by RK4 at the same step with the torque held, so the trajectories differ by rounding carried through
#: the loop, which the sliding-mode law (k_s = 200, boundary layer delta = 1) feeds back without
#: amplifying it much over 0.05 s: measured 4.5e-13 rad for both laws (link angles of order 1 rad, so
#: a few thousand ulps); 1e-9 leaves three decades for other BLAS, compilers and MuJoCo builds
#: while the rotor spin coupling alone moves q by 2.0e-5 rad over the same run (reduced vs complete
#: plant, same law): a modelling difference of that kind fails it by four decades.
GAP_BOUND = 1e-9


def cell(row, k):
    return row.split("|")[k].strip()


def test_quick_section_table_and_figure(tmp_path):
    ctx = DemoContext(out=tmp_path, duration=1.0, quick=True, n_mc=1, progress=None, results={})
    md, figures = complete_section(ctx)
    rows = [line for line in md if line.startswith("| panda")]
    assert [cell(r, 2) for r in rows] == ["reduced law", "reduced law", "compensated law"]
    mj = [line for line in md if line.startswith("| MuJoCo")]
    assert [cell(r, 2) for r in mj] == ["reduced law", "compensated law"]
    for r in rows + mj:
        rms = float(cell(r, 3).split()[0])
        assert math.isfinite(rms) and 0 < rms < 0.1, r
    fjm_rms = {cell(r, 2): float(cell(r, 3).split()[0]) for r in rows[1:]}
    for r in mj:
        gap = float(cell(r, 6))
        assert 0 <= gap < GAP_BOUND, r
        # the same law on the same plant: the RMS printed to 3 digits agrees
        assert abs(float(cell(r, 3).split()[0]) - fjm_rms[cell(r, 2)]) <= 0.01 * fjm_rms[cell(r, 2)], r
    assert (tmp_path / MUJOCO_FILE).stat().st_size > 1000
    assert figures[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and figures[0].stat().st_size > 10_000


def test_without_mujoco_one_line(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "mujoco", None)  # `import mujoco` raises ImportError
    assert mujoco_runs(tmp_path, 0.01, {}) is None
    assert not (tmp_path / MUJOCO_FILE).exists()
    text = mujoco_text(None)
    assert "\n" not in text and "not installed" in text
