"""Command line: ``fjm COMMAND ...`` (``python -m fjm_runtime.cli``): the parser, ``--version``, dispatch.

Examples
--------
``fjm models`` (every model: joints, parameters, source)
``fjm simulate link1 --K 120 --reference sine --duration 10 --plot out/run.png``
``fjm simulate planar2 --controller ismc --param K1=120 --param K2=180 --reference sine``
``fjm figures --out out`` (``--quick``: a fast smoke run of the same pipeline)
``fjm sweep link1 --samples 1000 --chunk 250 --out out/sweep.csv`` (Dask; ``--scheduler ADDRESS``)
``fjm derive --model-file arm.toml --out DIR`` (needs ``pip install '.[derive]'``)
``fjm export mjcf panda --out panda.xml [--complete]`` (a MuJoCo model, docs/mujoco.md)

Every error a user can cause is one line on stderr (``fjm: error: ...``) and exit status 2.
"""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys
from typing import List, Optional

from . import analyze, derive, design, excite, export, figures, identify, models, simulate, sweep
from ..validation import FjmValueError

#: Sub-commands with an ``add_parser(sub)`` and a ``run(args)``, in ``--help`` order.
COMMANDS = {"simulate": simulate, "design": design, "analyze": analyze, "sweep": sweep, "figures": figures, "models": models,
            "export": export, "excite": excite, "identify": identify}


def _tune_module():
    """``fjm_runtime.cli.tune`` when it is there (``add_parser(sub)``, ``run(args)``), else None."""
    if importlib.util.find_spec(f"{__package__}.tune") is None:
        return None
    return importlib.import_module(f"{__package__}.tune")


def version() -> str:
    """The installed package version (``fjm_runtime.__version__`` in a source checkout)."""
    try:
        from importlib.metadata import PackageNotFoundError, version as dist_version
        try:
            return dist_version("fjm")
        except PackageNotFoundError:
            pass
    except ImportError:  # pragma: no cover
        pass
    from .. import __version__
    return __version__


def build_parser() -> argparse.ArgumentParser:
    """The ``fjm`` parser with every sub-command."""
    parser = argparse.ArgumentParser(
        prog="fjm", description="Flexible-joint manipulators: feedback linearization + sliding-mode control.")
    parser.add_argument("--version", action="version", version=f"fjm {version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    simulate.add_parser(sub)
    design.add_parser(sub)
    analyze.add_parser(sub)
    derive.add_parser(sub)
    sweep.add_parser(sub)
    figures.add_parser(sub)
    models.add_parser(sub)
    export.add_parser(sub)
    excite.add_parser(sub)
    identify.add_parser(sub)
    tune = _tune_module()
    if tune is not None:
        tune.add_parser(sub)
    return parser


def _error(msg: str) -> int:
    print(f"fjm: error: {msg}", file=sys.stderr)
    return 2


def main(argv: Optional[List[str]] = None) -> int:
    """Run ``fjm`` with ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        if argv[:1] == ["derive"]:
            return derive.run(argv[1:])
        parser = build_parser()
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help()
            return 2
        module = COMMANDS.get(args.command) or (_tune_module() if args.command == "tune" else None)
        if module is None:
            return _error(f"unknown command {args.command!r}")
        return module.run(args)
    except (FjmValueError, ValueError) as exc:
        return _error(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    except OSError as exc:
        where = f" {exc.filename}" if getattr(exc, "filename", None) else ""
        return _error(f"{exc.strerror or exc}{where}")


if __name__ == "__main__":
    sys.exit(main())
