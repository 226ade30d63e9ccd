"""The demo's complete-model section in quick mode: three runs at N = 100, a table of finite numbers, a figure."""
import math

from fjm_runtime.experiments.complete import complete_section
from fjm_runtime.experiments.settings import DemoContext


def test_quick_section_table_and_figure(tmp_path):
    ctx = DemoContext(out=tmp_path, duration=1.0, quick=True, n_mc=1, progress=None, results={})
    md, figures = complete_section(ctx)
    rows = [line for line in md if line.startswith("| panda")]
    assert [r.split("|")[2].strip() for r in rows] == ["reduced law", "reduced law", "compensated law"]
    for r in rows:
        rms = float(r.split("|")[3].split()[0])
        assert math.isfinite(rms) and 0 < rms < 0.1, r
    assert figures[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and figures[0].stat().st_size > 10_000
