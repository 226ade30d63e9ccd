"""Import graph and size checks for Python packages of this repository (stdlib only).

Usage::

    python tools/import_graph.py derive fjm_runtime [--max-function 80] [--max-module 500]

For every package given (a directory with ``__init__.py``, relative to the
current directory), every module is parsed with :mod:`ast`; imports within
the package -- absolute (``import derive.x``, ``from derive import x``) and
relative (``from .x import y``, ``from .. import z``), at the top level or
inside functions -- become edges of a module graph, and a depth-first search
reports every cycle found. It also reports

* cross-module imports of private names (``from .x import _name``);
* functions longer than ``--max-function`` lines (``end_lineno - lineno + 1``,
  decorators not counted), when the flag is given;
* modules longer than ``--max-module`` lines, when the flag is given.

Exit status 1 if any package has a cycle or a violation, else 0.
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path
from typing import Dict, List, Optional, Set, Tuple


def module_files(package: Path) -> Dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file of ``package``."""
    out: Dict[str, Path] = {}
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(package.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _resolve_base(module: str, is_package: bool, level: int, name: Optional[str]) -> str:
    """The absolute module named by ``from <level dots><name> import ...`` inside ``module``."""
    if level == 0:
        return name or ""
    parts = module.split(".")
    if not is_package:
        parts = parts[:-1]
    if level > 1:
        parts = parts[: len(parts) - (level - 1)]
    return ".".join(parts + ([name] if name else []))


def _known(target: str, modules: Dict[str, Path]) -> Optional[str]:
    """The longest prefix of ``target`` that is a module of the package (None if outside)."""
    parts = target.split(".")
    for k in range(len(parts), 0, -1):
        cand = ".".join(parts[:k])
        if cand in modules:
            return cand
    return None


def analyse(module: str, path: Path, modules: Dict[str, Path]) -> Tuple[Set[str], List[str]]:
    """Edges of ``module`` within the package, and its cross-module private imports."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    is_package = path.name == "__init__.py"
    edges: Set[str] = set()
    private: List[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                hit = _known(alias.name, modules)
                if hit and hit != module:
                    edges.add(hit)
        elif isinstance(node, ast.ImportFrom):
            base = _resolve_base(module, is_package, node.level, node.module)
            for alias in node.names:
                sub = f"{base}.{alias.name}" if base else alias.name
                if sub in modules:  # ``from pkg import submodule``
                    if sub != module:
                        edges.add(sub)
                    continue
                hit = _known(base, modules)
                if hit and hit != module:
                    edges.add(hit)
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        private.append(f"{path}:{node.lineno}: from {base} import {alias.name}")
    return edges, private


def find_cycles(graph: Dict[str, Set[str]]) -> List[List[str]]:
    """Every cycle closed by a back edge of a depth-first search (each reported once)."""
    cycles: List[List[str]] = []
    seen: Set[Tuple[str, ...]] = set()
    state: Dict[str, int] = {}  # 1 = on the stack, 2 = done
    stack: List[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                cyc = stack[stack.index(nxt):]
                k = cyc.index(min(cyc))
                key = tuple(cyc[k:] + cyc[:k])
                if key not in seen:
                    seen.add(key)
                    cycles.append(list(key) + [key[0]])
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)
    return cycles


def long_functions(path: Path, limit: int) -> List[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            length = node.end_lineno - node.lineno + 1
            if length > limit:
                out.append(f"{path}:{node.lineno}: function {node.name} has {length} lines (> {limit})")
    return out


def check_package(name: str, max_function: Optional[int], max_module: Optional[int]) -> int:
    package = Path(name)
    if not (package / "__init__.py").is_file():
        print(f"{name}: not a package (no {package / '__init__.py'})")
        return 1
    modules = module_files(package)
    graph: Dict[str, Set[str]] = {}
    private: List[str] = []
    for mod, path in modules.items():
        graph[mod], priv = analyse(mod, path, modules)
        private += priv
    cycles = find_cycles(graph)
    sizes: List[str] = []
    functions: List[str] = []
    for path in modules.values():
        if max_module is not None:
            n_lines = len(path.read_text(encoding="utf-8").splitlines())
            if n_lines > max_module:
                sizes.append(f"{path}: {n_lines} lines (> {max_module})")
        if max_function is not None:
            functions += long_functions(path, max_function)
    n_edges = sum(len(v) for v in graph.values())
    print(f"{name}: {len(modules)} modules, {n_edges} internal imports, {len(cycles)} cycle(s), "
          f"{len(private)} private import(s), {len(functions)} long function(s), {len(sizes)} long module(s)")
    for cyc in cycles:
        print("  cycle: " + " -> ".join(cyc))
    for line in private + functions + sizes:
        print("  " + line)
    return 1 if (cycles or private or functions or sizes) else 0


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("packages", nargs="+", help="package directories, e.g. derive fjm_runtime")
    ap.add_argument("--max-function", type=int, default=None, metavar="LINES")
    ap.add_argument("--max-module", type=int, default=None, metavar="LINES")
    args = ap.parse_args(argv)
    status = 0
    for name in args.packages:
        status |= check_package(name, args.max_function, args.max_module)
    return status


if __name__ == "__main__":
    sys.exit(main())
