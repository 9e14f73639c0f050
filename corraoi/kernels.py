"""Compose a compiled kernel per policy family and keep it in numba's disk cache.

numba caches a compiled function beside its source file, keyed by that file. A kernel built
as a closure over a policy's hooks has no file of its own and misses the cache, so every new
process would recompile (seconds). Instead, the source of :mod:`corraoi._kernel` is copied
into the kernel cache with its ``HOOKS`` import lines pointing at the family's hooks, under a
name derived from a hash of everything that goes into it (the template, the hooks' modules,
:mod:`corraoi.rng`, the corraoi version). The copy is imported as a module and its ``advance``
is compiled once, then loaded from numba's cache by every later process.

Kernels are per family (the hooks), not per variant: ``correlated`` and ``aoi_aware`` are
runtime flags, so the paper's twelve policies need three kernels.

The cache folder is ``$CORRAOI_CACHE_DIR``, else ``$XDG_CACHE_HOME/corraoi``, else
``~/.cache/corraoi``; a folder that cannot be written falls back to the system's temp folder.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import sys
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ._version import __version__
from .errors import CorraoiError
from .policies.api import CompiledPolicy

#: Called with a one-line notice before a kernel is compiled (not when it loads from cache).
#: The CLI prints it; the library stays quiet.
on_compile: Callable[[str], None] | None = None

_TEMPLATE = Path(__file__).with_name("_kernel.py")
_RNG = Path(__file__).with_name("rng.py")
_HOOK_LINES = (
    "from corraoi.policies.hooks import forced_none as _forced  # HOOKS",
    "from corraoi.policies.hooks import score_none as _score  # HOOKS",
    "from corraoi.policies.hooks import update_none as _update  # HOOKS",
)
#: Seconds this process spent compiling kernels (speed figures such as record's slots/s
#: leave them out).
compile_seconds = 0.0
_COMPILING: set[str] = set()
_LOADED: dict[str, Any] = {}
_LOCK = threading.Lock()


class KernelError(CorraoiError):
    """A compiled policy whose hooks cannot be composed into a kernel."""

    exit_code = 2


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
        probe = folder / f".probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
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


def kernel_source(policy: type[CompiledPolicy]) -> tuple[str, str]:
    """(module name, source) of the kernel of ``policy``'s family."""
    refs = [
        _hook_ref(h, role, policy)
        for h, role in zip(hooks_of(policy), ("forced", "score", "update"), strict=True)
    ]
    text = _TEMPLATE.read_text(encoding="utf-8")
    digest = hashlib.sha256(text.encode())
    digest.update(_RNG.read_bytes())
    digest.update(__version__.encode())
    for (modname, attr, file), line, alias in zip(
        refs, _HOOK_LINES, ("_forced", "_score", "_update"), strict=True
    ):
        if line not in text:
            raise KernelError(f"kernel template {_TEMPLATE}: hook line missing: {line}")
        text = text.replace(line, f"from {modname} import {attr} as {alias}  # HOOKS")
        digest.update(f"{modname}:{attr}".encode())
        if file is not None and file.is_file():
            digest.update(file.read_bytes())
    header = (
        "# Generated by corraoi.kernels from corraoi/_kernel.py: the kernel of one policy\n"
        "# family. Do not edit; delete the folder to clear the cache.\n"
    )
    name = f"corraoi_kernel_{digest.hexdigest()[:20]}"
    return name, header + text


def _is_cached(folder: Path, modname: str) -> bool:
    pycache = folder / "__pycache__"
    if not pycache.is_dir():
        return False
    return any(p.name.startswith(f"{modname}.advance") for p in pycache.iterdir())


def kernel_for(policy: type[CompiledPolicy]) -> Any:
    """The compiled ``advance`` of ``policy``'s family (built, cached and loaded on demand)."""
    modname, source = kernel_source(policy)
    with _LOCK:
        if modname in _LOADED:
            return _LOADED[modname]
        folder = _writable(cache_dir())
        path = folder / f"{modname}.py"
        if not path.is_file() or path.read_text(encoding="utf-8") != source:
            tmp = folder / f".{modname}.{os.getpid()}.tmp"
            tmp.write_text(source, encoding="utf-8")
            os.replace(tmp, path)  # atomic: concurrent processes write the same bytes
        if not _is_cached(folder, modname):
            _COMPILING.add(modname)
            if on_compile is not None:
                on_compile(
                    f"compiling the engine for {policy.name} (first use; cached in {folder})"
                )
        spec = importlib.util.spec_from_file_location(modname, path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[modname] = module
        spec.loader.exec_module(module)
        _LOADED[modname] = module.advance
        return module.advance


def note_warm_up(kernel: Any, seconds: float) -> None:
    """Account a kernel's first call when it compiled (not when it loaded from the cache)."""
    global compile_seconds
    name = getattr(getattr(kernel, "py_func", None), "__module__", "")
    if name in _COMPILING:
        _COMPILING.discard(name)
        compile_seconds += seconds
