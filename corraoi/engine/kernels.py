"""Compose a compiled kernel per policy family and keep it in numba's disk cache.

numba caches a compiled function beside its source file, keyed by that file. A kernel built
as a closure over a policy's hooks has no file of its own and misses the cache, so every new
process would recompile (seconds). Instead, the source of :mod:`corraoi.engine._kernel` is copied
into the kernel cache with its ``HOOKS`` import lines pointing at the family's hooks, under a
name derived from a hash of everything that goes into it (the template, the hooks' modules,
:mod:`corraoi.rng`, the corraoi version). The copy is imported as a module and its ``advance``
is compiled once, then loaded from numba's cache by every later process.

Kernels are per family (the hooks), not per variant: ``correlated`` and ``aoi_aware`` are
runtime flags, so the paper's twelve policies need three families. Each family has two
kernels shaped by their job (the template's docstring): the serial record kernel, which a
one-run ``corraoi record`` compiles in about 3 s, and the sweep kernel, without the per-slot
recording path. A command compiles only the one it uses; when several families must compile
(a first ``--policy all``), :func:`corraoi.engine.kernel_pool.prepare` compiles them in worker
processes at once. A lock
file per kernel makes two processes that share a fresh cache compile it once, and a damaged
cache entry is rebuilt with one notice.

The cache folder is ``$CORRAOI_CACHE_DIR``, else ``$XDG_CACHE_HOME/corraoi``, else
``~/.cache/corraoi``; a folder that cannot be written falls back to the system's temp folder.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import importlib
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

import numpy as np

from corraoi._version import __version__
from corraoi.errors import KernelError
from corraoi.policies.api import CompiledPolicy

#: Called with a one-line notice before a kernel is compiled (not when it loads from cache).
#: The CLI prints it; the library stays quiet.
on_compile: Callable[[str], None] | None = None

_TEMPLATE = Path(__file__).with_name("_kernel.py")
_RNG = Path(__file__).parent.parent / "rng.py"
_HOOK_LINES = (
    "from corraoi.policies.hooks import forced_none as _forced  # HOOKS",
    "from corraoi.policies.hooks import score_none as _score  # HOOKS",
    "from corraoi.policies.hooks import update_none as _update  # HOOKS",
)
#: Seconds this process spent compiling kernels (speed figures such as record's slots/s
#: leave them out).
compile_seconds = 0.0
_LOADED: dict[str, Any] = {}
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


def _writable(folder: Path) -> Path:
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):  # a name of its own: threads probe at once
            pass
        return folder
    except OSError:
        fallback = Path(tempfile.gettempdir()) / f"corraoi-kernels-{__version__}-{os.getuid()}"
        fallback.mkdir(parents=True, exist_ok=True)
        return fallback


def load_hook(ref: Any, role: str, policy: type[CompiledPolicy]) -> Any:
    """The numba function a hook names: itself, or ``"module:function"`` imported."""
    if not isinstance(ref, str):
        return ref
    modname, _, attr = ref.partition(":")
    try:
        module = importlib.import_module(modname)
        return getattr(module, attr)
    except (ImportError, AttributeError) as exc:
        raise KernelError(
            f"policy {policy.name}: its {role} hook {ref!r} cannot be imported: {exc}"
        ) from None


def _hook_ref(ref: Any, role: str, policy: type[CompiledPolicy]) -> tuple[str, str, Path | None]:
    """(module, attribute, source file) of a compiled hook, which must be importable."""
    hook = load_hook(ref, role, policy)
    func = getattr(hook, "py_func", None)
    if func is None or not hasattr(hook, "compile"):
        raise KernelError(
            f"policy {policy.name}: its {role} hook {hook!r} is not a numba @njit function"
        )
    modname, attr = func.__module__, func.__name__
    module = sys.modules.get(modname)
    if module is None or getattr(module, attr, None) is not hook:
        raise KernelError(
            f"policy {policy.name}: its {role} hook {attr} must be defined at the top level of "
            f"module {modname} (hooks are imported by the generated kernel)"
        )
    file = getattr(module, "__file__", None)
    return modname, attr, Path(file) if file else None


def hooks_of(policy: type[CompiledPolicy]) -> tuple[Any, Any, Any]:
    return (
        policy.forced if policy.forced is not None else "corraoi.policies.hooks:forced_none",
        policy.score if policy.score is not None else "corraoi.policies.hooks:score_none",
        policy.update if policy.update is not None else "corraoi.policies.hooks:update_none",
    )


def kernel_source(policy: type[CompiledPolicy], *, record: bool) -> tuple[str, str]:
    """(module name, source) of the record or sweep kernel of ``policy``'s family."""
    refs = [
        _hook_ref(h, role, policy)
        for h, role in zip(hooks_of(policy), ("forced", "score", "update"), strict=True)
    ]
    text = _TEMPLATE.read_text(encoding="utf-8")
    digest = hashlib.sha256(text.encode())
    digest.update(_RNG.read_bytes())
    digest.update(__version__.encode())
    digest.update(b"record" if record else b"sweep")
    for (modname, attr, file), line, alias in zip(
        refs, _HOOK_LINES, ("_forced", "_score", "_update"), strict=True
    ):
        if line not in text:
            raise KernelError(f"kernel template {_TEMPLATE}: hook line missing: {line}")
        text = text.replace(line, f"from {modname} import {attr} as {alias}  # HOOKS")
        digest.update(f"{modname}:{attr}".encode())
        # the bytes the hook's module was loaded from (a plug-in's exact source: the file
        # may have changed since, or a sweep's kept copy runs): never the file read again
        loaded = getattr(sys.modules.get(modname), "__corraoi_source__", None)
        if isinstance(loaded, bytes):
            digest.update(loaded)
        elif file is not None and file.is_file():
            digest.update(file.read_bytes())
    if not record:
        text = _sweep_variant(text)
    header = (
        "# Generated by corraoi.engine.kernels from corraoi/engine/_kernel.py: the "
        + ("record" if record else "sweep")
        + " kernel of one policy\n# family. Do not edit; delete the folder to clear the cache.\n"
    )
    name = f"corraoi_{'record' if record else 'sweep'}_{digest.hexdigest()[:20]}"
    return name, header + text


def _sweep_variant(text: str) -> str:
    """The template with the sweep kernel's decorator and without the recording path."""
    lines = text.split("\n")
    out: list[str] = []
    skipping = False
    swapped = 0
    for line in lines:
        stripped = line.strip()
        if stripped == "# RECORD-BEGIN":
            skipping = True
        elif stripped == "# RECORD-END":
            skipping = False
        elif skipping:
            continue
        elif stripped.endswith("# KERNEL") and stripped.startswith("@njit("):
            out.append(f"{line[: len(line) - len(line.lstrip())]}{_sweep_decorator(text)}")
            swapped += 1
        else:
            out.append(line)
    if swapped != 1 or skipping:
        raise KernelError(f"kernel template {_TEMPLATE}: KERNEL or RECORD markers are broken")
    return "\n".join(out)


def _sweep_decorator(text: str) -> str:
    from . import _kernel

    return _kernel.SWEEP_DECORATOR


def _index_files(folder: Path, modname: str) -> list[Path]:
    pycache = folder / "__pycache__"
    if not pycache.is_dir():
        return []
    return [p for p in pycache.iterdir() if p.name.startswith(f"{modname}.advance")]


def _is_cached(folder: Path, modname: str) -> bool:
    return any(p.suffix == ".nbi" for p in _index_files(folder, modname))


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


def _damaged(folder: Path, modname: str) -> str:
    """Why a kernel's cached files cannot be trusted, as the end of a sentence ("" when they
    can, or when there are none): integrity is checked before numba loads machine code, so a
    truncated, altered or foreign file is rebuilt instead of being run."""
    if not _index_files(folder, modname):
        return ""
    try:
        want = json.loads(_sums_file(folder, modname).read_text(encoding="utf-8"))
        have = _sums(folder, modname)
    except (OSError, ValueError, RecursionError):
        return "has no checksums (cached by an older corraoi, or its checksums were lost)"
    return "" if want == have else "is damaged (its files do not match their checksums)"


def _clear_index(folder: Path, modname: str) -> None:
    for f in _index_files(folder, modname):
        f.unlink(missing_ok=True)
    _sums_file(folder, modname).unlink(missing_ok=True)


@contextlib.contextmanager
def _locked(folder: Path, modname: str) -> Iterator[None]:
    """Hold an exclusive lock on one kernel's lock file: a second process that needs the
    same kernel waits here and then loads what the first compiled (compiled once)."""
    fd = os.open(folder / f".{modname}.lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


def warm_args(K: int = 2) -> tuple[Any, ...]:
    """Arguments of a zero-slot ``advance`` call with the types the engine passes (so the
    compiled signature is the one the engine will look up in the cache)."""
    R = 1
    f8, i8 = np.float64, np.int64
    return (
        np.ones((1, 2), f8), 0, np.zeros(1, i8), np.zeros((K, 2), np.int8),
        np.zeros((K, 8, 1), np.uint64), np.zeros((K, K), np.int8), 0, False, False,
        np.zeros(0, f8), 0, 0,
        np.zeros((R, 4), np.uint64), np.zeros((R, 4), np.uint64), np.zeros((R, 2), f8),
        np.zeros((R, 1), f8), np.full(R, -1, i8), np.zeros((R, K), i8), np.zeros((R, K), i8),
        np.ones(R, i8), np.ones(R, i8), np.zeros(R, i8), np.zeros(R, i8), np.zeros((R, 3), i8),
        False, np.empty((R, 0), np.int32), np.empty((R, 0), np.int32),
        np.empty((R, 0), np.bool_), np.empty((R, 0), i8), np.empty((R, 0), i8),
        np.empty((R, 0), i8), np.empty((R, 0), np.bool_), np.empty((R, 0, K), np.bool_),
        np.empty((R, 0, K), i8), np.empty((R, 0, K), f8),
        np.empty(0, i8), np.empty((R, 0), i8), np.empty((R, 0), i8), np.empty((R, 0, K), i8),
    )  # fmt: skip


def _load(folder: Path, modname: str, path: Path, what: str) -> Any:
    """Import the generated module and compile (or load) its ``advance`` under the lock.

    A damaged cache entry (a truncated or foreign file in ``__pycache__``) is deleted and the
    kernel rebuilt, with one notice; it never ends the command.
    """
    global compile_seconds
    from numba.core.errors import NumbaPerformanceWarning

    with _locked(folder, modname):
        damaged = _damaged(folder, modname)  # checked before numba loads any of it
        if damaged:
            if on_compile is not None:
                on_compile(f"the cached engine for {what} {damaged}; rebuilding it")
            _clear_index(folder, modname)
        compiling = not _is_cached(folder, modname)
        if compiling and on_compile is not None and not damaged:  # said above if damaged
            on_compile(f"compiling the engine for {what} (first use; cached in {folder})")
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
                    module.advance(*warm_args())
            except KernelError:
                raise
            except Exception as exc:
                if attempt == 1 or not _index_files(folder, modname):
                    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()][:2]
                    why = " ".join(" ".join(lines).split())[:400]  # numba's errors run long
                    raise KernelError(f"the engine for {what} cannot be built in {folder}: "
                                      f"{type(exc).__name__}: {why}") from exc  # fmt: skip
                if on_compile is not None:
                    on_compile(
                        f"the cached engine for {what} is damaged "
                        f"({type(exc).__name__}); rebuilding it"
                    )
                _clear_index(folder, modname)
                compiling = True
                continue
            if compiling:
                compile_seconds += time.perf_counter() - start
                _write_sums(folder, modname)
            return module.advance
    raise AssertionError("unreachable")


def _write_source(folder: Path, modname: str, source: str) -> Path:
    path = folder / f"{modname}.py"
    if not path.is_file() or path.read_text(encoding="utf-8") != source:
        tmp = folder / f".{modname}.{os.getpid()}.tmp"
        tmp.write_text(source, encoding="utf-8")
        os.replace(tmp, path)  # atomic: concurrent processes write the same bytes
    return path


def kernel_for(policy: type[CompiledPolicy], *, record: bool) -> Any:
    """The compiled ``advance`` of ``policy``'s family: the record kernel (per-slot columns)
    or the sweep kernel (finals and snapshots only), built, cached and loaded on demand."""
    modname, source = kernel_source(policy, record=record)
    with _LOCK:
        if modname in _LOADED:
            return _LOADED[modname]
        folder = _writable(cache_dir())
        path = _write_source(folder, modname, source)
        kernel = _load(folder, modname, path, policy.name)
        _LOADED[modname] = kernel
        return kernel
