"""``fjm figures --quick``: the whole demo pipeline runs and writes every figure and summary.md.

Quick mode shortens every run (1 s) and the Monte Carlo (2 samples), so this smoke test checks
the files and the structure of the summary, not the documented numbers (those are checked by the
controller tests). About 100 s (the demo's compiled steps): ``exhaustive``, run by ``.ci/run`` after
``make test``.
"""
import math
import re

import pytest

pytestmark = pytest.mark.exhaustive

from fjm_runtime.cli.main import main

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
# What `make demo` promises (README "CLI" section: paper Figs 1-4, sat vs sign, controller
# comparison, planar2/planar3, Monte Carlo), by file name.
FIGURES = ["fig1_2_regulation.png", "fig3_4_tracking.png", "chattering_sat_vs_sign.png",
           "compare_link1_regulation.png", "compare_link1_tracking.png", "adaptive_stiffness_link1.png",
           "compare_planar2_tracking.png", "compare_planar3_tracking.png", "monte_carlo.png", "real_drives.png",
           "panda_drives.png", "real_arm_laws.png"]
SECTIONS = ["## Lemma 1 switching gain", "## Paper reproduction", "## Chattering",
            "## Plain feedback linearization", "## n links", "## Certified gains for the law that runs",
            "## Monte Carlo robustness", "## Real drives: the datasheet spring", "## Real drives on the Panda",
            "## Which law on which interface"]


def table_rows(text, heading):
    """Rows (lists of cells) of the first Markdown table after ``heading``."""
    lines = text[text.index(heading):].splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("|"))
    rows = []
    for line in lines[start + 2:]:  # skip header and separator
        if not line.startswith("|"):
            break
        rows.append([c.strip().strip("*") for c in line.strip("|").split("|")])
    return rows


@pytest.fixture(scope="module")
def quick_out(tmp_path_factory):
    out = tmp_path_factory.mktemp("figures")
    assert main(["figures", "--quick", "--out", str(out)]) == 0
    return out


def test_every_figure_is_a_non_empty_png(quick_out):
    for name in FIGURES:
        data = (quick_out / name).read_bytes()
        assert data[:8] == PNG_MAGIC, name
        assert len(data) > 10_000, (name, len(data))  # a drawn figure, not an empty canvas
    summary = (quick_out / "summary.md").read_text()
    referenced = set(re.findall(r"`([\w.]+\.png)`", summary))
    assert referenced and referenced <= {p.name for p in quick_out.glob("*.png")}, referenced
    assert set(FIGURES) <= referenced  # and the summary points at every one of them


def test_summary_has_the_sections_with_finite_numbers(quick_out):
    text = (quick_out / "summary.md").read_text()
    for heading in SECTIONS:
        assert heading in text, heading
    assert "Quick mode" in text  # the numbers are labelled as a smoke run
    # Lemma 1 gains: positive and finite for both tasks (columns 'k_s eq (16)' and 'k_s with rho')
    lemma = table_rows(text, "## Lemma 1 switching gain")
    assert [r[0] for r in lemma] == ["regulation", "tracking"]
    for row in lemma:
        for cell in row[3:]:
            assert math.isfinite(float(cell)) and float(cell) > 0, row
    # Paper reproduction: 2 tasks x 3 stiffnesses, every metric a finite number
    paper = table_rows(text, "## Paper reproduction")
    assert len(paper) == 6
    for row in paper:
        values = [float(c) for c in row[2:6]]  # final |e1|, RMS, RMS 2nd half, max |u|
        assert all(math.isfinite(v) and v >= 0 for v in values), row
    ratio = float(re.search(r"Total variation ratio sign/sat = ([0-9.e+]+)", text).group(1))
    assert math.isfinite(ratio) and ratio > 1
    mc = table_rows(text, "## Monte Carlo robustness")
    assert [float(r[0]) for r in mc] == [1.0, 0.1, 0.02, 0.0]
    for row in mc:
        assert row[2].endswith("/2"), row  # quick mode: 2 samples
        assert math.isfinite(float(row[1])) and math.isfinite(float(row[6])), row
    csv = (quick_out / "monte_carlo.csv").read_text().splitlines()
    assert csv[0].startswith("factor,k_s") and len(csv) == 5
