"""pyproject.toml declares every data folder it ships, so building the wheel prints no warning.

setuptools warns (and announces it will one day drop the files) when package data sits in a
folder that looks like a package but is missing from ``packages``: every model folder of
``generated/`` (shipped as ``fjm_runtime.generated.<model>``) and every built-in arm under
``derive/robots/`` must therefore be listed. The license is an SPDX string with its file.
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from support.paths import REPO  # noqa: E402
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))


def _packages():
    return set(PYPROJECT["tool"]["setuptools"]["packages"])


def test_every_generated_model_folder_is_a_listed_package():
    models = sorted(p.name for p in (REPO / "generated").iterdir() if (p / "manifest.json").is_file())
    assert models, "generated/ has no models"
    missing = [m for m in models if f"fjm_runtime.generated.{m}" not in _packages()]
    assert not missing, f"add to [tool.setuptools] packages in pyproject.toml: " \
                        f"{', '.join('fjm_runtime.generated.' + m for m in missing)}"


def test_every_builtin_robot_folder_is_a_listed_package():
    robots = sorted(p.name for p in (REPO / "derive" / "robots").iterdir() if p.is_dir() and p.name != "__pycache__")
    missing = [r for r in robots if f"derive.robots.{r}" not in _packages()]
    assert not missing, f"add to [tool.setuptools] packages in pyproject.toml: derive.robots.{missing}"


def test_listed_packages_exist():
    dirs = PYPROJECT["tool"]["setuptools"].get("package-dir", {})
    for pkg in _packages():
        root = next((dirs[k] + pkg[len(k):].replace(".", "/") for k in dirs if pkg == k or pkg.startswith(k + ".")),
                    pkg.replace(".", "/"))
        assert (REPO / root).is_dir(), f"pyproject.toml lists package {pkg}, but {root}/ does not exist"


def test_license_is_an_spdx_string_with_its_file():
    project = PYPROJECT["project"]
    assert isinstance(project["license"], str) and re.fullmatch(r"[A-Za-z0-9.\-+ ()]+", project["license"])
    for f in project["license-files"]:
        assert (REPO / f).is_file(), f"license file {f} is missing"
    # SPDX license strings and license-files need setuptools >= 77 in the build environment
    req = " ".join(PYPROJECT["build-system"]["requires"])
    m = re.search(r"setuptools\s*>=\s*(\d+)", req)
    assert m and int(m.group(1)) >= 77, req


def test_every_runtime_data_folder_is_a_listed_package():
    """A folder of shipped files under fjm_runtime/ or derive/ without ``__init__.py`` (e.g. the shipped
    designs, fjm_runtime/control/designed) is a package to setuptools: unlisted, it warns and may drop it."""
    folders = []
    for top in ("fjm_runtime", "derive"):
        for d in sorted((REPO / top).rglob("*")):
            files = [f for f in d.iterdir() if f.is_file() and f.suffix not in (".pyc",)] if d.is_dir() else []
            if d.name != "__pycache__" and files and not (d / "__init__.py").is_file():
                folders.append(".".join(d.relative_to(REPO).parts))
    assert "fjm_runtime.control.designed" in folders
    missing = [f for f in folders if f not in _packages()]
    assert not missing, f"add to [tool.setuptools] packages in pyproject.toml: {', '.join(missing)}"
