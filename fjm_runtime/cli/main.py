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
from pathlib import Path
from typing import List, Optional

from ..validation import FjmValueError
from .ranges import OneLineParser


def _command_table():
    """The rows of cli/commands.toml: ``name``, ``module``, ``help`` and (but derive) ``description``."""
    try:
        import tomllib
    except ImportError:  # Python < 3.11
        import tomli as tomllib
    return tomllib.loads((Path(__file__).parent / "commands.toml").read_text(encoding="utf-8"))["command"]


#: The sub-commands, in ``fjm --help`` order: (name, module of ``fjm_runtime.cli``, one-line help), from
#: cli/commands.toml (the one table of the commands; it also holds each one's ``--help`` description).
#: A module has ``run(args)`` and ``add_arguments(parser)``, or, without ``add_arguments``, ``run(argv)``
#: on the arguments as they are. A module missing from the install (``tune``) is left out.
_TABLE = _command_table()
COMMANDS = tuple((row["name"], row["module"], row["help"]) for row in _TABLE)
#: The description of ``fjm NAME --help`` by command name (None: derive prints its own help).
DESCRIPTIONS = {row["name"]: row.get("description") for row in _TABLE}


def command_module(name: str):
    """The module of sub-command ``name`` (see :data:`COMMANDS`), or None (unknown, or not installed)."""
    module = next((mod for cmd, mod, _ in COMMANDS if cmd == name), None)
    if module is None or importlib.util.find_spec(f"{__package__}.{module}") is None:
        return None
    return importlib.import_module(f"{__package__}.{module}")


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
    parser = OneLineParser(
        prog="fjm", description="Flexible-joint manipulators: feedback linearization + sliding-mode control.")
    parser.add_argument("--version", action="version", version=f"fjm {version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, _, help_line in COMMANDS:
        module = command_module(name)
        if module is None:
            continue
        own_args = hasattr(module, "add_arguments")
        p = sub.add_parser(name, help=help_line, description=DESCRIPTIONS[name], add_help=own_args)
        if own_args:
            module.add_arguments(p)
    return parser


def _error(msg: str) -> int:
    print(f"fjm: error: {msg}", file=sys.stderr)
    return 2


def main(argv: Optional[List[str]] = None) -> int:
    """Run ``fjm`` with ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        module = command_module(argv[0]) if argv else None
        if module is not None and not hasattr(module, "add_arguments"):  # ``fjm derive``: arguments as they are
            return module.run(argv[1:])
        parser = build_parser()
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help()
            return 2
        return command_module(args.command).run(args)
    except (FjmValueError, ValueError) as exc:
        return _error(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    except OSError as exc:
        where = f" {exc.filename}" if getattr(exc, "filename", None) else ""
        return _error(f"{exc.strerror or exc}{where}")


if __name__ == "__main__":
    sys.exit(main())
