"""``fjm derive`` (fjm_runtime.cli.derive) passes SIGTERM/SIGINT on to the derivation it runs in a subprocess: it
ends within a second and writes nothing (without forwarding, the child went on deriving); its help is plain text."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest


# exhaustive pass (.ci/run), to keep make test under 5 minutes: in make test the derive's own signal
# handling is checked by tests/derive/test_guard.py and test_interrupted_derive.py
@pytest.mark.slow  # derives in a subprocess
@pytest.mark.exhaustive
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_fjm_derive_ends_on_a_signal_and_writes_nothing(tmp_path, signum):
    from derive.guard.synthetic import write_synthetic_chain
    # a 21-joint chain: several seconds of derivation on a fast idle machine (the Panda, under a
    # second there, could end before the signal)
    toml, _ = write_synthetic_chain(21, tmp_path / "model")
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "fjm_runtime.cli", "derive", "--model-file", str(toml),
                             "--out", str(out)], stderr=subprocess.PIPE, text=True)
    seen = []
    deadline = time.time() + 120
    for line in proc.stderr:  # wait until the symbolic work has started (stage lines of the guard)
        seen.append(line)
        if "linearize" in line or "deriving" in line or time.time() > deadline:
            break
    time.sleep(0.3)
    t0 = time.time()
    proc.send_signal(signum)
    rc = proc.wait(timeout=30)
    elapsed = time.time() - t0
    proc.stderr.close()
    assert rc != 0, seen
    assert elapsed < 1.0, f"ended {elapsed:.2f} s after the signal"
    assert not out.exists() or not any(out.iterdir()), sorted(p.name for p in out.iterdir())
    time.sleep(0.5)
    ps = subprocess.run(["ps", "-eo", "args"], capture_output=True, text=True).stdout
    assert str(out) not in ps, "the derivation is still running after fjm derive ended"


def test_derive_help_is_plain_text():
    from fjm_runtime.cli.derive import plain_help
    raw = ("usage: fjm derive [-h] [--out DIR]\n\n``python -m derive [--models M ...]``.\n\n"
           "options:\n  --out DIR  output root (default: ``generated/``)\n")
    text = plain_help(raw)
    assert "``" not in text and text.startswith("usage: fjm derive") and "Derive models" in text
    assert "output root (default: generated/)" in text
