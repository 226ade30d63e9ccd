"""Paths the tests use, whatever folder a test file sits in."""

from pathlib import Path

#: The repository root (the folder holding pyproject.toml).
REPO = Path(__file__).resolve().parents[2]
#: The committed generated/ directory.
GENERATED = REPO / "generated"
#: The examples/ directory.
EXAMPLES = REPO / "examples"


def load_example(name: str):
    """The module of ``examples/<name>.py`` (examples are scripts, not a package: loaded by path)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
