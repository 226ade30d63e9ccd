"""The C the docs show: the example refuses bad inputs, and docs/c.md's snippet compiles and runs.

The generated C checks nothing (docs/c.md, README); ``examples/c/link1_alpha_beta`` is the caller
that validates: a NaN, an infinity or a non-positive stiffness, inertia, mass or length exits with
status 2 and one line on stderr, before the generated code runs.
"""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

import fjm_runtime

from support.paths import REPO  # noqa: E402
pytestmark = pytest.mark.slow  # builds C, a wheel or derives in a subprocess: `pytest -m 'not slow'` skips it

EXAMPLES = REPO / "examples" / "c"
GENERATED = REPO / "generated" / "link1"
DEFAULTS = ["1", "2", "150", "1", "9.8", "1", "0"]  # J_l J_m K M g0 L B_m


@pytest.fixture(scope="module")
def exe(tmp_path_factory):
    out = tmp_path_factory.mktemp("c_example_docs")
    proc = subprocess.run(["make", "-C", str(EXAMPLES), "alpha_beta", f"OUT={out}", "CC=gcc",
                           "GEN_WARN=-std=c99 -Wall -pedantic"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return out / "link1_alpha_beta"


def _params(**over):
    p = list(DEFAULTS)
    for name, value in over.items():
        p[["J_l", "J_m", "K", "M", "g0", "L", "B_m"].index(name)] = value
    return p


@pytest.mark.parametrize("args,needle", [
    (["nan", "0", "0", "0"], "finite"),
    (["0", "0", "0", "-inf"], "finite"),
    (["0.3", "0.1", "0.2", "-0.4", *_params(K="-150")], "K = -150: expected > 0"),
    (["0.3", "0.1", "0.2", "-0.4", *_params(K="0")], "K = 0: expected > 0"),
    (["0.3", "0.1", "0.2", "-0.4", *_params(J_m="0")], "J_m"),
    (["0.3", "0.1", "0.2", "-0.4", *_params(J_l="-1")], "J_l"),
    (["0.3", "0.1", "0.2", "-0.4", *_params(L="nan")], "finite"),
    (["0.3", "0.1", "0.2", "-0.4", *_params(B_m="-0.1")], "B_m = -0.1: expected >= 0"),
])
def test_example_refuses_bad_inputs_with_status_2_and_one_line(exe, args, needle):
    proc = subprocess.run([str(exe), *args], capture_output=True, text=True)
    assert proc.returncode == 2, (args, proc.stdout, proc.stderr)
    assert proc.stdout == "", "nothing may be printed as a result"
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], proc.stderr


def test_example_accepts_zero_gravity_and_damping(exe):
    proc = subprocess.run([str(exe), "0.3", "0.1", "0.2", "-0.4", *_params(g0="0", B_m="0.3")],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def test_docs_state_that_the_generated_c_performs_no_checks():
    c_md = (REPO / "docs" / "c.md").read_text(encoding="utf-8")
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    assert "The generated C performs no checks" in c_md
    assert "generated C performs no" in re.sub(r"\*\*|\s+", lambda m: "" if m.group(0) == "**" else " ", readme)


def test_docs_c_snippet_sizes_work_arrays_by_calling_work_and_runs(tmp_path):
    c_md = (REPO / "docs" / "c.md").read_text(encoding="utf-8")
    m = re.search(r"<!-- fjm:c-snippet -->\s*```c\n(.*?)```\s*<!-- /fjm:c-snippet -->", c_md, re.S)
    assert m, "docs/c.md lost its marked C snippet"
    src = m.group(1)
    assert "link1_alpha_work(" in src and not re.search(r"\b(iw|w)\[\d+\]", src)
    (tmp_path / "snippet.c").write_text(src)
    exe = tmp_path / "snippet"
    proc = subprocess.run(["gcc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O1", f"-I{GENERATED}",
                           str(tmp_path / "snippet.c"), str(GENERATED / "link1.c"), "-o", str(exe), "-lm"],
                          capture_output=True, text=True)
    if proc.returncode:  # the generated source's own warnings are tests/generated/test_c_sources.py's business
        proc = subprocess.run(["gcc", "-std=c99", "-O1", f"-I{GENERATED}", str(tmp_path / "snippet.c"),
                               str(GENERATED / "link1.c"), "-o", str(exe), "-lm"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    run = subprocess.run([str(exe)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    alpha = float(run.stdout.split("=")[1])
    m1 = fjm_runtime.load("link1")
    assert alpha == pytest.approx(m1.alpha([0.3, 0.2, 0.1, -0.4])[0], rel=1e-12, abs=1e-12)
