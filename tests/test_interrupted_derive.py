"""An interrupted ``python -m derive`` leaves the output tree exactly as it was.

A copy of generated/ is marked (a sentinel line appended to every file, so a
file that derive rewrites, even with identical content, is detected), then
``python -m derive --out COPY`` is started and signalled (SIGTERM, SIGINT)
while planar6 is being derived. Afterwards the copy must be byte-identical to
before and no staging directory (``.<out>-tmp-*``) or backup
(``<out>.old``) may be left next to it. A control run that is not interrupted
(``--models link1``) must replace link1 and keep the other models.
"""

from __future__ import annotations

import os
import select
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict

import pytest

pytest.importorskip("sympy")

REPO = Path(__file__).resolve().parent.parent
SENTINEL = b"\n# sentinel: not written by this derive run\n"


def tree_bytes(root: Path) -> Dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture
def marked_copy(tmp_path):
    parent = tmp_path / "work"
    parent.mkdir()
    out = parent / "generated"
    shutil.copytree(REPO / "generated", out)
    for f in out.rglob("*"):
        if f.is_file():
            with open(f, "ab") as fh:
                fh.write(SENTINEL)
    return out


def _start(out: Path, *extra) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.Popen([sys.executable, "-u", "-m", "derive", "--out", str(out), *extra],
                            cwd=out.parent, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def _read_until(proc: subprocess.Popen, marker: bytes, timeout: float) -> bytes:
    """Read the child's output until ``marker`` shows up (the progress line is flushed without newline)."""
    buf = b""
    deadline = time.monotonic() + timeout
    fd = proc.stdout.fileno()
    while marker not in buf:
        left = deadline - time.monotonic()
        if left <= 0:
            proc.kill()
            pytest.fail(f"derive did not reach {marker!r} within {timeout} s; output so far:\n{buf.decode()}")
        ready, _, _ = select.select([fd], [], [], min(left, 1.0))
        if ready:
            chunk = os.read(fd, 4096)
            if not chunk:
                pytest.fail(f"derive ended before {marker!r}:\n{buf.decode()}")
            buf += chunk
    return buf


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_interrupted_derive_leaves_tree_untouched(marked_copy, sig):
    out = marked_copy
    before = tree_bytes(out)
    proc = _start(out)
    log = _read_until(proc, b"planar6: deriving", timeout=120)
    time.sleep(0.3)  # well inside planar6 (several seconds of work)
    proc.send_signal(sig)
    rest, _ = proc.communicate(timeout=60)
    log += rest
    text = log.decode(errors="replace")
    assert proc.returncode != 0, f"derive exited 0 after {sig.name}:\n{text}"
    assert "derived " not in text, f"derive finished before the signal arrived:\n{text}"
    assert "link1:" in text and " ops" in text, f"no model was completed before the signal:\n{text}"
    after = tree_bytes(out)
    assert set(after) == set(before), sorted(set(after) ^ set(before))
    changed = [k for k in before if before[k] != after[k]]
    assert not changed, f"files rewritten by an interrupted derive: {changed[:10]}"
    leftovers = sorted(p.name for p in out.parent.iterdir() if p.name != out.name)
    assert not leftovers, f"left behind next to the output: {leftovers}"


def test_uninterrupted_control_run_replaces_only_requested_models(marked_copy):
    out = marked_copy
    before = tree_bytes(out)
    proc = _start(out, "--models", "link1")
    log, _ = proc.communicate(timeout=120)
    assert proc.returncode == 0, log.decode(errors="replace")
    after = tree_bytes(out)
    assert set(after) == set(before)
    for k in before:
        if k.startswith("link1/"):  # rewritten: sentinel gone, content = the committed file
            assert after[k] == (REPO / "generated" / k).read_bytes(), k
        else:  # carried over untouched
            assert after[k] == before[k], k
    leftovers = sorted(p.name for p in out.parent.iterdir() if p.name != out.name)
    assert not leftovers, f"left behind next to the output: {leftovers}"
