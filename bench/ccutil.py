"""Compile C with the bench's fixed flags and call timing drivers through ctypes."""
from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path
from typing import List, Sequence

#: One set of flags for every C file the bench compiles (generated, peers, hand-written).
CFLAGS: List[str] = ["-O2", "-fPIC"]


def cc() -> str:
    exe = os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc")
    if not exe:
        raise RuntimeError("no C compiler found (gcc/cc); set CC")
    return exe


def flags_tag(extra: Sequence[str]) -> str:
    """A file-name suffix for objects built with ``extra`` flags (``""`` without): ``-march=native`` -> ``_marchnative``."""
    return "_" + "".join(c for c in "".join(extra) if c.isalnum()) if extra else ""


def compile_object(src: Path, obj: Path, extra: Sequence[str] = ()) -> float:
    """``gcc CFLAGS -c src -o obj``; returns the wall time in s."""
    t0 = time.perf_counter()
    subprocess.run([cc(), *CFLAGS, *extra, "-c", str(src), "-o", str(obj)], check=True,
                   stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    return time.perf_counter() - t0


def link_shared(objs: Sequence[Path], out: Path) -> Path:
    subprocess.run([cc(), "-shared", *CFLAGS, *map(str, objs), "-o", str(out), "-lm"], check=True,
                   stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    return out
