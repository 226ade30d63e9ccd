"""The shape of the code: no import cycle, no cross-module private import, small modules and
functions (tools/import_graph.py), names imported from the module that defines them, and no issue
number in a product file (history is in git)."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

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


#: The one module that may list and re-export names it does not define: the public top-level API.
PUBLIC_FACADE = "fjm_runtime"
#: Folders whose imports of this repository's modules are checked.
IMPORTING_TREES = ("derive", "fjm_runtime", "tests", "bench", "examples", "tools")


def _module_names(root: Path, packages=("derive", "fjm_runtime")):
    """Dotted name -> (file, is_package) of every module of ``packages`` under ``root``."""
    out = {}
    for package in packages:
        for path in (root / package).rglob("*.py"):
            parts = list(path.relative_to(root).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            out[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return out


def _defined_names(statements):
    """Names bound at the top level of ``statements`` (functions, classes, assignments; inside ``if``
    and ``try`` too), imports excluded."""
    names = set()
    for node in statements:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names |= {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
        elif isinstance(node, (ast.If, ast.Try)):
            blocks = [node.body, node.orelse] + [getattr(node, "finalbody", [])] \
                + [h.body for h in getattr(node, "handlers", [])]
            names |= set().union(*(_defined_names(block) for block in blocks))
    return names


def _absolute(module: str, is_package: bool, level: int, name):
    """The module ``from <level dots><name> import ...`` names inside ``module``."""
    if level == 0:
        return name
    parts = module.split(".") if is_package else module.split(".")[:-1]
    return ".".join(parts[:len(parts) - (level - 1)] + ([name] if name else []))


def reexport_violations(root: Path, trees=IMPORTING_TREES):
    """Every ``__all__`` entry a module does not define, and every ``from M import name`` (in ``trees``)
    of a module M of this repository that does not define ``name`` (a submodule counts as defined);
    the public facade :data:`PUBLIC_FACADE` is exempt on both sides."""
    modules = _module_names(root)
    parsed = {m: ast.parse(path.read_text()) for m, (path, _) in modules.items()}
    defined = {m: _defined_names(tree.body) for m, tree in parsed.items()}
    hits = []
    for m, tree in parsed.items():
        for node in tree.body:
            if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
                hits += [f"{m}: __all__ lists {e.value}, defined elsewhere" for e in node.value.elts
                         if m != PUBLIC_FACADE and e.value not in defined[m]]
    for folder in trees:
        for path in sorted((root / folder).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            here = ".".join(parts[:-1] if is_package else parts)
            for node in ast.walk(ast.parse(path.read_text())):
                if not isinstance(node, ast.ImportFrom):
                    continue
                source = _absolute(here, is_package, node.level, node.module)
                if source not in modules or source == PUBLIC_FACADE:
                    continue
                hits += [f"{path.relative_to(root)}:{node.lineno}: {a.name} from {source}, which does not define it"
                         for a in node.names if a.name != "*" and a.name not in defined[source]
                         and f"{source}.{a.name}" not in modules]
    return hits


def test_names_are_imported_from_the_module_that_defines_them():
    hits = reexport_violations(REPO)
    assert not hits, "\n".join(hits)


def test_the_reexport_check_finds_a_reexport(tmp_path):
    """The check above can fail: a module listing an imported name in __all__, and a module importing a
    name through it, are both reported; the public facade may do either."""
    for package, body in (("fjm_runtime", "from .a import f\n__all__ = ['f']\n"), ("derive", "")):
        (tmp_path / package).mkdir()
        (tmp_path / package / "__init__.py").write_text(body)
    (tmp_path / "derive" / "a.py").write_text("def f():\n    return 1\n")
    (tmp_path / "derive" / "b.py").write_text("from .a import f  # noqa: F401\n__all__ = ['f']\n")
    (tmp_path / "derive" / "c.py").write_text("from .b import f\nfrom .a import f as g\n")
    (tmp_path / "fjm_runtime" / "a.py").write_text("def f():\n    return 1\n")
    (tmp_path / "fjm_runtime" / "c.py").write_text("from . import f\n")
    hits = reexport_violations(tmp_path, trees=("derive", "fjm_runtime"))
    assert hits == ["derive.b: __all__ lists f, defined elsewhere",
                    "derive/c.py:1: f from derive.b, which does not define it"], hits
