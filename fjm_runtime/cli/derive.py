"""``fjm derive ...``: ``python -m derive ...`` in a subprocess (the runtime never imports derive)."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path
from typing import List, Optional

from ..validation import FjmValueError

DESCRIPTION = ("Derive models symbolically (SymPy: feedback linearization T, alpha, beta and the controllers) and "
               "emit CasADi functions, C sources, manifest.json and REPORT.md per model into --out. Needs the "
               "build-time extra: pip install '.[derive]'.")
def out_argument(argv: List[str]) -> Optional[str]:
    """The value of ``--out`` in ``argv`` (``--out DIR`` or ``--out=DIR``), or None."""
    for i, a in enumerate(argv):
        if a == "--out" and i + 1 < len(argv):
            return argv[i + 1]
        if a.startswith("--out="):
            return a.split("=", 1)[1]
    return None


def run(argv: List[str]) -> int:
    """Check what can be checked here (the extra is installed, ``--out`` is not a file), then run derive."""
    for mod in ("derive", "sympy"):
        if importlib.util.find_spec(mod) is None:
            print(f"fjm derive: error: the derivation needs the build-time extra ({mod} is missing); "
                  "install it with: pip install '.[derive]'  (or: pip install 'fjm[derive]')", file=sys.stderr)
            return 2
    out = out_argument(argv)
    if out is not None and Path(out).exists() and not Path(out).is_dir():
        raise FjmValueError(f"--out {out}: is a file (expected a directory, existing or to be created)")
    code = ("import sys; from derive.__main__ import main; "
            "sys.exit(main(sys.argv[1:], prog='fjm derive'))")
    root = str(Path(importlib.util.find_spec("derive").origin).resolve().parent.parent)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root] + [v for v in [os.environ.get("PYTHONPATH")] if v]))
    if not {"-h", "--help"} & set(argv):
        return run_forwarding_signals([sys.executable, "-c", code, *argv], env)
    proc = subprocess.run([sys.executable, "-c", code, *argv], env=env, capture_output=True, text=True)
    sys.stdout.write(plain_help(proc.stdout))
    sys.stderr.write(proc.stderr)
    return proc.returncode


def run_forwarding_signals(cmd: List[str], env) -> int:
    """Run ``cmd`` and pass SIGINT/SIGTERM on to it, so that ``fjm derive`` ends the way
    ``python -m derive`` does (within 1 s, nothing written) instead of leaving the child running."""
    import signal
    proc = subprocess.Popen(cmd, env=env)
    forwarded = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.getsignal(s) for s in forwarded}

    def forward(signum, _frame):
        proc.send_signal(signum)

    try:
        for s in forwarded:
            signal.signal(s, forward)
        return proc.wait()
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def plain_help(text: str) -> str:
    """``python -m derive --help`` as plain text: the docstring paragraph replaced by :data:`DESCRIPTION`,
    reST literals (double backquotes) removed."""
    import re
    import textwrap
    head, sep, rest = text.partition("\n\n")
    if sep and "options:" in rest:
        _desc, sep2, opts = rest.partition("options:")
        rest = textwrap.fill(DESCRIPTION, 79) + "\n\n" + sep2 + opts
    return re.sub(r"``(.*?)``", r"\1", head + sep + rest, flags=re.S)
