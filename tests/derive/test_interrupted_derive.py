"""An interrupted ``python -m derive`` leaves the output tree exactly as it was.

A copy of generated/ is marked (a sentinel line appended to every file, so a
file that derive rewrites, even with identical content, is detected), then
``python -m derive --out COPY`` is started and signalled (SIGTERM, SIGINT)
while planar6 is being derived. Afterwards the copy must be byte-identical to
before and no staging directory (``.<out>-tmp-*``) or backup
(``<out>.old``) may be left next to it. A control run that is not interrupted
(``--models link1``) must replace link1 and keep the other models.

So that the signal lands at a known point however fast derive becomes, the
child runs derive's real ``main`` through a tiny wrapper that pauses at a hook
point and prints a marker: after planar6 has been emitted into the staging
directory (a sleep that the signal ends), or between the two renames that swap
the new tree in (until the test, having sent its signal, closes the child's stdin:
derive defers signals there, so the child must resume by itself, and waiting for
the test instead of a fixed sleep means the signal is always sent during the pause).
Nothing else of derive is replaced.

SIGKILL cannot be handled: a child killed at the swap pause leaves ``<out>.old`` and no
``<out>``, and ``derive.emit.writer.recover`` must restore the complete previous tree.
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

from support.paths import REPO  # noqa: E402
pytestmark = pytest.mark.slow  # builds C, a wheel or derives in a subprocess: `pytest -m 'not slow'` skips it

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


# Runs ``python -m derive ARGS`` with an optional pause point (argv[1]): "model:NAME" pauses after
# NAME's files are written (to staging), "swap" pauses after the first rename of the swap.
WRAPPER = r"""
import os, runpy, select, sys, time
hook, sys.argv = sys.argv[1], ["derive"] + sys.argv[2:]
def pause(what, seconds, until_stdin=False):
    print(f"\nPAUSED {what}", flush=True)
    if until_stdin:  # until the parent writes to or closes our stdin (after its signal), at most `seconds`
        select.select([sys.stdin], [], [], seconds)
    else:
        time.sleep(seconds)
if hook.startswith("model:"):
    import derive.emit.writer as writer
    real_write = writer.write_model
    def write_model(lin, outdir, **kw):
        manifest = real_write(lin, outdir, **kw)
        if outdir.name == hook[6:]:
            pause(hook, 60)
        return manifest
    writer.write_model = write_model
elif hook == "swap":
    def slow(real):
        def rename(src, dst, *a, **k):
            real(src, dst, *a, **k)
            if not os.path.basename(str(src)).startswith("."):  # moving the live tree aside
                pause("swap", 60, until_stdin=True)  # a derive that defers signals here resumes once signalled
        return rename
    os.rename, os.replace = slow(os.rename), slow(os.replace)
runpy.run_module("derive", run_name="__main__", alter_sys=True)
"""


def _start(out: Path, *extra, hook: str = "none") -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.Popen([sys.executable, "-u", "-c", WRAPPER, hook, "--out", str(out), *extra],
                            cwd=out.parent, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT)


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


# SIGTERM takes the same handler path as SIGINT: it runs in the exhaustive pass (.ci/run)
@pytest.mark.parametrize("sig", [pytest.param(signal.SIGTERM, marks=pytest.mark.exhaustive), signal.SIGINT],
                         ids=["SIGTERM", "SIGINT"])
def test_interrupted_derive_leaves_tree_untouched(marked_copy, sig):
    out = marked_copy
    before = tree_bytes(out)
    proc = _start(out, hook="model:planar6")
    log = _read_until(proc, b"PAUSED model:planar6", timeout=180)
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


def _derive_link1_replaces_only_link1(out, before):
    """``derive --models link1`` into ``out`` succeeds; link1's files are rewritten (sentinel gone, content =
    the committed file) and every other file of ``before`` is carried over untouched."""
    proc = _start(out, "--models", "link1")
    log, _ = proc.communicate(timeout=120)
    assert proc.returncode == 0, log.decode(errors="replace")
    after = tree_bytes(out)
    assert set(after) == set(before)
    for k in before:
        expected = (REPO / "generated" / k).read_bytes() if k.startswith("link1/") else before[k]
        assert after[k] == expected, k


# exhaustive pass (.ci/run), to keep make test under 5 minutes on 2 cores: make check-generated derives
# every model into a staging tree and swaps it in on every CI run
@pytest.mark.exhaustive
def test_uninterrupted_control_run_replaces_only_requested_models(marked_copy):
    out = marked_copy
    _derive_link1_replaces_only_link1(out, tree_bytes(out))
    leftovers = sorted(p.name for p in out.parent.iterdir() if p.name != out.name)
    assert not leftovers, f"left behind next to the output: {leftovers}"


# both signals in the exhaustive pass (.ci/run): make test keeps the signal-before-the-swap case above
@pytest.mark.exhaustive
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_interrupt_during_swap_keeps_a_complete_tree(marked_copy, sig):
    """A signal between the renames of the swap must leave either the old or the complete new tree."""
    out = marked_copy
    before = tree_bytes(out)
    proc = _start(out, "--models", "link1", hook="swap")
    # The live tree is always moved aside by a rename before the new one goes in, so the
    # hook always fires; a derive that swaps otherwise (or exits 0 first) fails here.
    log = _read_until(proc, b"PAUSED swap", timeout=120)
    proc.send_signal(sig)
    rest, _ = proc.communicate(timeout=60)  # closes the child's stdin: the paused swap resumes
    text = (log + rest).decode(errors="replace")
    assert out.is_dir(), f"{out.name}/ is gone after {sig.name} during the swap:\n{text}\n" \
        f"next to it: {sorted(p.name for p in out.parent.iterdir())}"
    after = tree_bytes(out)
    assert set(after) == set(before), sorted(set(after) ^ set(before))
    if after != before:  # then it must be the complete new tree: link1 re-derived, the rest carried over
        for k in before:
            if k.startswith("link1/"):
                assert after[k] == (REPO / "generated" / k).read_bytes(), k
            else:
                assert after[k] == before[k], k
    leftovers = sorted(p.name for p in out.parent.iterdir() if p.name != out.name)
    assert not leftovers, f"left behind next to the output: {leftovers}"


@pytest.mark.exhaustive  # ~10 s of derive subprocesses: .ci/run runs it after make test (make test stays under 5 minutes)
def test_sigkill_between_the_renames_is_recovered(marked_copy):
    """SIGKILL cannot be deferred: killed right after the live tree was moved aside, ``generated/``
    is missing and ``generated.old`` holds the previous tree. ``recover()`` (run first by every
    derive) must put the complete previous tree back; a following derive then succeeds."""
    from derive.emit.writer import recover

    out = marked_copy
    before = tree_bytes(out)
    proc = _start(out, "--models", "link1", hook="swap")
    _read_until(proc, b"PAUSED swap", timeout=120)
    proc.kill()  # SIGKILL at the pause point: after rename(generated -> generated.old), before the second
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    old = out.with_name(out.name + ".old")
    assert not out.exists() and old.is_dir(), sorted(p.name for p in out.parent.iterdir())

    recover(out)
    assert out.is_dir() and not old.exists()
    assert tree_bytes(out) == before  # the complete previous tree, byte for byte
    recover(out)  # idempotent: nothing to do on a complete tree
    assert tree_bytes(out) == before

    # the next derive starts from the recovered tree and completes normally
    _derive_link1_replaces_only_link1(out, before)
    assert not old.exists()


def test_recover_leaves_a_complete_tree_alone(tmp_path):
    """Killed after the second rename (new tree in place, ``.old`` not yet removed): recover() must
    not touch the live tree; with no ``.old`` at all it does nothing either."""
    from derive.emit.writer import recover

    out = tmp_path / "generated"
    shutil.copytree(REPO / "generated" / "link1", out / "link1")
    old = tmp_path / "generated.old"
    shutil.copytree(REPO / "generated" / "link1", old / "link1")
    (old / "link1" / "manifest.json").write_text("{}\n")  # the previous (different) tree
    before = tree_bytes(out)
    recover(out)
    assert tree_bytes(out) == before
    shutil.rmtree(old)
    recover(out)
    assert tree_bytes(out) == before
