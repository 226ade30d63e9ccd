"""Guards of ``python -m derive``: a cost pre-scan, per-stage progress, and interruptible symbolic work.

* :func:`prescan_model_file` reads only what the cost estimate needs from a
  model file (the number of joints and the form) with the standard library's
  TOML parser and :mod:`derive.spatial.urdf` (no SymPy, no CasADi), so a runaway
  input is refused before the heavy imports. Anything it cannot read is left
  to the full parser (:mod:`derive.model_file`), which reports it.
* :func:`machine_slowdown` reads the load average, by which the cost estimate's seconds grow.
* :class:`StageLog` prints one line per stage per model on stderr
  (``chain14: linearize ... 3.1 s``).
* :func:`run_interruptible` runs the symbolic work in a forked child process.
  SymPy and CasADi can spend seconds inside one call and a Python signal
  handler runs only between bytecodes of the main thread; and a process that
  does stop still has to free millions of expression nodes on the way out.
  The parent only waits: on SIGINT or SIGTERM it kills the child (SIGKILL),
  reaps it and raises :class:`Interrupted`, within milliseconds. The child dies
  with the parent (``PR_SET_PDEATHSIG`` on Linux). Without ``os.fork`` the
  work runs in-process with handlers that raise :class:`Interrupted`.
"""

from __future__ import annotations

import ctypes
import json
import os
import signal
import sys
import time
import traceback
from pathlib import Path
from typing import Callable, Optional, TextIO, Tuple

from .cost import slowdown

__all__ = ["Interrupted", "StageLog", "machine_slowdown", "prescan_model_file", "run_interruptible", "LONG_SECONDS"]

#: Models whose estimated derive takes longer than this print one line per stage.
LONG_SECONDS = 2.0

_HANDLED = (signal.SIGINT, signal.SIGTERM)


class Interrupted(Exception):
    """The derivation was ended by a signal (``signum``); nothing was written."""

    def __init__(self, signum: int):
        super().__init__(f"interrupted by {signal.Signals(signum).name}")
        self.signum = signum


def machine_slowdown() -> float:
    """The machine's current :func:`derive.guard.cost.slowdown`: the 1-minute load average on the cores this
    process may use (1.0 where the load average is not available)."""
    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):  # pragma: no cover - no load average (e.g. Windows)
        return 1.0
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return slowdown(load, cpus)


def prescan_model_file(path: Path) -> Optional[Tuple[str, int, str]]:
    """``(name, n, form)`` of a model file from its ``[model]`` table and URDF, or None if unreadable.

    ``form`` is ``"planar"`` (``links = n``) or ``"spatial"`` (``urdf``, ``base``, ``tip``: ``n``
    revolute joints on the chain). None means "not known here": the full parser decides.
    """
    try:
        import tomllib
    except ModuleNotFoundError:  # pragma: no cover - Python < 3.11: the full parser (tomli) decides
        return None
    try:
        path = Path(path)
        data = tomllib.loads(path.read_bytes().decode("utf-8-sig"))
        model = data["model"]
        name = str(model["name"])
        if "urdf" not in model:
            links = model["links"]
            return (name, links, "planar") if isinstance(links, int) and links >= 1 else None
        from ..spatial.urdf import load_urdf
        chain = load_urdf(path.parent / model["urdf"], model["base"], model["tip"])
        return name, len(chain.joints), "spatial"
    except Exception:  # noqa: BLE001 - any problem is reported by the full parser
        return None


class StageLog:
    """One stderr line per stage of one model: ``<model>: <stage> ... <seconds> s``.

    Call it with the next stage's label; each call ends the previous stage's
    line with its duration; :meth:`done` ends the last one. Disabled
    (``enabled=False``) it prints nothing.
    """

    def __init__(self, model: str, enabled: bool, stream: TextIO = None):
        self.model, self.enabled = model, enabled
        self.stream = stream if stream is not None else sys.stderr
        self._t0: Optional[float] = None

    def __call__(self, stage: str) -> None:
        self.done()
        if self.enabled:
            print(f"{self.model}: {stage} ...", end="", file=self.stream, flush=True)
        self._t0 = time.perf_counter()

    def done(self) -> None:
        """End the current stage's line (with its seconds)."""
        if self._t0 is not None and self.enabled:
            print(f" {time.perf_counter() - self._t0:.2f} s", file=self.stream, flush=True)
        self._t0 = None


def _die_with_parent() -> None:
    """Linux: the kernel sends this process SIGKILL when its parent dies (even by SIGKILL)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):  # pragma: no cover - not Linux
        pass


def _child(work: Callable[[], object], wfd: int) -> None:  # pragma: no cover - runs in the fork
    """The forked child: run ``work``, send its JSON result through ``wfd``, exit without cleanup."""
    code = 0
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides (Ctrl-C reaches the whole group)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        _die_with_parent()
        payload = json.dumps({"result": work()}).encode()
        while payload:
            payload = payload[os.write(wfd, payload):]
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    except BaseException:  # noqa: BLE001 - reported, then the parent returns the failure
        traceback.print_exc()
        code = 1
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)  # no interpreter teardown: freeing huge expression graphs takes seconds


def _raise_interrupted(signum, frame):
    raise Interrupted(signum)


def run_interruptible(work: Callable[[], object]) -> Tuple[int, object]:
    """Run ``work()`` (its result JSON-serializable) so that SIGINT/SIGTERM end it at once.

    Returns
    -------
    (int, object)
        ``(0, result)`` on success, ``(exit code, None)`` if the work failed (its traceback
        was printed on stderr).

    Raises
    ------
    Interrupted
        On SIGINT or SIGTERM; the child is dead and reaped when this is raised.
    """
    saved = {s: signal.signal(s, _raise_interrupted) for s in _HANDLED}
    try:
        if not hasattr(os, "fork"):  # pragma: no cover - e.g. Windows: in-process
            return 0, work()
        sys.stdout.flush()
        sys.stderr.flush()
        rfd, wfd = os.pipe()
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child
            os.close(rfd)
            _child(work, wfd)
        os.close(wfd)
        status = []
        try:
            return _collect(pid, rfd, status)
        finally:
            os.close(rfd)
            if not status:  # interrupted (or failed) before the child was reaped
                _kill_and_reap(pid)
    finally:
        for s, handler in saved.items():
            signal.signal(s, handler)


def _collect(pid: int, rfd: int, status: list) -> Tuple[int, object]:
    """Read the child's result until EOF, then its exit status (appended to ``status`` once reaped)."""
    chunks = []
    while True:
        chunk = os.read(rfd, 1 << 16)  # a signal handler raising Interrupted ends the wait here
        if not chunk:
            break
        chunks.append(chunk)
    status.append(os.waitpid(pid, 0)[1])
    code = os.waitstatus_to_exitcode(status[0])
    if code != 0 or not chunks:
        return (code if code > 0 else 128 - code if code < 0 else 1), None
    return 0, json.loads(b"".join(chunks))["result"]


def _kill_and_reap(pid: int) -> None:
    """SIGKILL the (not yet reaped) child and reap it; further SIGINT/SIGTERM are ignored meanwhile."""
    saved = {s: signal.signal(s, signal.SIG_IGN) for s in _HANDLED}
    try:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        try:
            os.waitpid(pid, 0)
        except ChildProcessError:
            pass
    finally:
        for s, handler in saved.items():
            signal.signal(s, handler)
