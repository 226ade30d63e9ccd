"""The repository stands alone.

* No tracked ``*.py``/``*.md`` file outside ``docs/`` points at the team's
  private design notes or at the paper's location outside the repository;
  the design lives in ``docs/`` and the paper is cited by title. (The
  patterns are assembled from pieces so that this file does not match them.)
* Every relative link in ``README.md`` and ``docs/*.md`` resolves to a file
  or directory inside the repository.
* ``python -m derive`` / ``fjm derive`` without ``--out`` outside a source
  checkout (e.g. installed from a wheel) is a usage error naming ``--out DIR``
  and ``FJM_GENERATED``, and writes nothing; with ``--out DIR`` it works and
  ``FJM_GENERATED=DIR`` makes ``fjm_runtime.load()`` read the result.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path
from typing import List

import numpy as np
import pytest

import derive.__main__ as derive_main_module  # noqa: E402
from fjm_runtime.cli import main as cli  # noqa: E402  (cli.main is the entry point)
from fjm_runtime.model import Model, load  # noqa: E402

from support.paths import REPO  # noqa: E402
pytestmark = pytest.mark.slow  # builds C, a wheel or derives in a subprocess: `pytest -m 'not slow'` skips it

_NOTES, _SHARED = "DESIGN" + ".md", "/" + "shared"
FORBIDDEN = re.compile("|".join(re.escape(s) for s in (".." + _SHARED, _NOTES, "/work" + _SHARED)))
# [text](target) and [text]: target  (reference definitions); images too.
INLINE_LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
REF_LINK = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$", re.MULTILINE)
FENCE = re.compile(r"^(```|~~~).*?^\1", re.MULTILINE | re.DOTALL)


def repo_files() -> List[str]:
    """Tracked and new (not ignored) files, relative to the repository root.

    Outside a git checkout (an unpacked source archive) every file is listed, except the
    virtual environment, caches and build outputs that .gitignore names.
    """
    if shutil.which("git") is None or not (REPO / ".git").exists():
        skip = {".venv", "__pycache__", "build", "dist", "out", ".pytest_cache", ".hypothesis"}
        return sorted(str(f.relative_to(REPO)) for f in REPO.rglob("*")
                      if f.is_file() and not skip.intersection(f.relative_to(REPO).parts)
                      and not f.name.endswith((".pyc", ".so", ".o")) and ".egg-info" not in str(f))
    out = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"],
                         cwd=REPO, capture_output=True, check=True).stdout.decode()
    return sorted({f for f in out.split("\0") if f and (REPO / f).is_file()})


def markdown_links(text: str) -> List[str]:
    """Link targets of a Markdown text, outside fenced code blocks."""
    text = FENCE.sub("", text)
    return INLINE_LINK.findall(text) + REF_LINK.findall(text)


def heading_anchors(text: str) -> set:
    """GitHub's anchors of the Markdown headings of ``text`` (lower case, punctuation dropped)."""
    text = FENCE.sub("", text)
    return {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-")
            for h in re.findall(r"^#{1,6}\s+(.+?)\s*#*$", text, re.MULTILINE)}


def is_external(target: str) -> bool:
    return bool(re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target))


# ---- no references outside the repository ---------------------------------------------------

def test_no_file_points_at_private_notes():
    offenders = []
    for rel in repo_files():
        if not rel.endswith((".py", ".md")) or rel.startswith("docs/"):
            continue
        for k, line in enumerate((REPO / rel).read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            if FORBIDDEN.search(line):
                offenders.append(f"{rel}:{k}: {line.strip()}")
    assert not offenders, ("these lines refer to files outside the repository (cite docs/ or the paper by "
                           "title instead):\n" + "\n".join(offenders))


def test_forbidden_pattern_catches_what_it_should():
    assert FORBIDDEN.search(f"see {_NOTES} section 2") and FORBIDDEN.search(f"in `..{_SHARED}/paper/`")
    assert not FORBIDDEN.search("see docs/design.md, section 2")


def test_docs_exist_and_readme_points_to_them():
    for name in ("README.md", "design.md", "errata.md", "derivation.md"):
        assert (REPO / "docs" / name).is_file(), f"docs/{name} is missing"
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    assert "docs/" in " ".join(markdown_links(readme)), "README.md has no link into docs/"
    assert "Robust Control of Flexible Joint Manipulators" in readme, "README.md must cite the paper by title"


def markdown_files() -> List[Path]:
    return [REPO / "README.md"] + sorted((REPO / "docs").glob("*.md"))


@pytest.mark.parametrize("md", markdown_files(), ids=lambda p: str(p.relative_to(REPO)))
def test_relative_links_resolve_inside_the_repository(md):
    broken = []
    for target in markdown_links(md.read_text(encoding="utf-8")):
        if is_external(target):
            continue
        path, _, anchor = target.partition("#")
        if not path:
            path = md.name
        resolved = (md.parent / path).resolve()
        try:
            resolved.relative_to(REPO)
        except ValueError:
            broken.append(f"{target} (outside the repository)")
            continue
        if not resolved.exists():
            broken.append(f"{target} (no such file)")
        elif anchor and resolved.suffix == ".md" and anchor not in heading_anchors(resolved.read_text("utf-8")):
            broken.append(f"{target} (no heading with that anchor in {path})")
    assert not broken, f"{md.relative_to(REPO)}: broken relative links: {broken}"


def test_link_extraction_sees_links():
    text = "a [x](docs/a.md) b ![i](img.png \"t\") [w](https://e.org) [s](#sec)\n[r]: ../y.md\n```\n[no](z.md)\n```\n"
    assert markdown_links(text) == ["docs/a.md", "img.png", "https://e.org", "#sec", "../y.md"]
    assert [t for t in markdown_links(text) if not is_external(t)] == ["docs/a.md", "img.png", "#sec", "../y.md"]
    assert heading_anchors("# Erratum 5: the `ad` sign\n## Runtime contract ##\n```\n# no\n```\n") == {
        "erratum-5-the-ad-sign", "runtime-contract"}


# ---- derive without --out outside a source checkout -------------------------------------------

def test_source_checkout_detection(tmp_path):
    assert derive_main_module.source_checkout(REPO)
    assert derive_main_module.default_out(REPO) == REPO / "generated"
    assert not derive_main_module.source_checkout(tmp_path)            # e.g. site-packages
    (tmp_path / "derive").mkdir()
    (tmp_path / "derive" / "__main__.py").write_text("")
    (tmp_path / "pyproject.toml").write_text('[project]\nname = "other"\n')
    assert not derive_main_module.source_checkout(tmp_path)            # somebody else's project
    (tmp_path / "pyproject.toml").write_text('[project]\nname = "fjm"\n')
    assert derive_main_module.source_checkout(tmp_path)


@pytest.fixture
def installed_layout(tmp_path, monkeypatch):
    """Pretend derive/ is installed: its parent is a site-packages-like directory."""
    site = tmp_path / "site-packages"
    site.mkdir()
    monkeypatch.setattr(derive_main_module, "REPO", site)
    monkeypatch.setattr(derive_main_module, "TIMINGS", site / "build" / "derive-timings.json")
    return site


@pytest.mark.parametrize("argv", [["--models", "link1"], ["--check"], []])
@pytest.mark.parametrize("entry", ["python -m derive"])  # `fjm derive` runs it in a subprocess: tests/packaging/test_wheel.py
def test_no_out_outside_checkout_is_a_usage_error(installed_layout, capsys, argv, entry):
    with pytest.raises(SystemExit) as exc:
        if entry == "fjm derive":
            cli.main(["derive"] + argv)
        else:
            derive_main_module.main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--out DIR" in err and "FJM_GENERATED=DIR" in err and "not an fjm source checkout" in err, err
    assert entry in err  # the usage line names the command the user typed
    assert list(installed_layout.iterdir()) == [], "nothing may be written without --out"


def test_with_out_outside_checkout_derives_and_load_reads_it(installed_layout, tmp_path, monkeypatch, capsys):
    out = tmp_path / "models"
    assert derive_main_module.main(["--models", "link1", "--out", str(out)]) == 0
    assert list(installed_layout.iterdir()) == [], "no timings or generated/ next to the installed package"
    monkeypatch.setenv("FJM_GENERATED", str(out))
    user = load("link1")
    assert user.directory == out / "link1"
    ref = Model(REPO / "generated" / "link1")
    x = np.array([0.3, 0.2, 0.1, -0.4])
    np.testing.assert_allclose(user.alpha(x), ref.alpha(x), rtol=1e-14, atol=0)
    np.testing.assert_allclose(user.beta(x), ref.beta(x), rtol=1e-14, atol=0)


def test_fjm_derive_is_a_subprocess_and_names_a_missing_extra(monkeypatch, capsys):
    """``fjm derive`` runs ``derive`` in a child process (the runtime imports no derive code)."""
    import importlib.util
    assert cli.main(["derive", "--check", "--models", "link1"]) == 0
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "sympy" else real(name, *a))
    assert cli.main(["derive", "--models", "link1"]) == 2
    err = capsys.readouterr().err
    assert "sympy is missing" in err and "pip install '.[derive]'" in err, err
    import ast
    for path in sorted((REPO / "fjm_runtime").rglob("*.py")):  # no import statement of derive anywhere
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else [])
            assert not [nm for nm in names if nm.split(".")[0] in ("derive", "sympy")], (path, node.lineno)


def test_checkout_default_is_generated(monkeypatch):
    """In the checkout, --out defaults to generated/ (checked without writing: --check of link1)."""
    assert derive_main_module.main(["--check", "--models", "link1"]) == 0
    assert os.path.samefile(derive_main_module.default_out(), REPO / "generated")
