"""A cache of compiled C: source -> shared object, built once, verified before every load.

Used by the compiled sampled-data loop (:mod:`fjm_runtime.sim.compiled`) and the batch
runners (:mod:`fjm_runtime.batch`); any C source (a CasADi Function code-generated
with :func:`generate_source`, plus a driver) goes through :func:`compile_library`
or, for a Function loaded back with :func:`casadi.external`, :func:`compile_function`.

Cache: ``$FJM_CACHE`` or ``$XDG_CACHE_HOME/fjm`` (default ``~/.cache/fjm``).
An entry is ``<key>.so`` plus ``<key>.json`` where ``key = sha256(C source,
compiler, flags)``. The JSON records the SHA-256 of the shared object; an entry
whose record is missing, unreadable, for another key, or whose bytes do not
match, is rebuilt, never loaded. New entries are written to a temporary file
and renamed into place (never overwritten in place), so concurrent processes
and already-loaded libraries are safe. A build holds an exclusive lock on
``<key>.lock`` (``fcntl.flock``, POSIX): a second process that wants the same
entry (e.g. another pytest-xdist worker) waits for the first build and loads
its result instead of compiling the same source again.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import tempfile
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Optional, Sequence, Tuple

import casadi as ca

try:
    import fcntl
except ImportError:  # not POSIX: no inter-process lock (builds may repeat; entries stay safe)
    fcntl = None

#: Default compiler flags (also part of the cache key).
DEFAULT_FLAGS: Tuple[str, ...] = ("-O2", "-fPIC", "-shared")

_memo: dict = {}
_lock = threading.Lock()


class CompileError(RuntimeError):
    """The C compiler is missing or failed."""


def cache_dir() -> Path:
    """The compiled-code cache directory (created on demand)."""
    env = os.environ.get("FJM_CACHE")
    if env:
        root = Path(env)
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        root = Path(base) / "fjm"
    root.mkdir(parents=True, exist_ok=True)
    return root


def find_compiler() -> str:
    """The C compiler: ``$CC``, else ``gcc``, else ``cc`` on ``PATH``.

    Raises
    ------
    CompileError
        None of them is found.
    """
    exe = os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc")
    if not exe:
        raise CompileError("no C compiler found (looked for $CC, gcc, cc); install gcc or set CC")
    return exe


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def generate_source(fn: ca.Function) -> str:
    """C source of ``fn`` (CasADi code generator, same options as ``make derive``)."""
    with tempfile.TemporaryDirectory(prefix="fjm-cg-") as tmp:
        cg = ca.CodeGenerator(f"{fn.name()}.c", {"with_header": False})
        cg.add(fn)
        path = cg.generate(tmp + os.sep)
        return Path(path).read_text()


def cache_key(source: str, flags: Sequence[str], compiler: Optional[str] = None) -> str:
    """``sha256(source, compiler, flags)`` as hex."""
    h = hashlib.sha256()
    h.update(source.encode())
    h.update(b"\0" + (compiler or find_compiler()).encode())
    for f in flags:
        h.update(b"\0" + f.encode())
    return h.hexdigest()


def _entry_valid(so: Path, meta: Path, key: str) -> bool:
    try:
        record = json.loads(meta.read_text())
        return (record.get("key") == key and so.is_file()
                and record.get("so_sha256") == _sha256_file(so))
    except (OSError, ValueError, AttributeError):
        return False


@contextmanager
def _entry_lock(root: Path, key: str):
    """Hold an exclusive inter-process lock on the entry ``key`` (blocks while another holds it)."""
    if fcntl is None:
        yield
        return
    with open(root / f"{key}.lock", "a") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


def _build(source: str, key: str, flags: Sequence[str], root: Path, name: str) -> Path:
    so, meta = root / f"{key}.so", root / f"{key}.json"
    with tempfile.TemporaryDirectory(prefix="fjm-build-", dir=root) as tmp:
        src = Path(tmp) / f"{name}.c"
        src.write_text(source)
        out = Path(tmp) / f"{key}.so"
        cmd = [find_compiler(), *flags, str(src), "-o", str(out), "-lm"]
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if proc.returncode != 0:
            raise CompileError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-4000:]}")
        digest = _sha256_file(out)
        tmp_meta = Path(tmp) / f"{key}.json"
        tmp_meta.write_text(json.dumps({"key": key, "so_sha256": digest, "function": name,
                                        "flags": list(flags), "compiler": find_compiler()}, indent=1))
        os.replace(out, so)          # library first, then the record that vouches for it
        os.replace(tmp_meta, meta)
    return so


def compile_library(source: str, name: str, flags: Sequence[str] = DEFAULT_FLAGS,
                    cache: Optional[Path] = None) -> Path:
    """Compile C ``source`` to a shared object in the cache (or reuse a verified entry).

    Returns the path of the ``.so``; the caller loads it (``ctypes`` or
    ``casadi.external``). Same cache rules as :func:`compile_function`.
    """
    key = cache_key(source, flags)
    root = Path(cache) if cache is not None else cache_dir()
    root.mkdir(parents=True, exist_ok=True)
    with _lock:
        so, meta = root / f"{key}.so", root / f"{key}.json"
        if _entry_valid(so, meta, key):
            return so
        with _entry_lock(root, key):
            if _entry_valid(so, meta, key):      # built by another process while we waited
                return so
            return _build(source, key, flags, root, name)


def _load_entry(name: str, so: Path, meta: Path, key: str):
    """``casadi.external(name, so)`` of a valid cache entry, or ``None`` (missing, invalid or unloadable)."""
    if not _entry_valid(so, meta, key):
        return None
    try:
        return ca.external(name, str(so))
    except RuntimeError:
        return None


def compile_function(fn: ca.Function, flags: Sequence[str] = DEFAULT_FLAGS,
                     cache: Optional[Path] = None) -> ca.Function:
    """Code-generate ``fn``, compile it (or reuse a verified cache entry), load it.

    Parameters
    ----------
    fn : casadi.Function
        Any code-generatable Function (SX, or MX of SX/maps).
    flags : sequence of str
        Compiler flags; must produce a shared object (default ``-O2 -fPIC -shared``).
    cache : Path, optional
        Cache directory (default :func:`cache_dir`).

    Returns
    -------
    casadi.Function
        ``casadi.external(fn.name(), <cached .so>)``, same signature as ``fn``.
    """
    source = generate_source(fn)
    key = cache_key(source, flags)
    root = Path(cache) if cache is not None else cache_dir()
    root.mkdir(parents=True, exist_ok=True)
    memo_key = (str(root), key)
    with _lock:
        hit = _memo.get(memo_key)
        if hit is not None:
            return hit
        so, meta = root / f"{key}.so", root / f"{key}.json"
        ext = _load_entry(fn.name(), so, meta, key)
        if ext is None:
            with _entry_lock(root, key):
                ext = _load_entry(fn.name(), so, meta, key)  # built by another process while we waited
                if ext is None:
                    ext = ca.external(fn.name(), str(_build(source, key, flags, root, fn.name())))
        _memo[memo_key] = ext
        return ext
