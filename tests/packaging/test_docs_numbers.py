"""Every measured number of README.md and docs/*.md is the report of the committed bench/results.json.

The numbers sit between ``<!-- fjm:bench:NAME -->`` and ``<!-- /fjm:bench:NAME -->`` markers
(and the big tables between ``bench:begin`` / ``bench:end``); ``python -m bench.report --docs``
writes them from the results. Here every marked block is re-rendered from the committed file and
must equal what the documents hold, and timings typed by hand outside the markers fail.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from bench import report, report_blocks, result_values

from support.paths import REPO  # noqa: E402
DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
MARKER = re.compile(r"<!-- (/?)fjm:bench:([a-z0-9-]+) -->")


@pytest.fixture(scope="module")
def results():
    return result_values.load()


@pytest.mark.parametrize("path", DOCS, ids=lambda p: p.name)
def test_marked_blocks_equal_the_report_of_the_committed_results(path, results):
    text = path.read_text(encoding="utf-8")
    assert report.render_file(path, results) == text, \
        f"{path.relative_to(REPO)}: a marked number differs from bench/results.json: run python -m bench.report --docs"


@pytest.mark.parametrize("path", DOCS, ids=lambda p: p.name)
def test_markers_are_paired_and_known(path):
    stack = []
    for m in MARKER.finditer(path.read_text(encoding="utf-8")):
        closing, name = m.group(1) == "/", m.group(2)
        assert name in report_blocks.BLOCKS, f"{path.name}: unknown block {name}"
        if closing:
            assert stack and stack.pop() == name, f"{path.name}: </{name}> closes nothing"
        else:
            assert not stack, f"{path.name}: block {name} opened inside {stack[-1]}"
            stack.append(name)
    assert not stack, f"{path.name}: block {stack} not closed"


def test_readme_and_docs_quote_the_derive_and_realtime_results():
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    assert "<!-- fjm:bench:summary -->" in readme
    assert "<!-- fjm:bench:realtime -->" in (REPO / "docs" / "c.md").read_text(encoding="utf-8")
    assert "<!-- fjm:bench:panda-derive-time -->" in (REPO / "docs" / "spatial.md").read_text(encoding="utf-8")


def _unmarked(text: str) -> str:
    """``text`` without the marked blocks and the bench tables (what a person typed)."""
    text = report_blocks.NAMED.sub(" ", text)
    if report.BEGIN in text and report.END in text:
        text = text[:text.index(report.BEGIN)] + text[text.index(report.END):]
    return text


#: Measured quantities that only a bench run can know: execution times in ns/us, sizes in kB,
#: derivation wall times ("derived in 7 s", "make derive ... 13.9 s"), and the drifted figures
#: once typed by hand. Settings (dt = 1 ms, 10 s runs, 5 kHz) do not match.
HAND_TYPED = [
    re.compile(r"\b\d+(\.\d+)?\s?(ns|us|µs|kB)\b"),
    re.compile(r"\bderived in ~?\d"),
    re.compile(r"\b(13\.9|4\.9) s\b"),
    re.compile(r"~?7-9 s\b"),
    re.compile(r"\biw\[\d+\]|\bw\[\d+\]"),
]


@pytest.mark.parametrize("path", DOCS, ids=lambda p: p.name)
def test_no_hand_typed_measurement_outside_markers(path):
    text = _unmarked(path.read_text(encoding="utf-8"))
    found = [(text[:m.start()].count("\n") + 1, m.group(0)) for pat in HAND_TYPED for m in pat.finditer(text)]
    assert not found, (f"{path.name}: measured numbers typed by hand (line in the unmarked text, match): {found}; "
                       "quote bench/results.json through a <!-- fjm:bench:NAME --> block (bench/report_blocks.py BLOCKS)")


def test_the_pattern_check_catches_a_typed_timing():
    assert any(p.search(_unmarked("the Panda is derived in ~7-9 s")) for p in HAND_TYPED)
    assert not any(p.search(_unmarked("x <!-- fjm:bench:run -->3.8 us<!-- /fjm:bench:run --> y")) for p in HAND_TYPED)


def test_rendering_is_idempotent(results):
    for path in DOCS:
        once = report.render_file(path, results)
        assert report_blocks.render_named(once, results) == once


def test_a_changed_result_changes_the_documents(results):
    import json
    worse = json.loads(json.dumps(results))
    worse["derive"]["total_seconds"] = 99.25
    text = report_blocks.render_named("a <!-- fjm:bench:derive-time -->13.9 s<!-- /fjm:bench:derive-time --> b", worse)
    assert "99.2 s" in text or "99.3 s" in text
    with pytest.raises(ValueError, match="unknown block"):
        report_blocks.render_named("<!-- fjm:bench:nope -->1<!-- /fjm:bench:nope -->", results)
