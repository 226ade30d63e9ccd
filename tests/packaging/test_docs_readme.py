"""The README is short, its quick start is the one that works, and no relative link is broken."""
from __future__ import annotations

import re
from pathlib import Path

from support.paths import REPO  # noqa: E402
README = REPO / "README.md"
DOCS = [README, *sorted((REPO / "docs").glob("*.md"))]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _section(text: str, heading: str) -> str:
    m = re.search(rf"^## {re.escape(heading)}\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert m, f"README.md has no section '## {heading}'"
    return m.group(1)


def test_readme_is_at_most_10_kb():
    size = len(README.read_bytes())
    assert size <= 10 * 1024, f"README.md is {size} bytes; move details into docs/"


def test_quick_start_lists_make_demo_make_test_and_the_venv_fjm():
    quick = _section(README.read_text(encoding="utf-8"), "Quick start")
    for needle in ("make demo", "make test", ".venv/bin/fjm", "source .venv/bin/activate"):
        assert needle in quick, f"the quick start does not mention {needle!r}"


def test_fjm_commands_in_the_readme_name_the_venv():
    """A bare `fjm ...` command line fails with 'command not found' right after make demo."""
    blocks = re.findall(r"```(?:sh|bash|console)?\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    bare = [ln for b in blocks for ln in b.splitlines() if re.match(r"\s*fjm\s", ln)]
    assert not bare, f"README command lines without .venv/bin/: {bare}"


def test_every_relative_link_points_at_an_existing_file():
    broken = []
    for md in DOCS:
        for target in LINK.findall(md.read_text(encoding="utf-8")):
            if re.match(r"[a-z]+:", target) or target.startswith("#"):
                continue
            path = target.split("#", 1)[0]
            if not (md.parent / path).exists():
                broken.append(f"{md.relative_to(REPO)}: {target}")
    assert not broken, broken


def test_nothing_points_outside_the_repository():
    for md in DOCS:
        text = md.read_text(encoding="utf-8")
        outside = "/" + "shared"  # the team's notes outside the repository (spelled apart: not a pointer)
        assert ".." + outside not in text and "/work" + outside not in text, md
        for target in LINK.findall(text):
            if not re.match(r"[a-z]+:", target):
                resolved = (md.parent / target.split("#", 1)[0]).resolve()
                assert REPO in resolved.parents or resolved == REPO, f"{md.name}: {target} leaves the repository"


def test_readme_image_is_committed_and_docs_index_lists_the_new_pages():
    text = README.read_text(encoding="utf-8")
    images = [t for t in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)]
    assert images and all((REPO / i).is_file() and i.startswith("docs/img/") for i in images), images
    index = (REPO / "docs" / "README.md").read_text(encoding="utf-8")
    for page in ("usage.md", "controllers.md", "c.md", "benchmarks.md"):
        assert f"]({page})" in index, f"docs/README.md does not list {page}"
