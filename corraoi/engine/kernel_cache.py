"""The kernel cache on disk: where compiled kernels live, a lock per entry, and a generated
kernel module compiled once, then loaded by every later process.

Its users: :mod:`corraoi.engine.kernels` (a policy family's kernel, on demand),
:mod:`corraoi.engine.kernel_pool` (several at once, in worker processes) and
:mod:`corraoi.gpu.device` (the emulated GPU's library, in a folder of its own).

The folder is ``$CORRAOI_CACHE_DIR``, else ``$XDG_CACHE_HOME/corraoi``, else
``~/.cache/corraoi``; a folder that cannot be written falls back to the system's temp folder.
A lock file per entry makes two processes that share a fresh cache compile it once. numba's
files of an entry are trusted only when they match the checksums written when it was
compiled: a truncated, altered or foreign file is rebuilt with one notice, never run. A
compile interrupted at any moment (Ctrl-C, a notebook's stop button), however often, leaves
nothing that is trusted: the next uninterrupted run compiles the entry whole and says so.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import importlib.util
import json
import os
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from corraoi._version import __version__
from corraoi.errors import KernelError

Say = Callable[[str], None] | None

#: Called with a one-line notice before a kernel is compiled (not when it loads from cache),
#: by every user of this cache. The CLI prints it; the library stays quiet. It lives here,
#: not in :mod:`corraoi.engine.kernels`, so that a command that runs no kernel (``info``,
#: ``diff``) can set it without importing the engine.
on_compile: Say = None

#: the kernels loaded in this process, by module name (a test swaps in an empty one to be
#: as a fresh process)
LOADED: dict[str, Any] = {}
_LOCK = threading.Lock()


def cache_dir() -> Path:
    """Where generated kernels (and numba's cache of them) live."""
    env = os.environ.get("CORRAOI_CACHE_DIR")
    if env:
        base = Path(env)
    else:
        xdg = os.environ.get("XDG_CACHE_HOME")
        base = (Path(xdg) if xdg else Path.home() / ".cache") / "corraoi"
    return base / f"kernels-{__version__}"


def folder(*parts: str) -> Path:
    """The cache folder (or ``parts`` below it), made; the system's temp folder instead when
    it cannot be written."""
    return _writable(cache_dir().joinpath(*parts))


def _writable(path: Path) -> Path:
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):  # a name of its own: threads probe at once
            pass
        return path
    except OSError:
        fallback = Path(tempfile.gettempdir()) / f"corraoi-kernels-{__version__}-{os.getuid()}"
        fallback.mkdir(parents=True, exist_ok=True)
        return fallback


@contextlib.contextmanager
def locked(folder: Path, name: str) -> Iterator[None]:
    """Hold an exclusive lock on one entry's lock file: a second process that needs the
    same entry waits here and then loads what the first compiled (compiled once)."""
    fd = os.open(folder / f".{name}.lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


def write_source(folder: Path, modname: str, source: str) -> Path:
    """The generated module ``modname`` in ``folder``, written unless it holds ``source``."""
    path = folder / f"{modname}.py"
    if not path.is_file() or path.read_text(encoding="utf-8") != source:
        tmp = folder / f".{modname}.{os.getpid()}.tmp"
        tmp.write_text(source, encoding="utf-8")
        os.replace(tmp, path)  # atomic: concurrent processes write the same bytes
    return path


def ready(folder: Path, modname: str) -> bool:
    """Whether the kernel ``modname`` is loaded in this process or compiled in ``folder``."""
    return modname in LOADED or any(p.suffix == ".nbi" for p in _index_files(folder, modname))


def kernel(modname: str, source: str, what: str, *, warm: Callable[[], tuple[Any, ...]],
           say: Say) -> tuple[Any, float]:  # fmt: skip
    """The compiled ``advance`` of the generated module ``modname`` (``source``), loaded once
    per process, and the seconds spent compiling it now (0 when it was loaded)."""
    with _LOCK:
        if modname in LOADED:
            return LOADED[modname], 0.0
        where = folder()
        path = write_source(where, modname, source)
        advance, took = load(where, modname, path, what, warm=warm, say=say)
        LOADED[modname] = advance
        return advance, took


def load(folder: Path, modname: str, path: Path, what: str, *,
         warm: Callable[[], tuple[Any, ...]], say: Say = None) -> tuple[Any, float]:  # fmt: skip
    """Import the generated module at ``path`` and compile (or load from numba's cache) its
    ``advance`` with the arguments ``warm()``, under the entry's lock; returns it and the
    seconds spent compiling (0 when it was loaded). ``say`` hears a notice before a kernel is
    compiled, never when it loads; ``what`` names the kernel there.

    A damaged cache entry (a truncated or foreign file in ``__pycache__``) is deleted and the
    kernel rebuilt, with one notice; it never ends the command.
    """
    from numba.core.errors import NumbaPerformanceWarning

    with locked(folder, modname):
        damaged = _damaged(folder, modname)  # checked before numba loads any of it
        if damaged:
            if say is not None:
                say(f"the cached engine for {what} {damaged}; rebuilding it")
            _clear_index(folder, modname)
        compiling = not any(p.suffix == ".nbi" for p in _index_files(folder, modname))
        if compiling and say is not None and not damaged:  # said above if damaged
            say(f"compiling the engine for {what} (first use; cached in {folder})")
        if compiling:
            _compiling_file(folder, modname).touch()
        for attempt in (0, 1):
            sys.modules.pop(modname, None)
            spec = importlib.util.spec_from_file_location(modname, path)
            assert spec is not None and spec.loader is not None
            module = importlib.util.module_from_spec(spec)
            sys.modules[modname] = module
            start = time.perf_counter()
            try:
                with warnings.catch_warnings():
                    # the sweep kernel asks for parallel=True for its IR passes, not for
                    # parfors: numba's "no transformation for parallel execution" is expected
                    warnings.simplefilter("ignore", NumbaPerformanceWarning)
                    spec.loader.exec_module(module)
                    module.advance(*warm())
            except KernelError:
                raise
            except Exception as exc:
                if attempt == 1 or not _index_files(folder, modname):
                    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()][:2]
                    why = " ".join(" ".join(lines).split())[:400]  # numba's errors run long
                    raise KernelError(f"the engine for {what} cannot be built in {folder}: "
                                      f"{type(exc).__name__}: {why}") from exc  # fmt: skip
                if say is not None:
                    say(f"the cached engine for {what} is damaged "
                        f"({type(exc).__name__}); rebuilding it")  # fmt: skip
                _clear_index(folder, modname)
                _compiling_file(folder, modname).touch()
                compiling = True
                continue
            took = 0.0
            if compiling:
                took = time.perf_counter() - start
                _write_sums(folder, modname)
                _compiling_file(folder, modname).unlink(missing_ok=True)
            return module.advance, took
    raise AssertionError("unreachable")


# ------------------------------------------------------------- numba's files of an entry


def _index_files(folder: Path, modname: str) -> list[Path]:
    pycache = folder / "__pycache__"
    if not pycache.is_dir():
        return []
    return [p for p in pycache.iterdir() if p.name.startswith(f"{modname}.advance")]


def _sums_file(folder: Path, modname: str) -> Path:
    return folder / f".{modname}.sha256"


def _sums(folder: Path, modname: str) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(_index_files(folder, modname))}  # fmt: skip


def _write_sums(folder: Path, modname: str) -> None:
    """Record the sha256 of every file numba cached for a kernel just compiled."""
    from corraoi.files.partial import PartialFile

    data = json.dumps(_sums(folder, modname), sort_keys=True).encode()
    PartialFile.write_bytes(_sums_file(folder, modname), data, what="kernel cache checksums")


def _compiling_file(folder: Path, modname: str) -> Path:
    """Present from the start of a compile until its files and checksums are all written:
    left behind, it says that a compile was interrupted (Ctrl-C, a notebook's stop button)."""
    return folder / f".{modname}.compiling"


def _damaged(folder: Path, modname: str) -> str:
    """Why a kernel's cached files cannot be trusted, as the end of a sentence ("" when they
    can, or when there are none): integrity is checked before numba loads machine code, so a
    truncated, altered or foreign file is rebuilt instead of being run. What an interrupted
    compile left (numba writes its index before its data, and leaves its temporary files
    when interrupted) is never trusted, whichever moment the interrupt hit: the next run
    compiles the entry whole."""
    if not _index_files(folder, modname):
        return ""
    try:
        want = json.loads(_sums_file(folder, modname).read_text(encoding="utf-8"))
        have = _sums(folder, modname)
    except (OSError, ValueError, RecursionError):
        want, have = None, {}
    if want == have:
        return ""
    if _compiling_file(folder, modname).exists():
        return "was interrupted while it compiled"
    if want is None:
        return "has no checksums (cached by an older corraoi, or its checksums were lost)"
    return "is damaged (its files do not match their checksums)"


def _clear_index(folder: Path, modname: str) -> None:
    for f in _index_files(folder, modname):
        f.unlink(missing_ok=True)
    _sums_file(folder, modname).unlink(missing_ok=True)
