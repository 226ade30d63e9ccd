"""The shape of the code: no import cycle, no cross-module private import, small modules and
functions (tools/import_graph.py), and no issue number in a product file (history is in git)."""

from __future__ import annotations

import re
import subprocess
import sys

from support.paths import REPO

#: Files the product ships or a user reads (tests and docs included); the licence texts are third-party.
PRODUCT_SUFFIXES = (".py", ".md", ".toml", ".c", ".h", ".json", ".txt", ".cfg")
#: "[(]" rather than "\(": the pattern must not match its own source line
ISSUE_REF = re.compile(r"\bissues? ?#?\d+|[(]issue\b", re.IGNORECASE)


def test_packages_have_no_cycle_no_private_import_and_no_oversized_code():
    proc = subprocess.run([sys.executable, "tools/import_graph.py", "derive", "fjm_runtime",
                           "--max-function", "80", "--max-module", "500"],
                          cwd=REPO, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for package in ("derive", "fjm_runtime"):  # the tool looked at both, and found modules in each
        assert re.search(rf"^{package}: \d+ modules, .* 0 cycle\(s\), 0 private import\(s\)", proc.stdout, re.M), \
            proc.stdout


def test_the_import_graph_tool_finds_a_cycle(tmp_path):
    """The check above can fail: a two-module circle in a scratch package is reported."""
    pkg = tmp_path / "circ"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from . import b\n")
    (pkg / "b.py").write_text("def f():\n    from .a import x\n    return x\n")
    proc = subprocess.run([sys.executable, str(REPO / "tools" / "import_graph.py"), "circ"],
                          cwd=tmp_path, capture_output=True, text=True)
    assert proc.returncode == 1 and "1 cycle(s)" in proc.stdout, proc.stdout


def test_no_issue_numbers_in_product_files():
    files = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True).stdout.split()
    if not files:  # not a git checkout (an unpacked archive): list the tree
        files = [str(p.relative_to(REPO)) for p in REPO.rglob("*") if p.is_file() and ".venv" not in p.parts]
    hits = []
    for name in files:
        if not name.endswith(PRODUCT_SUFFIXES) or "LICENSE" in name or name.startswith("generated/"):
            continue
        path = REPO / name
        if not path.is_file():
            continue
        for k, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            if ISSUE_REF.search(line):
                hits.append(f"{name}:{k}: {line.strip()[:100]}")
    assert not hits, "\n".join(hits)
